"""The Qt widgets a scripted module's GUI is made of, which slicer-core (no Qt) lacks: the
imitation qt_layer.py installs under `qt` and `ctk`, so that the ROS2Bridge module's
widget (`ROS2BridgeWidget.setup` and its slots) runs over Slicer's own `slicer.util`
(loadUI, childWidgetVariables, tryWithErrorDisplay, VTKObservationMixin) and a real MRML
scene. Nothing is drawn; a test drives a widget as a user would, through `emit`.

Each item names the behaviour imitated and where it is shown (Qt 5 docs, PythonQt, Slicer
main's sources):

- `Widget`: a QWidget as PythonQt hands it to Python: its Q_PROPERTYs as attributes
  (`text`, `checked`, `value`, `currentText`...), the .ui's dynamic properties through
  `property(name)` (Slicer's `SlicerParameterName`), `name` (objectName), `children()`
  (what `slicer.util.findChildren` walks), `connect("signal(args)", slot)` calling the
  slot with as many of the signal's arguments as it takes (PythonQt), `blockSignals`;
  QComboBox's and QListWidget's `addItem`/`clear`; qMRMLWidget's `setMRMLScene`
  (Libs/MRML/Widgets/qMRMLWidget.h) and qMRMLNodeComboBox's `currentNode`; `layout()`.
  `emit(signal, *args)` stands for the user's action.
- `FormLayout`: QFormLayout's `rowCount`, `removeRow`, `addRow` (Qt 5.8+).
- `QFile`, `QUiLoader`: what `slicer.util.loadUI` calls (Base/Python/slicer/util.py): the
  .ui's widgets made with their designer properties, the top one's children the others,
  and the file's `<connections>` made (Qt Designer's signal/slot connections).
- `ctkSliderWidget`: a Widget (CTK's Libs/Widgets/ctkSliderWidget.h: `value`, `minimum`,
  `maximum`, `decimals`, `singleStep`, `suffix`, `valueChanged(double)`).
- `QMessageBox.Ok`/`Critical`, `Qt.WaitCursor`: the constants `slicer.util.errorDisplay`
  and `tryWithErrorDisplay` name (no box is shown: with no main window, Slicer's
  `_messageDisplay` only logs the text).
"""

from __future__ import annotations

import inspect
import types
from pathlib import Path
from typing import Any, Callable, Optional
from xml.etree import ElementTree as ET

__all__ = ["FormLayout", "QFile", "QUiLoader", "Widget", "install_widgets"]


class Widget:
    """A QWidget of a .ui file (see the module docstring)."""

    def __init__(self, class_name: str = "QWidget", name: str = "",
                 properties: Optional[dict[str, Any]] = None,
                 dynamic: Optional[dict[str, Any]] = None,
                 items: Optional[list[str]] = None) -> None:
        self.class_name, self.name = class_name, name
        self._dynamic = dict(dynamic or {})
        self._slots: dict[str, list[Callable[..., Any]]] = {}
        self._blocked = False
        self._children: list[Widget] = []
        self._layout = FormLayout()
        self.text, self.checked, self.value, self.toolTip = "", False, 0, ""
        self.__dict__.update(properties or {})
        self.items = list(items or [])
        self.currentText = self.items[0] if self.items else ""
        self.scene: Any = None
        self.current_node: Any = None

    def className(self) -> str:  # noqa: N802
        return self.class_name

    def children(self) -> list[Widget]:
        return list(self._children)

    def property(self, name: str) -> Any:
        return self._dynamic.get(name)

    def layout(self) -> FormLayout:
        return self._layout

    def connect(self, signal: str, slot: Callable[..., Any]) -> bool:
        self._slots.setdefault(signal, []).append(slot)
        return True

    def blockSignals(self, block: bool) -> bool:  # noqa: N802
        was, self._blocked = self._blocked, bool(block)
        return was

    def emit(self, signal: str, *args: Any) -> None:
        if self._blocked:
            return
        for slot in list(self._slots.get(signal, [])):
            try:
                parameters = list(inspect.signature(slot).parameters.values())
            except (TypeError, ValueError):  # a builtin: give it everything
                slot(*args)
                continue
            if any(p.kind is p.VAR_POSITIONAL for p in parameters):
                slot(*args)
            else:
                slot(*args[:sum(p.default is p.empty for p in parameters)])

    def addItem(self, text: str) -> None:  # noqa: N802
        self.items.append(text)
        self.currentText = self.currentText or text

    def clear(self) -> None:
        self.items, self.currentText = [], ""

    def setMRMLScene(self, scene: Any) -> None:  # noqa: N802
        self.scene = scene
        self.emit("mrmlSceneChanged(vtkMRMLScene*)", scene)

    def currentNode(self) -> Any:  # noqa: N802
        return self.current_node


class FormLayout:
    def __init__(self) -> None:
        self.rows: list[tuple[Any, Any]] = []

    def rowCount(self) -> int:  # noqa: N802
        return len(self.rows)

    def removeRow(self, row: int) -> None:  # noqa: N802
        del self.rows[row]

    def addRow(self, label: Any, field: Any = None) -> None:  # noqa: N802
        self.rows.append((label, field))


class QFile:
    ReadOnly = 1

    def __init__(self, path: str) -> None:
        self.path = Path(path)

    def exists(self) -> bool:
        return self.path.is_file()

    def open(self, mode: int) -> bool:
        return self.exists()


def _designer_value(prop: ET.Element) -> Any:
    value = prop[0]
    if value.tag == "bool":
        return value.text == "true"
    if value.tag == "number":
        return int(value.text or 0)
    if value.tag == "stringlist":
        return [item.text or "" for item in value]
    return value.text or ""


class QUiLoader:
    def load(self, qfile: QFile) -> Widget:
        root = ET.parse(qfile.path).getroot()
        made: dict[str, Widget] = {}
        for element in root.iter("widget"):
            properties: dict[str, Any] = {}
            dynamic: dict[str, Any] = {}
            for prop in element.findall("property"):
                target = dynamic if prop.get("stdset") == "0" else properties
                target[prop.get("name", "")] = _designer_value(prop)
            items = [_designer_value(item.find("property"))  # type: ignore[arg-type]
                     for item in element.findall("item")]
            made[element.get("name", "")] = Widget(element.get("class", ""),
                                                   element.get("name", ""), properties,
                                                   dynamic, items)
        for connection in root.iter("connection"):
            receiver = made[connection.findtext("receiver", "")]
            slot = connection.findtext("slot", "").split("(")[0]
            made[connection.findtext("sender", "")].connect(connection.findtext("signal", ""),
                                                           getattr(receiver, slot))
        top_element = root.find("widget")
        assert top_element is not None, f"{qfile.path}: no widget"
        top = made[top_element.get("name", "")]
        top._children = [w for w in made.values() if w is not top]
        return top


def ctkSliderWidget() -> Widget:  # noqa: N802
    return Widget("ctkSliderWidget")


def install_widgets(qt: types.ModuleType, ctk: types.ModuleType) -> None:
    """Add the widgets to the `qt` and `ctk` modules qt_layer.install makes."""
    qt.QFile = QFile  # type: ignore[attr-defined]
    qt.QUiLoader = QUiLoader  # type: ignore[attr-defined]
    qt.QWidget = Widget  # type: ignore[attr-defined]
    qt.QMessageBox = types.SimpleNamespace(Ok=0x400, Critical=3)  # type: ignore[attr-defined]
    qt.Qt = types.SimpleNamespace(WaitCursor=3)  # type: ignore[attr-defined]
    ctk.ctkSliderWidget = ctkSliderWidget  # type: ignore[attr-defined]

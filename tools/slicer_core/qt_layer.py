"""What 3D Slicer's Qt layer gives a scripted module and slicer-core (PyPI) lacks: the only
imitated part of the real-Slicer tier. Everything else (MRML, the module logics, slicer.util,
VTK, the OpenIGTLinkIF connector) is Slicer's own code.

Each imitation names where Slicer's sources show the behaviour (Slicer/Slicer main):

- `QTimer`: a Qt timer (`setInterval`, `connect("timeout()", slot)`, `start`, `stop`,
  `isActive`), fired from the event loop only. Qt's QTimer, as PythonQt gives `qt.QTimer`.
- `Application.processEvents`: one turn of Slicer's event loop: OpenIGTLinkIF's 5 ms timer
  (`CallConnectorTimerHander`) and the due timers. SlicerOpenIGTLink's
  `qSlicerOpenIGTLinkIFModule.cxx`; Qt's event loop.
- `Application.connect("startupCompleted()")`: the signal sent once every module is
  loaded. Slicer's `Base/QTGUI/qSlicerApplication.cxx`.
- `Application.moduleManager().module(name)`: None for a module not loaded.
  `Base/QTCore/qSlicerModuleManager.h`.
- `Application.topLevelWidgets()` (none: no main window, so `slicer.util.errorDisplay` only
  logs), `testingEnabled()` (False), `setOverrideCursor`/`restoreOverrideCursor` (nothing to
  show), `applicationName`: what `slicer.util.tryWithErrorDisplay` calls.
  `Base/QTCore/qSlicerCoreApplication.h`, Qt's QApplication.
- `getModuleLogic(name)`: `slicer.util.getModuleLogic`, the logic of a loaded module (a
  scripted module's widget's `.logic`). `Base/Python/slicer/util.py`.
- `ScriptedLoadableModule*`: the scripted-module base classes (`parent`, `moduleName`,
  `getParameterNode`: a singleton `vtkMRMLScriptedModuleNode` tagged with the module's
  name; `delayDisplay`; the widget's `parent.isEntered`, `layout.addWidget`, `setup`,
  `resourcePath`: the module folder's Resources/). `Base/Python/slicer/ScriptedLoadableModule.py`.
- `parameterNodeWrapper`, `WithinRange`: typed fields stored as the parameter node's
  parameters (str and int, the types the module uses), defaults written on first use;
  `connectGui(ui)` binds each widget whose `SlicerParameterName` names a field, both ways
  (QLineEdit `text`/textChanged(QString) to str, QSpinBox `value`/valueChanged(int) to int;
  the widgets follow the node's ModifiedEvent), an unknown name raising; `disconnectGui`
  ends that. `Base/Python/slicer/parameterNodeWrapper/{wrapper,validators,guiConnectors}.py`.
- `ctk` and the Qt widgets (`qt.QFile`, `qt.QUiLoader`, `ctk.ctkSliderWidget`...): in
  qt_widgets.py beside this file, each named there.

`install(app)` puts them in place (`sys.modules["qt"]`, `["ctk"]`,
`["slicer.ScriptedLoadableModule"]`, `["slicer.parameterNodeWrapper"]`, `slicer.app`) before
a module file is imported, as Slicer has them before it loads modules.
"""

from __future__ import annotations

import os
import sys
import time
import types
import typing
import unittest
from typing import Any, Callable, Optional

import slicer
import vtk

from tools.slicer_core.qt_widgets import install_widgets

__all__ = ["Application", "QTimer", "install"]


class QTimer:
    """A Qt timer fired by `Application.processEvents` when due."""

    _running: "list[QTimer]" = []

    def __init__(self) -> None:
        self._interval_ms = 0
        self._slots: list[Callable[[], Any]] = []
        self._due = 0.0
        self.singleShot_ = False

    def setInterval(self, ms: int) -> None:  # noqa: N802
        self._interval_ms = int(ms)

    def interval(self) -> int:
        return self._interval_ms

    def connect(self, signal: str, slot: Callable[[], Any]) -> None:
        if signal != "timeout()":
            raise ValueError(f"QTimer has no signal {signal!r}")
        self._slots.append(slot)

    def start(self, ms: Optional[int] = None) -> None:
        if ms is not None:
            self._interval_ms = int(ms)
        self._due = time.monotonic() + self._interval_ms / 1000.0
        if self not in QTimer._running:
            QTimer._running.append(self)

    def stop(self) -> None:
        if self in QTimer._running:
            QTimer._running.remove(self)

    def isActive(self) -> bool:  # noqa: N802
        return self in QTimer._running

    @staticmethod
    def singleShot(ms: int, slot: Callable[[], Any]) -> None:  # noqa: N802
        timer = QTimer()
        timer.singleShot_ = True
        timer.connect("timeout()", slot)
        timer.start(ms)

    def _fire_if_due(self, now: float) -> None:
        if now < self._due:
            return
        if self.singleShot_:
            self.stop()
        else:
            self._due = now + self._interval_ms / 1000.0
        for slot in list(self._slots):
            slot()


class _ModuleManager:
    def __init__(self) -> None:
        self.modules: dict[str, Any] = {}

    def module(self, name: str) -> Any:
        return self.modules.get(name)


class Application:
    """`slicer.app` as far as a scripted module's logic touches it."""

    def __init__(self, slicer_app: Any) -> None:
        self._slicer_app = slicer_app  # slicer_app.SlicerApp: the scene and module logics
        self._startup: list[Callable[[], Any]] = []
        self._manager = _ModuleManager()
        self.logics: dict[str, Any] = {}  # scripted module name -> its logic

    def moduleManager(self) -> _ModuleManager:  # noqa: N802
        return self._manager

    def connect(self, signal: str, slot: Callable[[], Any]) -> None:
        if signal != "startupCompleted()":
            raise ValueError(f"slicer.app has no signal {signal!r} here")
        self._startup.append(slot)

    def startupCompleted(self) -> None:  # noqa: N802
        for slot in self._startup:
            slot()

    applicationName = "Slicer"

    def topLevelWidgets(self) -> list[Any]:  # noqa: N802
        return []

    def testingEnabled(self) -> bool:  # noqa: N802
        return False

    def setOverrideCursor(self, cursor: Any) -> None:  # noqa: N802
        pass

    def restoreOverrideCursor(self) -> None:  # noqa: N802
        pass

    def processEvents(self) -> None:  # noqa: N802
        self._slicer_app.pump(0)  # OpenIGTLinkIF's connector timer
        now = time.monotonic()
        for timer in list(QTimer._running):
            timer._fire_if_due(now)


# --- slicer.ScriptedLoadableModule ------------------------------------------------------------
class ScriptedLoadableModule:
    def __init__(self, parent: Any) -> None:
        self.parent = parent if parent is not None else types.SimpleNamespace()
        self.moduleName = type(self).__name__


class ScriptedLoadableModuleWidget:
    def __init__(self, parent: Any = None) -> None:
        self.parent = parent if parent is not None else types.SimpleNamespace(isEntered=True)
        self.moduleName = type(self).__name__[:-len("Widget")]
        self.layout = types.SimpleNamespace(widgets=[])
        self.layout.addWidget = self.layout.widgets.append

    def setup(self) -> None:
        pass

    def resourcePath(self, filename: str) -> str:  # noqa: N802
        module = sys.modules[type(self).__module__].__file__
        assert module is not None
        return os.path.join(os.path.dirname(module), "Resources", filename)


class ScriptedLoadableModuleLogic:
    def __init__(self, parent: Any = None) -> None:
        name = type(self).__name__
        self.moduleName = name[:-len("Logic")] if name.endswith("Logic") else name
        self.isSingletonParameterNode = True

    def getParameterNode(self) -> Any:  # noqa: N802
        scene = slicer.mrmlScene
        node = scene.GetSingletonNode(self.moduleName, "vtkMRMLScriptedModuleNode")
        if node is not None:
            return node
        node = scene.CreateNodeByClass("vtkMRMLScriptedModuleNode")
        node.UnRegister(None)  # CreateNodeByClass hands over a reference, as in Slicer
        node.SetSingletonTag(self.moduleName)
        node.SetName(scene.GetUniqueNameByString(self.moduleName))
        node.SetAttribute("ModuleName", self.moduleName)
        return scene.AddNode(node)


class ScriptedLoadableModuleTest(unittest.TestCase):
    displayed: list[str] = []

    def delayDisplay(self, message: str, msec: int = 1000) -> None:  # noqa: N802
        ScriptedLoadableModuleTest.displayed.append(message)
        print(message, flush=True)


# --- slicer.parameterNodeWrapper -----------------------------------------------------------
class WithinRange:
    def __init__(self, minimum: float, maximum: float) -> None:
        self.minimum, self.maximum = minimum, maximum


def _field(name: str, kind: type, default: Any) -> property:
    def get(self: Any) -> Any:
        node = self.parameterNode
        if not node.GetParameter(name):
            return default
        return kind(node.GetParameter(name))

    def set_(self: Any, value: Any) -> None:
        self.parameterNode.SetParameter(name, str(kind(value)))
    return property(get, set_)


# A bound widget's property and the signal it changes by, per widget class.
_GUI_FIELDS = {"QLineEdit": ("text", "textChanged(QString)"),
               "QSpinBox": ("value", "valueChanged(int)")}


def parameterNodeWrapper(cls: type) -> type:  # noqa: N802
    hints = typing.get_type_hints(cls, include_extras=True)
    fields = {}
    for name, hint in hints.items():
        kind = typing.get_args(hint)[0] if typing.get_origin(hint) is typing.Annotated else hint
        fields[name] = (kind, getattr(cls, name))

    def __init__(self: Any, parameterNode: Any) -> None:  # noqa: N807,N803
        self.parameterNode = parameterNode
        self._guis = {}  # tag -> (observer tag, {field: widget})
        for name, (_kind, default) in fields.items():
            if not parameterNode.GetParameter(name):
                parameterNode.SetParameter(name, str(default))

    def connectGui(self: Any, gui: Any) -> int:  # noqa: N802
        widgets = {w.property("SlicerParameterName"): w for w in vars(gui).values()
                   if hasattr(w, "property") and w.property("SlicerParameterName")}
        for name, widget in widgets.items():
            if name not in fields:
                raise ValueError(f"{widget.name}: no parameter {name!r} in {cls.__name__}")
            attribute, signal = _GUI_FIELDS[widget.className()]
            setattr(widget, attribute, getattr(self, name))
            widget.connect(signal, lambda value, n=name: setattr(self, n, value))

        def follow(caller: Any = None, event: Any = None) -> None:
            for name, widget in widgets.items():
                setattr(widget, _GUI_FIELDS[widget.className()][0], getattr(self, name))
        tag = self.parameterNode.AddObserver(vtk.vtkCommand.ModifiedEvent, follow)
        self._guis[tag] = widgets
        return int(tag)

    def disconnectGui(self: Any, tag: int) -> None:  # noqa: N802
        if self._guis.pop(tag, None) is not None:
            self.parameterNode.RemoveObserver(tag)

    namespace = {name: _field(name, kind, default) for name, (kind, default) in fields.items()}
    namespace.update(__init__=__init__, connectGui=connectGui, disconnectGui=disconnectGui)
    return type(cls.__name__, (), namespace)


def install(slicer_app: Any) -> Application:
    """Put the imitations where Slicer has them; returns `slicer.app`."""
    app = Application(slicer_app)
    qt = types.ModuleType("qt")
    qt.QTimer = QTimer  # type: ignore[attr-defined]
    ctk = types.ModuleType("ctk")
    install_widgets(qt, ctk)
    sys.modules["qt"] = qt
    sys.modules["ctk"] = ctk
    slm = types.ModuleType("slicer.ScriptedLoadableModule")
    for item in (ScriptedLoadableModule, ScriptedLoadableModuleWidget,
                 ScriptedLoadableModuleLogic, ScriptedLoadableModuleTest):
        setattr(slm, item.__name__, item)
    sys.modules["slicer.ScriptedLoadableModule"] = slm
    slicer.ScriptedLoadableModule = slm
    pnw = types.ModuleType("slicer.parameterNodeWrapper")
    pnw.parameterNodeWrapper = parameterNodeWrapper  # type: ignore[attr-defined]
    pnw.WithinRange = WithinRange  # type: ignore[attr-defined]
    sys.modules["slicer.parameterNodeWrapper"] = pnw
    slicer.parameterNodeWrapper = pnw
    slicer.app = app

    def getModuleLogic(module: Any) -> Any:  # noqa: N802
        name = module if isinstance(module, str) else getattr(module, "name", module)
        if name in app.logics:
            return app.logics[name]
        raise RuntimeError(f"Could not find module with name '{name}'")
    slicer.util.getModuleLogic = getModuleLogic
    return app

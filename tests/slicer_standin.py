"""Stand-ins of the Slicer API the ROS2Bridge module calls, kept for one user only:
tests/peers/module_link_reader.py (the operating-room tests), which times each pose by its
message header, a time Slicer's real connector keeps on no MRML node. Every other test of
the module runs in a real Slicer scene (tests/slicer_real/); do not add users here.

Only the calls checked in SlicerOpenIGTLink / OpenIGTLinkIO / Slicer sources exist on these
(see slicer_client/README.md, "Verified against"), so a misspelt or invented call
(GetStatus instead of GetCommandStatus...) fails although Slicer is absent.

`TcpConnector` is vtkMRMLIGTLConnectorNode in client mode over a real socket, as
OpenIGTLinkIO's igtlioConnector (Logic/igtlioConnector.cxx) behaves: a blocking connect
with no timeout, retried every 0.1 s; no keepalive; a receive thread whose messages reach
the scene's nodes only in `PeriodicProcess` on the main thread (one modification per
message); Connected/Disconnected events from there too; a blocking `SendCommand` loops on
`PeriodicProcess` every 5 ms until the reply or the command's timeout.
"""

from __future__ import annotations

import contextlib
import functools
import importlib.util
import inspect
import socket
import sys
import threading
import time
import types
import unittest
import weakref
from collections import deque
from pathlib import Path
from xml.etree import ElementTree as ET
from typing import Any, Callable, Deque, Dict, Optional, Tuple

import numpy as np

from protocol import framing
from protocol.messages import Command as IgtlCommand
from protocol.messages import Message, RtsCommand, Status, StatusCode
from slicer_constants import constant, event_as_observers_get_it

MODULE = Path(__file__).resolve().parents[1] / "slicer_client" / "slicer_module" / \
    "ROS2Bridge" / "ROS2Bridge.py"

MODIFIED_EVENT = constant("vtkCommand.ModifiedEvent")
TRANSFORM_MODIFIED_EVENT = constant("vtkMRMLTransformNode.TransformModifiedEvent")


class Observable:
    def __init__(self) -> None:
        self._observers: dict = {}
        self._next = 1

    def AddObserver(self, event, callback, priority=0.0):  # noqa: N802
        self._next += 1
        self._observers[self._next] = (event, callback)
        return self._next

    def RemoveObserver(self, tag):  # noqa: N802
        self._observers.pop(tag, None)

    def InvokeEvent(self, event):  # noqa: N802
        for ev, callback in list(self._observers.values()):
            if ev in (event, event_as_observers_get_it(event)):
                callback(self, event_as_observers_get_it(event))  # as VTK's wrapping does

    def Modified(self):  # noqa: N802
        self.InvokeEvent(MODIFIED_EVENT)

    def RemoveAllObservers(self):  # noqa: N802
        self._observers.clear()

    def HasObserver(self, event):  # noqa: N802
        return any(ev in (event, event_as_observers_get_it(event))
                   for ev, _ in self._observers.values())


class Node(Observable):
    """vtkMRMLNode's attributes (the connector copies each message's metadata into them
    as ``OpenIGTLink.<key>``)."""

    CLASSES: Tuple[str, ...] = ("vtkMRMLNode",)  # the node's class, then its bases

    def __init__(self) -> None:
        super().__init__()
        self.attributes: Dict[str, str] = {}
        self._scene: Any = None  # the Scene that holds it (AddNode / RemoveNode)
        self._description = ""
        self._disabled, self._pending = 0, {}

    def GetAttributeNames(self): return list(self.attributes)  # noqa: E704, N802
    def GetAttribute(self, name): return self.attributes.get(name)  # noqa: E704, N802
    def SetAttribute(self, name, value): self.attributes[name] = value  # noqa: E704, N802
    def SetHideFromEditors(self, hide): self.hidden = bool(hide)  # noqa: E704, N802
    def GetScene(self): return self._scene  # noqa: E704, N802
    def GetClassName(self): return self.CLASSES[0]  # noqa: E704, N802
    def IsA(self, name): return name in self.CLASSES  # noqa: E704, N802
    def SetDescription(self, text): self._description = text  # noqa: E704, N802
    def GetDescription(self): return self._description  # noqa: E704, N802
    def SetName(self, name): self._name = name  # noqa: E704, N802

    def CopyWithScene(self, other):  # noqa: N802
        """vtkMRMLNode::CopyWithScene: its content and its ID, kept when this node is added
        to the scene in its place."""
        self._name, self.attributes = other.GetName(), dict(other.attributes)
        self._kept_id = other.GetID()

    def StartModify(self):  # noqa: N802
        was, self._disabled = self._disabled, 1
        return was

    def EndModify(self, was):  # noqa: N802
        """vtkMRMLNode::EndModify: the events held back while modifying, once each."""
        self._disabled = was
        pending, self._pending = self._pending, {}
        if not was:
            for event in pending:
                self.InvokeEvent(event)
        return sum(pending.values())

    def GetCustomModifiedEventPending(self, event):  # noqa: N802
        return self._pending.get(event, 0)

    def _changed(self, event: int) -> None:
        """A custom modified event and ModifiedEvent: now, or at EndModify."""
        if self._disabled:
            self._pending[event] = 1
            self._pending[MODIFIED_EVENT] = 1
        else:
            self.InvokeEvent(event)
            self.Modified()


class TextNode(Node):
    TextModifiedEvent = constant("vtkMRMLTextNode.TextModifiedEvent")
    CLASSES = ("vtkMRMLTextNode", "vtkMRMLStorableNode", "vtkMRMLNode")
    _ids = 0

    def __init__(self, name: str) -> None:
        super().__init__()
        TextNode._ids += 1
        self._id, self._name, self._text, self._enc = f"vtkMRMLTextNode{self._ids}", name, "", 1

    def GetID(self): return self._id  # noqa: E704, N802
    def GetName(self): return self._name  # noqa: E704, N802
    def GetText(self): return self._text  # noqa: E704, N802

    def SetText(self, text, encoding=-1):  # noqa: N802
        if encoding >= 0 and encoding != self._enc:
            self._enc = encoding
            self._pending[self.TextModifiedEvent] = 1
        if text != self._text:
            self._text = text
            self._pending[self.TextModifiedEvent] = 1
        if not self._disabled:
            self.EndModify(0)


class StatusNode(Node):
    """vtkMRMLIGTLStatusNode: the connector calls SetStatus, then Modified, per message."""

    CLASSES = ("vtkMRMLIGTLStatusNode", "vtkMRMLNode")

    def __init__(self, name: str) -> None:
        super().__init__()
        self._name = name
        self._id = "vtkMRMLIGTLStatusNode" + name
        self.code, self.error_name, self.text = 0, "", ""

    def GetID(self): return self._id  # noqa: E704, N802
    def GetName(self): return self._name  # noqa: E704, N802
    def GetCode(self): return self.code  # noqa: E704, N802
    def GetErrorName(self): return self.error_name  # noqa: E704, N802
    def GetStatusString(self): return self.text  # noqa: E704, N802


class Command(Observable):
    """vtkSlicerOpenIGTLinkCommand. `script`: for the plain `Connector`, the (status,
    response) each send ends with."""

    script: list = []
    CommandCompletedEvent = constant("vtkSlicerOpenIGTLinkCommand.CommandCompletedEvent")
    CommandWaiting = 1

    def __init__(self) -> None:
        super().__init__()
        self.name = self.content = ""
        self.timeout, self.blocking, self.status, self.response = 0.0, False, 0, ""

    def SetName(self, name): self.name = name  # noqa: E704, N802
    def SetCommandContent(self, text): self.content = text  # noqa: E704, N802
    def SetTimeoutSec(self, seconds): self.timeout = seconds  # noqa: E704, N802
    def SetBlocking(self, on): self.blocking = on  # noqa: E704, N802
    def GetResponseContent(self): return self.response  # noqa: E704, N802
    def GetCommandStatus(self): return self.status  # noqa: E704, N802
    def GetErrorMessage(self): return ""  # noqa: E704, N802


class Connector(Node):
    """vtkMRMLIGTLConnectorNode with no socket: commands end as `Command.script` says."""

    ConnectedEvent = constant("vtkMRMLIGTLConnectorNode.ConnectedEvent")
    DisconnectedEvent = constant("vtkMRMLIGTLConnectorNode.DisconnectedEvent")
    StateOff = constant("vtkMRMLIGTLConnectorNode.StateOff")
    StateWaitConnection = constant("vtkMRMLIGTLConnectorNode.StateWaitConnection")
    StateConnected = constant("vtkMRMLIGTLConnectorNode.StateConnected")
    CLASSES = ("vtkMRMLIGTLConnectorNode", "vtkMRMLNode")

    def __init__(self, name: str = "") -> None:
        super().__init__()
        self._name, self._id = name, "vtkMRMLIGTLConnectorNode" + name
        self.state, self.sent, self.pushed, self.outgoing = 2, [], [], []
        self.incoming: list = []
        self.commands: list = []
        self.periodic = 0

    def GetState(self): return self.state  # noqa: E704, N802
    def GetName(self): return self._name  # noqa: E704, N802
    def GetID(self): return self._id  # noqa: E704, N802
    def GetServerHostname(self): return "127.0.0.1"  # noqa: E704, N802
    def GetServerPort(self): return 18944  # noqa: E704, N802
    def GetNumberOfOutgoingMRMLNodes(self): return len(self.outgoing)  # noqa: E704, N802
    def GetOutgoingMRMLNode(self, i): return self.outgoing[i]  # noqa: E704, N802
    def GetNumberOfIncomingMRMLNodes(self): return len(self.incoming)  # noqa: E704, N802
    def GetIncomingMRMLNode(self, i): return self.incoming[i]  # noqa: E704, N802

    def PeriodicProcess(self):  # noqa: N802
        self.periodic += 1

    def RegisterOutgoingMRMLNode(self, node, devType=None):  # noqa: N802
        self.outgoing.append(node)  # the connector then pushes on TextModifiedEvent
        node.AddObserver(TextNode.TextModifiedEvent, lambda n, e: self.pushed.append(n._text))
        return 1

    def PushNode(self, node):  # noqa: N802
        self.pushed.append(node._text)
        return 0

    def forget(self, node: Any) -> None:
        """The scene removed `node`: the connector no longer updates or sends it."""
        self.incoming = [n for n in self.incoming if n is not node]
        self.outgoing = [n for n in self.outgoing if n is not node]

    def SendCommand(self, command):  # noqa: N802
        self.sent.append((command.name, command.content, command.blocking, command.timeout))
        self.commands.append(command)
        command.status, command.response = Command.script.pop(0)


class Scene(Observable):
    """vtkMRMLScene: its nodes (AddNode gives each a unique id, as the scene does), the
    classes AddNewNodeByClass can make (NODE_CLASSES), RemoveNode and Clear, and the
    save/close events the module observes."""

    StartSaveEvent = constant("vtkMRMLScene.StartSaveEvent")
    StartCloseEvent = constant("vtkMRMLScene.StartCloseEvent")
    EndCloseEvent = constant("vtkMRMLScene.EndCloseEvent")
    EndImportEvent = constant("vtkMRMLScene.EndImportEvent")

    def __init__(self) -> None:
        super().__init__()
        self.nodes: list = []
        self._counts: Dict[str, int] = {}
        self.subject_hierarchy: Any = None  # made by GetSubjectHierarchyNode

    def GetFirstNode(self, name, cls):  # noqa: N802
        return next((n for n in self.nodes if n.GetName() == name and n.IsA(cls)), None)

    def GetNodeByID(self, node_id):  # noqa: N802
        return next((n for n in self.nodes if n.GetID() == node_id), None)

    def AddNode(self, node):  # noqa: N802
        cls = node.GetClassName() if hasattr(node, "GetClassName") else type(node).__name__
        kept = getattr(node, "_kept_id", None)  # an ID the node was given: kept if free
        if kept and self.GetNodeByID(kept) is None:
            node._id, node._scene = kept, self
        else:
            self._counts[cls] = self._counts.get(cls, 0) + 1
            node._id, node._scene = f"{cls}{self._counts[cls]}", self
        self.nodes.append(node)
        if isinstance(node, MarkupsFiducialNode) and node.GetDisplayNode() is None:
            node.CreateDefaultDisplayNodes()  # as the Markups module does on NodeAddedEvent
        return node

    def AddNewNodeByClass(self, cls, name=""):  # noqa: N802
        made = NODE_CLASSES.get(cls)
        if made is None:
            raise ValueError(f"the stand-in scene cannot make a {cls}")
        node = made(name)
        return self.AddNode(node)

    def AddNewNodeByClassWithID(self, cls, name, node_id):  # noqa: N802
        node = NODE_CLASSES[cls](name)
        node._kept_id = node_id
        return self.AddNode(node)

    def RemoveNode(self, node):  # noqa: N802
        if node not in self.nodes:
            return
        self.nodes.remove(node)
        node._scene = None
        for connector in self.nodes:  # the connector forgets its removed nodes
            if isinstance(connector, Connector):
                connector.forget(node)
        if self.subject_hierarchy is not None:
            self.subject_hierarchy.forget(node)

    def Clear(self, removeSingletons=0):  # noqa: N802, N803
        self.InvokeEvent(self.StartCloseEvent)
        for node in list(self.nodes):
            if isinstance(node, TcpConnector):
                node.Stop()
            self.RemoveNode(node)
        self.subject_hierarchy = None
        self.InvokeEvent(self.EndCloseEvent)

    def IsNodeClassRegistered(self, cls):  # noqa: N802
        return cls in NODE_CLASSES


def install_slicer(setitem: Callable[[str, types.ModuleType], None],
                   real_vtk: bool = False) -> types.ModuleType:
    """Put the stand-in `slicer`, `qt`, `vtk` and `ctk` modules where `import` finds them
    (``setitem(name, module)``: sys.modules' own, or a test's monkeypatch). `real_vtk`: the
    real VTK (installed from PyPI) instead of the two constants the transport's text path
    needs, for the scene's model, markups and transform nodes."""
    slicer = types.ModuleType("slicer")
    slicer.mrmlScene = Scene()
    slicer.app = App()  # startupCompleted(), processEvents()
    slicer.vtkMRMLIGTLConnectorNode = Connector
    slicer.vtkSlicerOpenIGTLinkCommand = Command
    slicer.vtkMRMLTextNode = TextNode
    slicer.vtkMRMLTransformNode = TransformNode
    slicer.vtkMRMLLinearTransformNode = TransformNode
    slicer.vtkMRMLScriptedModuleNode = ScriptedModuleNode
    slicer.vtkMRMLModelNode = ModelNode
    slicer.vtkMRMLMarkupsNode = MarkupsFiducialNode
    slicer.vtkMRMLSubjectHierarchyNode = SubjectHierarchyNode
    slm = types.ModuleType("slicer.ScriptedLoadableModule")
    slm.ScriptedLoadableModule = ScriptedLoadableModule
    slm.ScriptedLoadableModuleLogic = ScriptedLoadableModuleLogic
    slm.ScriptedLoadableModuleWidget = ScriptedLoadableModuleWidget
    slm.ScriptedLoadableModuleTest = type("ScriptedLoadableModuleTest",
                                          (ScriptedLoadableModuleTest,), {"displayed": []})
    pnw = types.ModuleType("slicer.parameterNodeWrapper")
    pnw.parameterNodeWrapper = parameter_node_wrapper
    pnw.WithinRange = lambda lo, hi: (lo, hi)
    util = types.ModuleType("slicer.util")
    util.VTKObservationMixin = VTKObservationMixin
    util.loadUI, util.childWidgetVariables = load_ui, child_widget_variables
    util.errors = []  # what tryWithErrorDisplay showed
    util.tryWithErrorDisplay = functools.partial(try_with_error_display, util.errors)
    util.getNodesByClass = lambda cls, scene=None: [
        n for n in (scene or slicer.mrmlScene).nodes if n.IsA(cls)]
    util.arrayFromModelPointData = array_from_model_point_data
    util.moduleLogics = {}  # name -> logic: what getModuleLogic answers (the test fills it)
    util.getModuleLogic = lambda module: util.moduleLogics.get(module)
    util.exit = exit_slicer
    slicer.ScriptedLoadableModule, slicer.parameterNodeWrapper, slicer.util = slm, pnw, util
    if real_vtk:
        import vtk as real
        vtk: types.ModuleType = real
    else:
        vtk = types.ModuleType("vtk")
        vtk.vtkCommand = types.SimpleNamespace(ModifiedEvent=MODIFIED_EVENT)
    qt = types.ModuleType("qt")
    qt.QTimer = type("QTimer", (Timer,), {"app": slicer.app})  # fired by this app's loop
    ctk = types.ModuleType("ctk")
    ctk.ctkSliderWidget = lambda: UiWidget("ctkSliderWidget", "", {}, {})
    for name, module in (("slicer", slicer), ("slicer.ScriptedLoadableModule", slm),
                         ("slicer.parameterNodeWrapper", pnw), ("slicer.util", util),
                         ("qt", qt), ("vtk", vtk), ("ctk", ctk)):
        setitem(name, module)
    return slicer


def load_module(setitem: Callable[[str, types.ModuleType], None], real_vtk: bool = False) -> Any:
    """ROS2Bridge.py, imported over the stand-ins. Its folder goes on sys.path, as Slicer
    puts it there when it loads the module (qSlicerScriptedLoadableModuleFactory.cxx), and
    ROS2BridgeLib is imported afresh, over these stand-ins rather than an earlier test's."""
    install_slicer(setitem, real_vtk)
    if str(MODULE.parent) not in sys.path:
        sys.path.insert(0, str(MODULE.parent))
    for name in [name for name in sys.modules if name.split(".")[0] == "ROS2BridgeLib"]:
        del sys.modules[name]
    spec = importlib.util.spec_from_file_location("ROS2Bridge_under_test", MODULE)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# --- the module's classes and GUI: ScriptedLoadableModule.py, util.py, parameterNodeWrapper ---
class Signals:
    """PythonQt's `connect("signal(args)", slot)`; `emit` is the test's hand on the widget."""

    def __init__(self) -> None:
        self.slots: Dict[str, list] = {}
        self.blocked = False

    def connect(self, signal: str, slot: Callable[..., Any]) -> bool:
        self.slots.setdefault(signal, []).append(slot)
        return True

    def blockSignals(self, block: bool) -> bool:  # noqa: N802
        was, self.blocked = self.blocked, bool(block)
        return was

    def emit(self, signal: str, *args: Any) -> None:
        """Calls each slot with as many of the signal's arguments as it takes, as PythonQt
        does (Slicer's template connects clicked(bool) to a slot without arguments)."""
        if self.blocked:
            return
        for slot in list(self.slots.get(signal, [])):
            try:
                parameters = inspect.signature(slot).parameters.values()
            except (TypeError, ValueError):  # a builtin: give it everything
                slot(*args)
                continue
            if any(p.kind is p.VAR_POSITIONAL for p in parameters):
                slot(*args)
            else:
                slot(*args[:sum(p.default is p.empty for p in parameters)])


class Timer(Signals):
    """qt.QTimer: fires only in its app's `processEvents` (a test's event loop), or when a
    test calls the slot."""

    app: Any = None  # the App whose processEvents fires it (install_slicer's QTimer)

    def __init__(self) -> None:
        super().__init__()
        self.interval, self.active, self.last = 0, False, 0.0
        if self.app is not None:
            self.app.timers.add(self)

    def setInterval(self, ms: int) -> None: self.interval = ms  # noqa: E704, N802
    def stop(self) -> None: self.active = False  # noqa: E704

    def start(self) -> None:
        self.active, self.last = True, time.monotonic()


class App(Signals):
    """slicer.app: `processEvents` runs what Slicer's event loop would in one pass: the
    OpenIGTLinkIF logic's connector timer (PeriodicProcess of each running connector
    node of the scene), then every active QTimer that is due."""

    def __init__(self) -> None:
        super().__init__()
        self.timers: "weakref.WeakSet[Timer]" = weakref.WeakSet()

    def processEvents(self) -> None:  # noqa: N802
        import slicer
        for node in list(slicer.mrmlScene.nodes):
            if isinstance(node, Connector) and node.GetState() != Connector.StateOff:
                node.PeriodicProcess()
        now = time.monotonic()
        for timer in list(self.timers):
            if timer.active and now - timer.last >= timer.interval / 1000.0:
                timer.last = now
                timer.emit("timeout()")


class FormLayout:
    """QFormLayout's rows (rowCount, removeRow, addRow: Qt 5.8+)."""

    def __init__(self) -> None:
        self.rows: list = []

    def rowCount(self) -> int: return len(self.rows)  # noqa: E704, N802
    def removeRow(self, row: int) -> None: del self.rows[row]  # noqa: E704, N802
    def addRow(self, label: Any, field: Any = None) -> None: self.rows.append((label, field))  # noqa: E704, E501, N802


class UiWidget(Signals):
    """A widget of a .ui file: its designer properties as attributes (text, checked...),
    its dynamic ones (stdset="0", e.g. SlicerParameterName) through `property()`, and the
    few methods the module calls on combo boxes, lists, node selectors and containers."""

    def __init__(self, class_name: str, name: str, properties: Dict[str, Any],
                 dynamic: Dict[str, Any], items: Optional[list] = None) -> None:
        super().__init__()
        self.class_name, self.name, self._dynamic = class_name, name, dynamic
        self.text, self.checked, self.value = "", False, 0
        self.__dict__.update(properties)
        self.items = list(items or [])
        self.currentText = self.items[0] if self.items else ""
        self.form = FormLayout()
        self.scene: Any = None
        self.current_node: Any = None

    def property(self, name: str) -> Any: return self._dynamic.get(name)  # noqa: E704
    def layout(self) -> FormLayout: return self.form  # noqa: E704
    def currentNode(self) -> Any: return self.current_node  # noqa: E704, N802

    def addItem(self, text: str) -> None:  # noqa: N802
        self.items.append(text)
        self.currentText = self.currentText or text

    def clear(self) -> None:
        self.items, self.currentText = [], ""

    def setMRMLScene(self, scene: Any) -> None:  # noqa: N802
        self.scene = scene  # qMRMLWidget passes it on: mrmlSceneChanged(vtkMRMLScene*)
        self.emit("mrmlSceneChanged(vtkMRMLScene*)", scene)


def _designer_value(prop: ET.Element) -> Any:
    value = prop[0]
    if value.tag == "bool":
        return value.text == "true"
    if value.tag == "number":
        return int(value.text or 0)
    if value.tag == "stringlist":
        return [item.text or "" for item in value]
    return value.text or ""


def load_ui(path: str) -> UiWidget:
    """slicer.util.loadUI: the .ui's widgets, each one named; the top one's `children`
    are all the others; the file's signal/slot connections made."""
    root = ET.parse(path).getroot()
    made: Dict[str, UiWidget] = {}
    for element in root.iter("widget"):
        properties: Dict[str, Any] = {}
        dynamic: Dict[str, Any] = {}
        for prop in element.findall("property"):
            target = dynamic if prop.get("stdset") == "0" else properties
            target[prop.get("name", "")] = _designer_value(prop)
        items = [_designer_value(item.find("property")) for item in element.findall("item")]
        made[element.get("name", "")] = UiWidget(element.get("class", ""), element.get("name", ""),
                                                 properties, dynamic, items)
    for connection in root.iter("connection"):
        receiver = made[connection.findtext("receiver", "")]
        slot = connection.findtext("slot", "").split("(")[0]
        made[connection.findtext("sender", "")].connect(connection.findtext("signal", ""),
                                                       getattr(receiver, slot))
    top = made[root.find("widget").get("name", "")]  # type: ignore[union-attr]
    top.children = list(made.values())  # type: ignore[attr-defined]
    return top


def child_widget_variables(widget: UiWidget) -> Any:
    """slicer.util.childWidgetVariables: every named widget (the top one included)."""
    return types.SimpleNamespace(**{w.name: w for w in widget.children})  # type: ignore


def try_with_error_display(shown: list, message: str, show: bool = True,
                           waitCursor: bool = False) -> Any:  # noqa: N803
    """slicer.util.tryWithErrorDisplay: shows the message, then re-raises."""
    @contextlib.contextmanager
    def guard() -> Any:
        try:
            yield
        except Exception as error:
            shown.append(f"{message} {error}")
            raise
    return guard()


class VTKObservationMixin:
    """slicer.util.VTKObservationMixin: observers kept as (object, event, method, tag)."""

    def __init__(self) -> None:
        self.Observations: list = []

    def addObserver(self, obj: Any, event: Any, method: Any, priority: float = 0.0) -> None:  # noqa: N802
        self.Observations.append((obj, event, method, obj.AddObserver(event, method)))

    def removeObservers(self, method: Any = None) -> None:  # noqa: N802
        self.Observations = [o for o in self.Observations
                             if method is not None and o[2] != method]

    def hasObserver(self, obj: Any, event: Any, method: Any) -> bool:  # noqa: N802
        return any(o[:3] == (obj, event, method) for o in self.Observations)

    def removeObserver(self, obj: Any, event: Any, method: Any) -> None:  # noqa: N802
        for o in [o for o in self.Observations if o[:3] == (obj, event, method)]:
            obj.RemoveObserver(o[3])
            self.Observations.remove(o)


class ScriptedLoadableModule:
    def __init__(self, parent: Any) -> None:
        self.parent = parent


class ScriptedLoadableModuleLogic:
    """getParameterNode: the scene's one parameter node of the module (a plain dict here)."""

    def __init__(self) -> None:
        pass

    def getParameterNode(self) -> Dict[str, Any]:  # noqa: N802
        import slicer
        return slicer.mrmlScene.__dict__.setdefault("parameterNode", {})


class ScriptedLoadableModuleWidget:
    """The widget's parent, its layout, and resourcePath (the module folder's Resources)."""

    def __init__(self, parent: Any = None) -> None:
        self.parent = parent or types.SimpleNamespace(isEntered=True)
        self.layout = types.SimpleNamespace(widgets=[])
        self.layout.addWidget = self.layout.widgets.append

    def setup(self) -> None:
        pass

    def resourcePath(self, filename: str) -> str:  # noqa: N802
        return str(MODULE.parent / "Resources" / filename)


def parameter_node_wrapper(cls: type) -> type:
    """parameterNodeWrapper: typed attributes stored in the parameter node (defaults from
    the class), and connectGui over widgets carrying a SlicerParameterName property:
    QLineEdit <-> str (textChanged), QSpinBox <-> int (valueChanged); an unknown name raises."""
    names = list(cls.__annotations__)
    defaults = {name: getattr(cls, name) for name in names}
    gui_field = {"QLineEdit": ("text", "textChanged(QString)"),
                 "QSpinBox": ("value", "valueChanged(int)")}

    def init(self: Any, node: Dict[str, Any]) -> None:
        object.__setattr__(self, "_node", node)
        node.setdefault("_guis", {})

    def get(self: Any, name: str) -> Any:
        return self._node.get(name, defaults[name])

    def set_(self: Any, name: str, value: Any) -> None:
        self._node[name] = value
        for gui in self._node["_guis"].values():  # the GUI follows the parameter node
            if name in gui:
                setattr(gui[name], gui_field[gui[name].class_name][0], value)

    def connect_gui(self: Any, ui: Any) -> int:
        widgets = {w.property("SlicerParameterName"): w for w in vars(ui).values()
                   if w.property("SlicerParameterName")}
        for name, widget in widgets.items():
            if name not in names:
                raise ValueError(f"no parameter {name!r}")
            attribute, signal = gui_field[widget.class_name]
            setattr(widget, attribute, get(self, name))
            widget.connect(signal, functools.partial(lambda n, v: set_(self, n, v), name))
        tag = len(self._node["_guis"]) + 1
        self._node["_guis"][tag] = widgets
        return tag

    def disconnect_gui(self: Any, tag: int) -> None:
        self._node["_guis"].pop(tag, None)

    attributes: Dict[str, Any] = {
        name: property(functools.partial(lambda n, self: get(self, n), name),
                       functools.partial(lambda n, self, v: set_(self, n, v), name))
        for name in names}
    attributes.update(__init__=init, connectGui=connect_gui, disconnectGui=disconnect_gui)
    return type(cls.__name__, (), attributes)


class _Transformable:
    """vtkMRMLTransformableNode: the id of the transform node it is under."""

    _parent_id: Optional[str] = None

    def SetAndObserveTransformNodeID(self, node_id):  # noqa: N802
        self._parent_id = node_id
        return True

    def GetTransformNodeID(self): return self._parent_id  # noqa: E704, N802

    def GetParentTransformNode(self):  # noqa: N802
        scene = self.GetScene()  # type: ignore[attr-defined]
        return scene.GetNodeByID(self._parent_id) if scene and self._parent_id else None


def _to_world(node: Any) -> np.ndarray:
    """The matrix from `node`'s coordinates to the world: its own transform (a transform
    node) and those of every parent above it."""
    matrix = np.eye(4)
    while node is not None:
        if isinstance(node, TransformNode):
            matrix = node.matrix @ matrix
        node = node.GetParentTransformNode()
    return matrix


class _Displayable:
    """vtkMRMLDisplayableNode: its display nodes (ids), made in the scene."""

    DISPLAY_CLASS = ""
    _display_ids: list

    def AddAndObserveDisplayNodeID(self, node_id):  # noqa: N802
        self._display_ids.append(node_id)

    def GetNumberOfDisplayNodes(self): return len(self._display_ids)  # noqa: E704, N802

    def GetNthDisplayNode(self, i):  # noqa: N802
        scene = self.GetScene()  # type: ignore[attr-defined]
        return scene.GetNodeByID(self._display_ids[i]) if scene else None

    def GetDisplayNode(self):  # noqa: N802
        return self.GetNthDisplayNode(0) if self._display_ids else None

    def CreateDefaultDisplayNodes(self):  # noqa: N802
        scene = self.GetScene()  # type: ignore[attr-defined]
        if scene is None or self._display_ids:
            return
        self.AddAndObserveDisplayNodeID(scene.AddNewNodeByClass(self.DISPLAY_CLASS).GetID())


class TransformNode(_Transformable, _Displayable, Node):
    """vtkMRMLLinearTransformNode: `matrix` (numpy) to its parent transform."""

    CLASSES = ("vtkMRMLLinearTransformNode", "vtkMRMLTransformNode", "vtkMRMLDisplayableNode",
               "vtkMRMLTransformableNode", "vtkMRMLStorableNode", "vtkMRMLNode")
    TransformModifiedEvent = TRANSFORM_MODIFIED_EVENT
    DISPLAY_CLASS = "vtkMRMLTransformDisplayNode"

    def __init__(self, name: str = "") -> None:
        super().__init__()
        self._name, self._id = name, "vtkMRMLLinearTransformNode" + name
        self.matrix = np.eye(4)
        self._display_ids: list = []

    def GetID(self): return self._id  # noqa: E704, N802
    def GetName(self): return self._name  # noqa: E704, N802

    def GetMatrixTransformToParent(self, out):  # noqa: N802
        for i in range(4):
            for j in range(4):
                out.SetElement(i, j, float(self.matrix[i, j]))
        return 1

    def SetMatrixTransformToParent(self, matrix):  # noqa: N802
        self.matrix = np.array([[matrix.GetElement(i, j) for j in range(4)] for i in range(4)])
        self._changed(TRANSFORM_MODIFIED_EVENT)

    @staticmethod
    def GetTransformBetweenNodes(source, target, transform):  # noqa: N802
        """vtkMRMLTransformNode::GetTransformBetweenNodes (None: the world), linear only."""
        from vtkmodules.vtkCommonMath import vtkMatrix4x4
        matrix = _to_world(source)
        if target is not None:
            matrix = np.linalg.inv(_to_world(target)) @ matrix
        vtk_matrix = vtkMatrix4x4()
        for i in range(4):
            for j in range(4):
                vtk_matrix.SetElement(i, j, float(matrix[i, j]))
        transform.Identity()
        transform.Concatenate(vtk_matrix)
        return 1


class ModelNode(_Transformable, _Displayable, Node):
    """vtkMRMLModelNode: a vtkPolyData (real VTK) and its display nodes."""

    CLASSES = ("vtkMRMLModelNode", "vtkMRMLDisplayableNode", "vtkMRMLTransformableNode",
               "vtkMRMLStorableNode", "vtkMRMLNode")
    MeshModifiedEvent = constant("vtkMRMLModelNode.MeshModifiedEvent")
    DISPLAY_CLASS = "vtkMRMLModelDisplayNode"

    def __init__(self, name: str = "") -> None:
        super().__init__()
        self._name, self._id, self._polydata, self._display_ids = name, "", None, []

    def GetID(self): return self._id  # noqa: E704, N802
    def GetName(self): return self._name  # noqa: E704, N802
    def GetPolyData(self): return self._polydata  # noqa: E704, N802

    def SetAndObservePolyData(self, polydata):  # noqa: N802
        self._polydata = polydata
        self._changed(self.MeshModifiedEvent)


class DisplayNode(Node):
    """vtkMRMLDisplayNode's colour, opacity and scalar settings."""

    CLASSES = ("vtkMRMLDisplayNode", "vtkMRMLNode")

    def __init__(self, name: str = "") -> None:
        super().__init__()
        self._name, self._id = name, ""
        self.color, self.selected_color, self.opacity = (0.5, 0.5, 0.5), (1.0, 0.5, 0.5), 1.0
        self.active_scalar: Tuple[Any, Any] = (None, None)
        self.scalar_range_flag, self.scalar_visibility = "UseData", False

    def GetID(self): return self._id  # noqa: E704, N802
    def GetName(self): return self._name  # noqa: E704, N802
    def SetColor(self, r, g, b): self.color = (float(r), float(g), float(b))  # noqa: E704, N802
    def GetColor(self): return self.color  # noqa: E704, N802
    def SetSelectedColor(self, r, g, b): self.selected_color = (float(r), float(g), float(b))  # noqa: E704, E501, N802
    def GetSelectedColor(self): return self.selected_color  # noqa: E704, N802
    def SetOpacity(self, opacity): self.opacity = float(opacity)  # noqa: E704, N802
    def GetOpacity(self): return self.opacity  # noqa: E704, N802
    def SetActiveScalar(self, name, location): self.active_scalar = (name, location)  # noqa: E704, E501, N802
    def GetActiveScalarName(self): return self.active_scalar[0]  # noqa: E704, N802
    def SetScalarRangeFlagFromString(self, flag): self.scalar_range_flag = flag  # noqa: E704, N802
    def GetScalarRangeFlagAsString(self): return self.scalar_range_flag  # noqa: E704, N802
    def SetScalarVisibility(self, on): self.scalar_visibility = bool(on)  # noqa: E704, N802
    def GetScalarVisibility(self): return self.scalar_visibility  # noqa: E704, N802


class ModelDisplayNode(DisplayNode):
    CLASSES = ("vtkMRMLModelDisplayNode", "vtkMRMLDisplayNode", "vtkMRMLNode")


class MarkupsDisplayNode(DisplayNode):
    CLASSES = ("vtkMRMLMarkupsDisplayNode", "vtkMRMLDisplayNode", "vtkMRMLNode")


class MarkupsFiducialNode(_Transformable, _Displayable, Node):
    """vtkMRMLMarkupsFiducialNode: control points (position, label) as vtkMRMLMarkupsNode.h
    declares them; AddControlPoint takes a vtkVector3d or x, y, z."""

    CLASSES = ("vtkMRMLMarkupsFiducialNode", "vtkMRMLMarkupsNode", "vtkMRMLDisplayableNode",
               "vtkMRMLTransformableNode", "vtkMRMLStorableNode", "vtkMRMLNode")
    PointModifiedEvent = constant("vtkMRMLMarkupsNode.PointModifiedEvent")
    DISPLAY_CLASS = "vtkMRMLMarkupsDisplayNode"

    def __init__(self, name: str = "") -> None:
        super().__init__()
        self._name, self._id, self._display_ids = name, "", []
        self.points: list = []  # [[x, y, z], label]

    def GetID(self): return self._id  # noqa: E704, N802
    def GetName(self): return self._name  # noqa: E704, N802
    def GetNumberOfControlPoints(self): return len(self.points)  # noqa: E704, N802
    def GetNthControlPointLabel(self, i): return self.points[i][1]  # noqa: E704, N802

    def AddControlPoint(self, *args):  # noqa: N802
        if len(args) >= 3:
            position, label = [float(v) for v in args[:3]], (args[3] if len(args) > 3 else "")
        else:
            vector = args[0]
            position = [vector.GetX(), vector.GetY(), vector.GetZ()]
            label = args[1] if len(args) > 1 else ""
        self.points.append([position, label])
        self._changed(self.PointModifiedEvent)
        return len(self.points) - 1

    def SetNthControlPointPosition(self, i, x, y, z):  # noqa: N802
        self.points[i][0] = [float(x), float(y), float(z)]
        self._changed(self.PointModifiedEvent)

    def SetNthControlPointLabel(self, i, label):  # noqa: N802
        self.points[i][1] = label
        self._changed(self.PointModifiedEvent)

    def RemoveAllControlPoints(self):  # noqa: N802
        self.points = []
        self._changed(self.PointModifiedEvent)

    def GetNthControlPointPositionWorld(self, i, out):  # noqa: N802
        world = _to_world(self.GetParentTransformNode()) @ np.array([*self.points[i][0], 1.0])
        out[0], out[1], out[2] = (float(v) for v in world[:3])


class SubjectHierarchyNode:
    """vtkMRMLSubjectHierarchyNode: items (name, parent, data node); the scene's item is 1,
    0 is the invalid item. A data node's item is made under the scene when first asked
    for (Slicer makes it as the node is added)."""

    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        self.items: Dict[int, list] = {1: ["Scene", 0, None]}
        self._next = 2

    @staticmethod
    def GetSubjectHierarchyNode(scene):  # noqa: N802
        if scene.subject_hierarchy is None:
            scene.subject_hierarchy = SubjectHierarchyNode(scene)
        return scene.subject_hierarchy

    def _new(self, name: str, parent: int, node: Any) -> int:
        item, self._next = self._next, self._next + 1
        self.items[item] = [name, parent, node]
        return item

    def GetSceneItemID(self): return 1  # noqa: E704, N802
    def CreateFolderItem(self, parent, name): return self._new(name, parent, None)  # noqa: E704, N802
    def GetItemName(self, item): return self.items[item][0] if item in self.items else ""  # noqa: E704, N802
    def GetItemParent(self, item): return self.items[item][1] if item in self.items else 0  # noqa: E704, N802
    def GetItemDataNode(self, item): return self.items[item][2] if item in self.items else None  # noqa: E704, E501, N802

    def GetItemByName(self, name):  # noqa: N802
        return next((i for i, (n, _, _) in self.items.items() if n == name), 0)

    def GetItemChildWithName(self, parent, name):  # noqa: N802
        return next((i for i, (n, p, _) in self.items.items() if p == parent and n == name), 0)

    def GetItemByDataNode(self, node):  # noqa: N802
        found = next((i for i, (_, _, d) in self.items.items() if d is node), 0)
        if not found and node.GetScene() is self.scene:
            found = self._new(node.GetName(), 1, node)
        return found

    def SetItemParent(self, item, parent):  # noqa: N802
        self.items[item][1] = parent

    def RemoveItem(self, item, removeDataNode=True, recursive=True):  # noqa: N802, N803
        if item not in self.items or item == 1:
            return False
        if recursive:
            for child in [i for i, (_, p, _) in self.items.items() if p == item]:
                self.RemoveItem(child, removeDataNode, recursive)
        _, _, node = self.items.pop(item)
        if removeDataNode and node is not None:
            self.scene.RemoveNode(node)
        return True

    def forget(self, node: Any) -> None:
        for item in [i for i, (_, _, d) in self.items.items() if d is node]:
            del self.items[item]


class ScriptedLoadableModuleTest(unittest.TestCase):
    """ScriptedLoadableModule.py's test base: a unittest.TestCase with delayDisplay (which
    here records the message in `displayed`)."""

    displayed: list = []

    def delayDisplay(self, message, requestedDelay=None, msec=None):  # noqa: N802
        self.displayed.append(message)


def exit_slicer(status: int = 0) -> None:
    """slicer.util.exit: ends the application with `status`."""
    raise SystemExit(status)


def array_from_model_point_data(node: Any, name: str) -> Any:
    """slicer.util.arrayFromModelPointData: a numpy view of a point-data array."""
    from vtkmodules.util.numpy_support import vtk_to_numpy
    return vtk_to_numpy(node.GetPolyData().GetPointData().GetArray(name))


def vtk_from_polydata(body: Any) -> Any:
    """What OpenIGTLinkIO's PolyData converter makes of a POLYDATA: a vtkPolyData with the
    points, cells and attribute arrays (each named as on the wire). Of VERTICES it makes
    one vtkVertex of the first id of each cell, and it writes the second cell's id past
    its vtkVertex (Slicer dies): here, an error."""
    from vtkmodules.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray
    from vtkmodules.vtkCommonCore import vtkPoints
    from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData
    polydata = vtkPolyData()
    points = vtkPoints()
    points.SetData(numpy_to_vtk(np.asarray(body.points, dtype=np.float32).reshape(-1, 3),
                                deep=True))
    polydata.SetPoints(points)
    for section, setter in (("vertices", polydata.SetVerts), ("lines", polydata.SetLines),
                            ("polygons", polydata.SetPolys),
                            ("triangle_strips", polydata.SetStrips)):
        flat = np.asarray(getattr(body, section), dtype=np.int64)
        if section == "vertices" and flat.size:
            if int(flat[0]) + 1 != flat.size:
                raise RuntimeError("more than one VERTICES cell: OpenIGTLinkIO's converter "
                                   "writes past a vtkVertex (3D Slicer crashes)")
            flat = np.array([1, flat[1]], dtype=np.int64) if flat[0] else flat[:0]
        if flat.size:
            cells = vtkCellArray()
            cells.ImportLegacyFormat(numpy_to_vtkIdTypeArray(flat, deep=True))
            setter(cells)
    for attribute in body.attributes:
        data = np.asarray(attribute.data, dtype=np.float32)
        array = numpy_to_vtk(data.reshape(len(data), -1), deep=True)
        array.SetName(attribute.name)
        target = polydata.GetCellData() if attribute.on_cells else polydata.GetPointData()
        target.AddArray(array)
    return polydata


def polydata_from_vtk(polydata: Any) -> Any:
    """What OpenIGTLinkIO's PolyData converter sends of a vtkPolyData (points and cells)."""
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkCommonCore import vtkIdTypeArray

    from protocol.messages import PolyData

    def flat(cells: Any) -> np.ndarray:
        out = vtkIdTypeArray()
        cells.ExportLegacyFormat(out)
        return vtk_to_numpy(out).astype(np.uint32) if out.GetNumberOfTuples() else \
            np.zeros(0, dtype=np.uint32)
    points = polydata.GetPoints()
    return PolyData(
        points=(vtk_to_numpy(points.GetData()).astype(np.float32) if points is not None
                else np.zeros((0, 3), dtype=np.float32)),
        vertices=flat(polydata.GetVerts()), lines=flat(polydata.GetLines()),
        polygons=flat(polydata.GetPolys()), triangle_strips=flat(polydata.GetStrips()))


def outgoing_message(node: Any) -> Message:
    """The message the connector sends for an outgoing node (header v2, no metadata)."""
    from protocol.messages import Point, PointElement, String, Transform
    name = node.GetName()
    if node.IsA("vtkMRMLTextNode"):
        return Message(name, String(node.GetText(), encoding=node._enc))
    if node.IsA("vtkMRMLLinearTransformNode"):
        return Message(name, Transform(np.array(node.matrix, dtype=np.float64)))
    if node.IsA("vtkMRMLModelNode"):
        return Message(name, polydata_from_vtk(node.GetPolyData()))
    if node.IsA("vtkMRMLMarkupsNode"):
        return Message(name, Point([PointElement(name=label, group="Fiducial",
                                                 position=np.array(position))
                                    for position, label in node.points]))
    raise TypeError(f"the connector cannot send a {node.GetClassName()}")


class ScriptedModuleNode(Node):
    """vtkMRMLScriptedModuleNode: a node with a name and attributes (the reference's
    nodes are made on it: the module's ROS2BridgeLib/scene_nodes.py)."""

    CLASSES = ("vtkMRMLScriptedModuleNode", "vtkMRMLNode")

    def __init__(self, name: str = "") -> None:
        super().__init__()
        self._name, self._id = name, ""

    def GetID(self): return self._id  # noqa: E704, N802
    def GetName(self): return self._name  # noqa: E704, N802


NODE_CLASSES: Dict[str, Callable[[str], Any]] = {
    "vtkMRMLScriptedModuleNode": ScriptedModuleNode, "vtkMRMLTextNode": TextNode,
    "vtkMRMLLinearTransformNode": TransformNode,
    "vtkMRMLModelNode": ModelNode, "vtkMRMLModelDisplayNode": ModelDisplayNode,
    "vtkMRMLMarkupsFiducialNode": MarkupsFiducialNode,
    "vtkMRMLMarkupsDisplayNode": MarkupsDisplayNode,
    "vtkMRMLIGTLConnectorNode": lambda name: TcpConnector(name=name)}


class TcpConnector(Connector):
    """vtkMRMLIGTLConnectorNode in client mode, over a real socket (see the module's
    docstring). `on_node(node, message)` is called on the main thread as each message
    reaches its node: what the scene shows, when it shows it. Made with a host, it starts
    at once; made by the scene (AddNewNodeByClass), it waits for SetTypeClient and Start,
    and puts the nodes it makes into that scene."""

    COMPLETED = constant("vtkSlicerOpenIGTLinkCommand.CommandCompletedEvent")
    EXPIRED = constant("vtkSlicerOpenIGTLinkCommand.CommandExpired")
    RESPONSE = constant("vtkSlicerOpenIGTLinkCommand.CommandResponseReceived")

    def __init__(self, host: str = "", port: int = 0,
                 on_node: Callable[[Any, Message], None] = lambda node, message: None, *,
                 name: str = "") -> None:
        super().__init__(name)
        self.host, self.port, self.on_node = host, port, on_node
        self.state = self.StateOff
        self._arrived: Deque[Tuple[str, Optional[Message]]] = deque()
        self._sock: Optional[socket.socket] = None
        self._send_lock = threading.Lock()
        self._waiting: Dict[int, Tuple[Command, float]] = {}
        self._next_id = 1
        self._nodes: Dict[Tuple[str, str], Any] = {}
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None
        if host:
            self.Start()

    def GetServerHostname(self): return self.host  # noqa: E704, N802
    def GetServerPort(self): return self.port  # noqa: E704, N802

    def SetTypeClient(self, host, port):  # noqa: N802
        self.host, self.port = str(host), int(port)
        return 1

    def Start(self):  # noqa: N802
        if self._thread is not None:
            return 0
        self._stop = threading.Event()
        self.state = self.StateWaitConnection
        self._thread = threading.Thread(target=self._run, args=(self._stop,),
                                        name="igtlio-connect", daemon=True)
        self._thread.start()
        return 1

    def Stop(self):  # noqa: N802
        """Ends the thread and its socket; returns 0 when it was not running."""
        thread = self._thread
        if thread is None:
            return 0
        self.stop()
        thread.join(timeout=10)
        self._thread = None
        self._arrived.clear()
        self._waiting.clear()
        self.state = self.StateOff
        return 1

    def stop(self) -> None:
        self._stop.set()
        sock = self._sock
        if sock is not None:
            with contextlib.suppress(OSError):
                sock.shutdown(socket.SHUT_RDWR)  # as igtlCloseSocketMacro: wakes the reader

    # --- the connector's thread: connect, read until it ends, retry every 0.1 s ----------
    def _run(self, stop: Optional[threading.Event] = None) -> None:
        stop = stop or self._stop
        while not stop.is_set():
            try:
                sock = socket.create_connection((self.host, self.port))
            except OSError:
                time.sleep(0.1)
                continue
            # Slicer's connector announces header v2 with a STATUS carrying metadata.
            sock.sendall(framing.encode(Message("", Status(code=StatusCode.OK),
                                                metadata={"dummy": "dummy"}),
                                        header_version=2))
            self._sock = sock
            self._arrived.append(("connected", None))
            decoder = framing.Decoder()
            try:
                while not stop.is_set():
                    data = sock.recv(1 << 16)
                    if not data:
                        break
                    decoder.feed(data)
                    for message in decoder.messages():
                        self._arrived.append(("message", message))
            except OSError:
                pass
            self._sock = None
            sock.close()
            self._arrived.append(("disconnected", None))
            time.sleep(0.1)

    # --- the main thread's side -------------------------------------------------------------
    def PeriodicProcess(self):  # noqa: N802
        super().PeriodicProcess()
        while self._arrived:
            what, message = self._arrived.popleft()
            if what == "connected":
                self.state = self.StateConnected
                self.InvokeEvent(self.ConnectedEvent)
            elif what == "disconnected":
                self.state = self.StateWaitConnection
                self.InvokeEvent(self.DisconnectedEvent)
            elif message is not None:
                self._import(message)
        now = time.monotonic()
        for command_id, (cmd, deadline) in list(self._waiting.items()):
            if now > deadline:
                del self._waiting[command_id]
                cmd.status = self.EXPIRED
                cmd.InvokeEvent(self.COMPLETED)

    def _import(self, message: Message) -> None:
        body = message.body
        if isinstance(body, RtsCommand):
            entry = self._waiting.pop(body.command_id, None)
            if entry is not None:
                entry[0].status, entry[0].response = self.RESPONSE, body.text
                entry[0].InvokeEvent(self.COMPLETED)
            return
        node_class = {"STATUS": StatusNode, "TRANSFORM": TransformNode,
                      "STRING": TextNode, "POLYDATA": ModelNode}.get(message.type_name)
        if node_class is None:
            return
        key = (message.type_name, message.device_name)
        node = self._nodes.get(key)
        if node is not None and self._scene is not None and node.GetScene() is None:
            node = None  # the scene removed it: the connector makes it again
        if node is None:
            node = self._nodes[key] = node_class(message.device_name)
            self.incoming.append(node)
            if self._scene is not None:
                self._scene.AddNode(node)
        # One modification per message: its metadata and content, then its events.
        was = node.StartModify()
        for name, value in message.metadata.items():
            node.SetAttribute(f"OpenIGTLink.{name}", value)
        if isinstance(body, Status):
            node.code, node.error_name, node.text = body.code, body.error_name, body.text
        elif message.type_name == "TRANSFORM":
            node.matrix = np.array(body.matrix)
            node._pending[TRANSFORM_MODIFIED_EVENT] = 1
        elif message.type_name == "STRING":
            node.SetText(body.text, body.encoding)
        elif message.type_name == "POLYDATA":
            node.SetAndObservePolyData(vtk_from_polydata(body))
        node._pending[MODIFIED_EVENT] = 1
        node.EndModify(was)
        self.on_node(node, message)

    def RegisterOutgoingMRMLNode(self, node, devType=None):  # noqa: N802
        """The connector pushes a registered node on its content's modified event."""
        event = next((event for cls, event in (
            ("vtkMRMLTextNode", TextNode.TextModifiedEvent),
            ("vtkMRMLLinearTransformNode", TRANSFORM_MODIFIED_EVENT),
            ("vtkMRMLModelNode", ModelNode.MeshModifiedEvent),
            ("vtkMRMLMarkupsNode", MarkupsFiducialNode.PointModifiedEvent)) if node.IsA(cls)),
            None)
        if event is None:
            return 0
        if node not in self.outgoing:
            self.outgoing.append(node)
            node.AddObserver(event, lambda n, e: self.PushNode(n))
        return 1

    def PushNode(self, node):  # noqa: N802
        message = outgoing_message(node)
        self.pushed.append(message)
        sock = self._sock
        if sock is None or self.state != self.StateConnected:
            return 0
        try:
            with self._send_lock:
                sock.sendall(framing.encode(message, header_version=2))
        except OSError:
            return 0
        return 1

    def forget(self, node: Any) -> None:
        super().forget(node)
        for key in [k for k, n in self._nodes.items() if n is node]:
            del self._nodes[key]

    def SendCommand(self, command):  # noqa: N802
        sock = self._sock
        if sock is None or self.state != self.StateConnected:
            return  # no client socket: the status stays unknown
        command_id, self._next_id = self._next_id, self._next_id + 1
        frame = framing.encode(Message("command", IgtlCommand(
            command_id=command_id, name=command.name, text=command.content)), header_version=2)
        try:
            with self._send_lock:
                sock.sendall(frame)
        except OSError:
            command.status = 4  # failed
            return
        command.status = Command.CommandWaiting
        self._waiting[command_id] = (command, time.monotonic() + command.timeout)
        while command.blocking and command.status == Command.CommandWaiting:
            self.PeriodicProcess()
            time.sleep(0.005)

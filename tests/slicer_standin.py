"""Stand-ins of the Slicer API the ROS2Bridge module calls, so that its code runs here
although 3D Slicer cannot.

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
from collections import deque
from pathlib import Path
from xml.etree import ElementTree as ET
from typing import Any, Callable, Deque, Dict, Optional, Tuple

import numpy as np

from protocol import framing
from protocol.messages import Command as IgtlCommand
from protocol.messages import Message, RtsCommand, Status, StatusCode

MODULE = Path(__file__).resolve().parents[1] / "slicer_client" / "slicer_module" / \
    "ROS2Bridge" / "ROS2Bridge.py"

MODIFIED_EVENT = 33  # vtkCommand::ModifiedEvent
TRANSFORM_MODIFIED_EVENT = 15000  # vtkMRMLTransformNode::TransformModifiedEvent


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
            if ev == event:
                callback(self, event)

    def Modified(self):  # noqa: N802
        self.InvokeEvent(MODIFIED_EVENT)


class Node(Observable):
    """vtkMRMLNode's attributes (the connector copies each message's metadata into them
    as ``OpenIGTLink.<key>``)."""

    def __init__(self) -> None:
        super().__init__()
        self.attributes: Dict[str, str] = {}

    def GetAttributeNames(self): return list(self.attributes)  # noqa: E704, N802
    def GetAttribute(self, name): return self.attributes.get(name)  # noqa: E704, N802
    def SetAttribute(self, name, value): self.attributes[name] = value  # noqa: E704, N802
    def SetHideFromEditors(self, hide): self.hidden = bool(hide)  # noqa: E704, N802


class TextNode(Node):
    TextModifiedEvent = 51000
    _ids = 0

    def __init__(self, name: str) -> None:
        super().__init__()
        TextNode._ids += 1
        self._id, self._name, self._text, self._enc = f"vtkMRMLTextNode{self._ids}", name, "", 1
        self._disabled, self._pending = 0, {}

    def GetID(self): return self._id  # noqa: E704, N802
    def GetName(self): return self._name  # noqa: E704, N802
    def IsA(self, name): return name in ("vtkMRMLTextNode", "vtkMRMLNode")  # noqa: E704, N802

    def StartModify(self):  # noqa: N802
        was, self._disabled = self._disabled, 1
        return was

    def EndModify(self, was):  # noqa: N802
        self._disabled = was
        pending, self._pending = self._pending, {}
        if not was:
            for event in pending:
                self.InvokeEvent(event)
        return sum(pending.values())

    def GetCustomModifiedEventPending(self, event):  # noqa: N802
        return self._pending.get(event, 0)

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

    def __init__(self, name: str) -> None:
        super().__init__()
        self._name = name
        self.code, self.error_name, self.text = 0, "", ""

    def GetID(self): return "vtkMRMLIGTLStatusNode" + self._name  # noqa: E704, N802
    def GetName(self): return self._name  # noqa: E704, N802
    def IsA(self, name): return name in ("vtkMRMLIGTLStatusNode", "vtkMRMLNode")  # noqa: E704, N802
    def GetCode(self): return self.code  # noqa: E704, N802
    def GetErrorName(self): return self.error_name  # noqa: E704, N802
    def GetStatusString(self): return self.text  # noqa: E704, N802


class Command(Observable):
    """vtkSlicerOpenIGTLinkCommand. `script`: for the plain `Connector`, the (status,
    response) each send ends with."""

    script: list = []
    CommandCompletedEvent = 128004
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


class Connector(Observable):
    """vtkMRMLIGTLConnectorNode with no socket: commands end as `Command.script` says."""

    ConnectedEvent, DisconnectedEvent = 118944, 118945
    StateOff, StateWaitConnection, StateConnected = 0, 1, 2

    def __init__(self) -> None:
        super().__init__()
        self.state, self.sent, self.pushed, self.outgoing = 2, [], [], []
        self.incoming: list = []
        self.commands: list = []
        self.periodic = 0

    def GetState(self): return self.state  # noqa: E704, N802
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

    def SendCommand(self, command):  # noqa: N802
        self.sent.append((command.name, command.content, command.blocking, command.timeout))
        self.commands.append(command)
        command.status, command.response = Command.script.pop(0)


class Scene:
    StartSaveEvent, StartCloseEvent, EndCloseEvent = 1, 2, 3

    def __init__(self) -> None:
        self.nodes: list = []

    def GetFirstNode(self, name, cls):  # noqa: N802
        return next((n for n in self.nodes if n.GetName() == name and n.IsA(cls)), None)

    def AddNewNodeByClass(self, cls, name):  # noqa: N802
        assert cls == "vtkMRMLTextNode"
        self.nodes.append(TextNode(name))
        return self.nodes[-1]

    def AddObserver(self, *args): return 1  # noqa: E704, N802


def install_slicer(setitem: Callable[[str, types.ModuleType], None]) -> types.ModuleType:
    """Put the stand-in `slicer`, `qt`, `vtk` and `ctk` modules where `import` finds them
    (``setitem(name, module)``: sys.modules' own, or a test's monkeypatch)."""
    slicer = types.ModuleType("slicer")
    slicer.mrmlScene = Scene()
    slicer.app = Signals()  # startupCompleted()
    slicer.vtkMRMLIGTLConnectorNode = Connector
    slicer.vtkSlicerOpenIGTLinkCommand = Command
    slicer.vtkMRMLTextNode = TextNode
    slicer.vtkMRMLTransformNode = types.SimpleNamespace(
        TransformModifiedEvent=TRANSFORM_MODIFIED_EVENT)
    slm = types.ModuleType("slicer.ScriptedLoadableModule")
    slm.ScriptedLoadableModule = ScriptedLoadableModule
    slm.ScriptedLoadableModuleLogic = ScriptedLoadableModuleLogic
    slm.ScriptedLoadableModuleWidget = ScriptedLoadableModuleWidget
    slm.ScriptedLoadableModuleTest = type("ScriptedLoadableModuleTest", (), {})
    pnw = types.ModuleType("slicer.parameterNodeWrapper")
    pnw.parameterNodeWrapper = parameter_node_wrapper
    pnw.WithinRange = lambda lo, hi: (lo, hi)
    util = types.ModuleType("slicer.util")
    util.VTKObservationMixin = VTKObservationMixin
    util.loadUI, util.childWidgetVariables = load_ui, child_widget_variables
    util.errors = []  # what tryWithErrorDisplay showed
    util.tryWithErrorDisplay = functools.partial(try_with_error_display, util.errors)
    slicer.ScriptedLoadableModule, slicer.parameterNodeWrapper, slicer.util = slm, pnw, util
    vtk = types.ModuleType("vtk")
    vtk.vtkCommand = types.SimpleNamespace(ModifiedEvent=MODIFIED_EVENT)
    qt = types.ModuleType("qt")
    qt.QTimer = Timer
    ctk = types.ModuleType("ctk")
    ctk.ctkSliderWidget = lambda: UiWidget("ctkSliderWidget", "", {}, {})
    for name, module in (("slicer", slicer), ("slicer.ScriptedLoadableModule", slm),
                         ("slicer.parameterNodeWrapper", pnw), ("slicer.util", util),
                         ("qt", qt), ("vtk", vtk), ("ctk", ctk)):
        setitem(name, module)
    return slicer


def load_module(setitem: Callable[[str, types.ModuleType], None]) -> Any:
    """ROS2Bridge.py, imported over the stand-ins. Its folder goes on sys.path, as Slicer
    puts it there when it loads the module (qSlicerScriptedLoadableModuleFactory.cxx), and
    ROS2BridgeLib is imported afresh, over these stand-ins rather than an earlier test's."""
    install_slicer(setitem)
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
    """qt.QTimer: never fires by itself here (a test calls the slot)."""

    def __init__(self) -> None:
        super().__init__()
        self.interval, self.active = 0, False

    def setInterval(self, ms: int) -> None: self.interval = ms  # noqa: E704, N802
    def start(self) -> None: self.active = True  # noqa: E704
    def stop(self) -> None: self.active = False  # noqa: E704


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


class TransformNode(Node):
    def __init__(self, name: str) -> None:
        super().__init__()
        self._name = name
        self.matrix = np.eye(4)

    def GetID(self): return "vtkMRMLLinearTransformNode" + self._name  # noqa: E704, N802
    def GetName(self): return self._name  # noqa: E704, N802
    def IsA(self, name): return name in ("vtkMRMLLinearTransformNode", "vtkMRMLTransformNode")  # noqa: E704, E501, N802


class TcpConnector(Connector):
    """vtkMRMLIGTLConnectorNode in client mode, over a real socket (see the module's
    docstring). `on_node(node, message)` is called on the main thread as each message
    reaches its node: what the scene shows, when it shows it."""

    COMPLETED, EXPIRED, RESPONSE = 128004, 2, 5

    def __init__(self, host: str, port: int,
                 on_node: Callable[[Any, Message], None] = lambda node, message: None) -> None:
        super().__init__()
        self.host, self.port, self.on_node = host, port, on_node
        self.state = self.StateWaitConnection
        self._arrived: Deque[Tuple[str, Optional[Message]]] = deque()
        self._sock: Optional[socket.socket] = None
        self._send_lock = threading.Lock()
        self._waiting: Dict[int, Tuple[Command, float]] = {}
        self._next_id = 1
        self._nodes: Dict[Tuple[str, str], Any] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="igtlio-connect", daemon=True)
        self._thread.start()

    def GetServerHostname(self): return self.host  # noqa: E704, N802
    def GetServerPort(self): return self.port  # noqa: E704, N802

    def stop(self) -> None:
        self._stop.set()
        sock = self._sock
        if sock is not None:
            sock.shutdown(socket.SHUT_RDWR)  # as igtlCloseSocketMacro: wakes the reader

    # --- the connector's thread: connect, read until it ends, retry every 0.1 s ----------
    def _run(self) -> None:
        while not self._stop.is_set():
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
                while not self._stop.is_set():
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
                      "STRING": TextNode}.get(message.type_name)
        if node_class is None:
            return
        key = (message.type_name, message.device_name)
        node = self._nodes.get(key)
        if node is None:
            node = self._nodes[key] = node_class(message.device_name)
            self.incoming.append(node)
        for name, value in message.metadata.items():
            node.SetAttribute(f"OpenIGTLink.{name}", value)
        if isinstance(body, Status):
            node.code, node.error_name, node.text = body.code, body.error_name, body.text
            node.Modified()
        elif message.type_name == "TRANSFORM":
            node.matrix = np.array(body.matrix)
            node.InvokeEvent(TRANSFORM_MODIFIED_EVENT)
        self.on_node(node, message)

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


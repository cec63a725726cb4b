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

import importlib.util
import socket
import threading
import time
import types
from collections import deque
from pathlib import Path
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
    slicer.vtkMRMLIGTLConnectorNode = Connector
    slicer.vtkSlicerOpenIGTLinkCommand = Command
    slicer.vtkMRMLTextNode = TextNode
    slicer.vtkMRMLTransformNode = types.SimpleNamespace(
        TransformModifiedEvent=TRANSFORM_MODIFIED_EVENT)
    slm = types.ModuleType("slicer.ScriptedLoadableModule")
    for name in ("ScriptedLoadableModule", "ScriptedLoadableModuleLogic",
                 "ScriptedLoadableModuleWidget", "ScriptedLoadableModuleTest"):
        setattr(slm, name, type(name, (), {"__init__": lambda self, *a: None}))
    pnw = types.ModuleType("slicer.parameterNodeWrapper")
    pnw.parameterNodeWrapper = lambda cls: cls
    pnw.WithinRange = lambda lo, hi: (lo, hi)
    util = types.ModuleType("slicer.util")
    util.VTKObservationMixin = type("VTKObservationMixin", (), {})
    slicer.ScriptedLoadableModule, slicer.parameterNodeWrapper, slicer.util = slm, pnw, util
    vtk = types.ModuleType("vtk")
    vtk.vtkCommand = types.SimpleNamespace(ModifiedEvent=MODIFIED_EVENT)
    for name, module in (("slicer", slicer), ("slicer.ScriptedLoadableModule", slm),
                         ("slicer.parameterNodeWrapper", pnw), ("slicer.util", util),
                         ("qt", types.ModuleType("qt")), ("vtk", vtk),
                         ("ctk", types.ModuleType("ctk"))):
        setitem(name, module)
    return slicer


def load_module(setitem: Callable[[str, types.ModuleType], None]) -> Any:
    """ROS2Bridge.py, imported over the stand-ins."""
    install_slicer(setitem)
    spec = importlib.util.spec_from_file_location("ROS2Bridge_under_test", MODULE)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


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


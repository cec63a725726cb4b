"""slicer_client's Transport over 3D Slicer's OpenIGTLinkIF connector node (client mode):
the ROS2Bridge module's only link to the daemon. Slicer's objects (connector, nodes,
commands) are untyped wrappers here: typed `Any`, what is taken from them is typed."""

import logging
import queue
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Optional

import numpy as np
import slicer
import vtk

from protocol import commands as c
from protocol.liveness import HEARTBEAT_DEVICE
from protocol.messages import Message
from protocol.naming import KEY_ROBOT
from slicer_client.scene_plan import ATTRIBUTE_PREFIX
from slicer_client.connection import CommandTimeoutError, ConnectionClosedError
from slicer_client.connector_codec import (SLICER_TEXT_ENCODING, build_command,
                                           message_from_node, outgoing_content, parse_reply)
from slicer_client.send_plan import SendPlan
from slicer_client.transport import TransportListener

__all__ = ["ConnectorTransport"]

log = logging.getLogger("ROS2Bridge")  # the module's logger, as before the split
# The connector's attribute for a message's ros2.robot metadata: a robot's mesh.
ROBOT_ATTRIBUTE = ATTRIBUTE_PREFIX + KEY_ROBOT

Observer = tuple[Any, int]  # (VTK object, observer tag)
# A command handed to the main thread is given up this long after its own timeout: the main
# thread may be busy (a blocking command of its own) when it is handed over.
HANDOFF_GRACE_S = 1.0


@dataclass
class _HandedOff:
    """A command another thread asked for, run by the main thread (`serve_other_threads`)."""

    op: str
    arguments: Optional[Mapping[str, Any]]
    timeout: float
    done: threading.Event = field(default_factory=threading.Event)
    reply: Optional[dict[str, Any]] = None
    error: Optional[BaseException] = None


@dataclass
class _Bundle:
    """A tracking-data bundle the connector made (a robot's link poses): its element nodes
    and each one's MTime as last handed on (-1: not yet)."""

    node: Any
    elements: list[Any] = field(default_factory=list)
    handed: list[int] = field(default_factory=list)
    # The bundle's attributes (its robot's names), as the connector set them from the first
    # message: the same in every message of the robot.
    attributes: dict[str, str] = field(default_factory=dict)


class ConnectorTransport:
    """slicer_client's Transport over an OpenIGTLinkIF connector node (see transport.py).

    Commands block the GUI thread (only a user's action sends one): `SendCommand` loops on
    the IO connector's PeriodicProcess every 5 ms, so replies (and incoming data) keep
    being read meanwhile; on a link found dead they are refused at once. Received data
    comes from the connector's nodes, observed here and handed to the client as Messages.
    The connector reconnects by itself; its Connected/Disconnected events are only
    delivered while it is connected (the OpenIGTLinkIF logic's 5 ms timer skips
    unconnected connectors), so a loss is also noticed by `poll()` from the module's timer.

    A pulled cable: the connector's socket has no keepalive and never sends, so it stays
    "connected". The daemon's heartbeat is a STATUS whose node the connector modifies once
    per message; `poll()` takes `DEAD_AFTER_S` without one for a dead link. The connector
    keeps its socket: the daemon resets its end and knocks it once the cable is back
    (bridge/core/knock.py), and the connector then reconnects at once. (Restarting the connector
    here would start a blocking connect() with no timeout, which a later Stop() waits for.)
    That reconnect is announced by nothing: OpenIGTLinkIO's connection thread makes the new
    socket within one turn (igtlioConnector::ConnectionAcceptThreadFunction), before it
    checks its state, so no Disconnected/ConnectedEvent comes, and the daemon sends a new
    socket no heartbeat before a hello. So while silent, any message the connector puts into
    its incoming nodes (a stream's value, a new node) also means a socket carries data
    again, and the link is taken up (hello, bridges) as after a ConnectedEvent.
    """

    watches_silence = True
    # The connector puts each value into the scene itself, whatever its age: the daemon
    # cuts a dead link before its backlog ages past the freshness bound.
    drops_late_values = False
    # A subscriber's whole messages come as STRING (a text node of the connector) when
    # their JSON fits 65535 bytes (protocol.messages.document_body); a larger one is a JSON
    # message, which the connector does not import (standard OpenIGTLink types only).
    carries_whole_messages = True
    # The connector imports every message into the scene on the main thread, which a
    # display shows at its frame rate: the daemon sends each stream's newest once a frame.
    display_hz: Optional[float] = c.DISPLAY_HZ

    def __init__(self, connector: Any, clock: Callable[[], float] = time.monotonic) -> None:
        self.connector = connector
        self.address = f"{connector.GetServerHostname()}:{connector.GetServerPort()}"
        self._clock = clock
        self._listener: Optional[TransportListener] = None
        self._node_observers: dict[str, Observer] = {}  # node id -> (node, tag)
        # Watched nodes the connector changed since the last `poll`, in the order of their
        # latest change: handed on there, the newest value once per tick (the callbacks
        # run in the same tick's Spin, so a value waits for nothing it did not wait for).
        self._changed: dict[str, Any] = {}
        # Tracking-data bundles (a robot's link poses), by node id: their moved elements
        # are handed on from `poll`, once per tick.
        self._bundles: dict[str, _Bundle] = {}
        # The incoming nodes as many as when `_watchIncomingNodes` last looked, and none new
        # since (NewDeviceEvent): a tick then does not look at each node again.
        self._looked_at = -1
        self._connector_tags: list[int] = []
        self._first = True
        self._up_now = False  # the listener was told "connected" and not "lost" since
        self._dead_after = 0.0  # seconds without a heartbeat that mean a dead link (0: off)
        self._heard = 0.0  # when the last heartbeat came (clock)
        # When the heartbeat went missing on a socket still up (clock); None while heard.
        self._silent_since: Optional[float] = None
        # The incoming nodes then: (how many, their newest modification time).
        self._silent_incoming = (0, 0)
        self._heartbeat: Optional[Observer] = None  # (node, tag) of the heartbeat's STATUS node
        self.heartbeats = 0  # heard on this transport
        # Slicer's connector and scene belong to the main thread (the one that made this):
        # a command from another thread (an async service call's worker) is run there.
        self._main_thread = threading.get_ident()
        self._handed_off: "queue.SimpleQueue[_HandedOff]" = queue.SimpleQueue()
        self.commands_handed_off = 0  # run on the main thread for another thread

    @property
    def connected(self) -> bool:
        return self._socket_up() and self._silent_since is None

    @property
    def silent(self) -> bool:
        """The heartbeat stopped on a socket the connector still holds."""
        return self._silent_since is not None

    def _socket_up(self) -> bool:
        return bool(self.connector.GetState() == slicer.vtkMRMLIGTLConnectorNode.StateConnected)

    def set_listener(self, listener: TransportListener) -> None:
        self._listener = listener
        for event, handler in ((slicer.vtkMRMLIGTLConnectorNode.ConnectedEvent,
                                self._onConnectedEvent),
                               (slicer.vtkMRMLIGTLConnectorNode.DisconnectedEvent,
                                self._onDisconnectedEvent),
                               (slicer.vtkMRMLIGTLConnectorNode.NewDeviceEvent,
                                self._onNewDevice)):
            self._connector_tags.append(self.connector.AddObserver(event, handler))
        if self.connected:
            self._up()  # errors reach whoever made the Client

    def _up(self) -> None:
        assert self._listener is not None  # only called with a listener set
        first, self._first = self._first, False
        self._up_now = True
        self._silent_since = None
        self._listener.on_connected(self.command, first)

    def _onConnectedEvent(self, caller: Any = None, event: Any = None) -> None:
        if self._up_now or self._listener is None:
            return
        self._silent_since = None  # a new socket
        try:
            self._up()
        except Exception:  # noqa: BLE001 - inside a VTK callback: log, keep the connector
            log.exception("re-creating the bridges on %s failed", self.address)

    def _onDisconnectedEvent(self, caller: Any = None, event: Any = None) -> None:
        self._down("the connector lost the daemon (it retries itself)")

    def expect_data_within(self, seconds: float) -> None:
        """The daemon sends this connection a heartbeat (hello asked for it)."""
        self._dead_after = max(0.0, float(seconds))
        self._heard = self._clock()

    def _watchIncomingNodes(self, firstNew: int) -> None:
        """Observe the STATUS nodes the connector makes: the heartbeat's (counted), and
        each stream's stale/live condition (handed to the client, which marks the
        subscriber stale as slicer_client does); and a robot's meshes (the client counts
        its load done), placed or not yet. Nodes from index `firstNew` on were made by the
        connector's last PeriodicProcess: a heartbeat node among them is a heartbeat heard
        (its observer comes after the modification that made it)."""
        count = self.connector.GetNumberOfIncomingMRMLNodes()
        if count == self._looked_at:
            return
        self._looked_at = count
        for i in range(count):
            node = self.connector.GetIncomingMRMLNode(i)
            if node is not None and node.IsA("vtkMRMLModelNode") \
                    and node.GetAttribute(ROBOT_ATTRIBUTE):
                self.watch(node)
            if node is None or not node.IsA("vtkMRMLIGTLStatusNode"):
                continue
            if node.GetName() != HEARTBEAT_DEVICE:
                self.watch(node)
            elif self._heartbeat is None or self._heartbeat[0] is not node:
                if self._heartbeat is not None:
                    self._heartbeat[0].RemoveObserver(self._heartbeat[1])
                tag = node.AddObserver(vtk.vtkCommand.ModifiedEvent, self._onHeartbeat)
                self._heartbeat = (node, tag)
                if i >= firstNew:
                    self._onHeartbeat()
                node.SetHideFromEditors(True)  # plumbing, not data for the user

    def _onNewDevice(self, caller: Any = None, event: Any = None) -> None:
        self._looked_at = -1  # its content and attributes come after: looked at next tick

    def _onHeartbeat(self, caller: Any = None, event: Any = None) -> None:
        self._heard = self._clock()
        self.heartbeats += 1

    def poll(self) -> None:
        """Called from the module's timer: run what other threads handed over; report a
        loss the connector has not yet sent, or a heartbeat gone missing; and a heartbeat
        back on the same socket."""
        self.serve_other_threads()
        if not self._socket_up():
            self._handOn()  # what came before the loss
            self._silent_since = None
            self._down("the connector lost the daemon (it retries itself)")
            return
        if self._listener is None:
            return
        known = self.connector.GetNumberOfIncomingMRMLNodes()
        self.connector.PeriodicProcess()  # what has come is counted before judging silence
        self._watchIncomingNodes(known)
        self._handOn()
        if not self._dead_after:
            return
        now = self._clock()
        if self._silent_since is not None:
            count, newest = self._incomingNow()
            if self._heard > self._silent_since or count > self._silent_incoming[0] \
                    or newest > self._silent_incoming[1]:  # a socket carries data again
                try:
                    self._up()
                except Exception:  # noqa: BLE001 - the next loss or reconnect retries
                    log.exception("re-creating the bridges on %s failed", self.address)
            return
        silence = now - self._heard
        if self._up_now and silence > self._dead_after:
            self._silent_since = now
            self._silent_incoming = self._incomingNow()
            self._down(f"no heartbeat from the daemon for {silence:.1f} s: the link to "
                       f"{self.address} is down (a pulled cable?); the connector reconnects "
                       "when it is back")

    def _handOn(self) -> None:
        """Hand the client what the connector changed since the last tick: each watched
        node's newest content, in the order of change, then the bundles' moved elements."""
        changed, self._changed = self._changed, {}
        for node in changed.values():
            self._forward(node)
        for bundle in tuple(self._bundles.values()):
            self._forwardBundle(bundle)

    def _incomingNow(self) -> tuple[int, int]:
        """How many incoming nodes the connector has, and their newest modification time
        (VTK's MTime): either grows only as messages come in while the link is silent (the
        module changes an incoming node only as it arrives)."""
        count = self.connector.GetNumberOfIncomingMRMLNodes()
        nodes = (self.connector.GetIncomingMRMLNode(i) for i in range(count))
        return count, max((int(n.GetMTime()) for n in nodes if n is not None), default=0)

    def _down(self, reason: str) -> None:
        if not self._up_now or self._listener is None:
            return
        self._up_now = False
        log.warning("%s", reason)
        self._listener.on_disconnected(reason)

    def _requireConnected(self, what: str) -> None:
        if self._silent_since is not None:
            raise ConnectionClosedError(
                f"{what}: no heartbeat from the daemon at {self.address} for more than "
                f"{self._dead_after:g} s (the link is down)")
        if not self._socket_up():
            raise ConnectionClosedError(
                f"{what}: 3D Slicer's connector is not connected to the daemon at "
                f"{self.address} (it keeps retrying; start it with `slicer-ros2-bridge run`)")

    def serve_other_threads(self) -> None:
        """Run, on the main thread, the commands other threads handed over (the connector
        processes what it receives in `SendCommand`, and MRML's nodes and observers are the
        main thread's: another thread must never drive them)."""
        if threading.get_ident() != self._main_thread:
            return
        while True:
            try:
                job = self._handed_off.get_nowait()
            except queue.Empty:
                return
            try:
                job.reply = self.command(job.op, job.arguments, timeout=job.timeout)
            except BaseException as error:  # noqa: BLE001 - handed back to the caller
                job.error = error
            finally:
                self.commands_handed_off += 1
                job.done.set()

    def command(self, op: str, arguments: Optional[Mapping[str, Any]] = None, *,
                timeout: float = 5.0) -> dict[str, Any]:
        if threading.get_ident() != self._main_thread:
            job = _HandedOff(op, arguments, timeout)
            self._handed_off.put(job)
            if not job.done.wait(timeout + HANDOFF_GRACE_S):
                raise CommandTimeoutError(op, timeout, "3D Slicer's main thread did not run "
                                          "it (it runs commands of other threads as it spins)")
            if job.error is not None:
                raise job.error
            assert job.reply is not None
            return job.reply
        name, text = build_command(op, arguments)
        self._requireConnected(op)  # a silent link: refused at once, the GUI never waits
        cmd = slicer.vtkSlicerOpenIGTLinkCommand()
        cmd.SetName(name)
        cmd.SetCommandContent(text)
        cmd.SetTimeoutSec(float(timeout))
        cmd.SetBlocking(True)
        self.connector.SendCommand(cmd)  # returns once replied, expired, or at once if not sent
        return parse_reply(op, cmd.GetResponseContent() or "", status=cmd.GetCommandStatus(),
                           timeout=timeout, error_message=cmd.GetErrorMessage() or "")

    def send(self, message: Message) -> None:
        """Stream a TRANSFORM or STRING under its device name through an outgoing node.
        The connector pushes a registered node itself when its content changes (it
        observes TransformModifiedEvent / TextModifiedEvent); an unchanged content is
        pushed here, so every call sends exactly one message."""
        class_name, payload = outgoing_content(message)  # raises for what cannot go
        self._requireConnected(f"sending to {message.device_name!r}")
        node = self._outgoing(class_name, message.device_name)
        if class_name == "vtkMRMLLinearTransformNode":
            event = slicer.vtkMRMLTransformNode.TransformModifiedEvent
        else:
            event = slicer.vtkMRMLTextNode.TextModifiedEvent
        was_modifying = node.StartModify()
        if class_name == "vtkMRMLLinearTransformNode":
            matrix = vtk.vtkMatrix4x4()
            for i in range(4):
                for j in range(4):
                    matrix.SetElement(i, j, float(payload[i][j]))
            node.SetMatrixTransformToParent(matrix)
        else:
            node.SetText(payload, SLICER_TEXT_ENCODING)
        pushes_itself = not was_modifying and node.GetCustomModifiedEventPending(event) > 0
        node.EndModify(was_modifying)
        if not pushes_itself:
            self.connector.PushNode(node)

    def sendNode(self, device: str, plan: SendPlan, node: Any) -> None:
        """Push ``node``'s data to the daemon under ``device`` as ``plan`` says
        (slicer_client/send_plan.py): a model node with a world-space, triangulated copy
        of the surface or the curve's polyline (POLYDATA), or a point-list node with the
        control points' world positions and labels (POINT). One push per call: the
        connector pushes a registered node on its own modified event when EndModify
        fires one, else PushNode does it here."""
        self._requireConnected(f"sending to {device!r}")
        out = self._outgoing(plan.outgoing_class, device)
        if plan.outgoing_class == "vtkMRMLModelNode":
            event = slicer.vtkMRMLModelNode.MeshModifiedEvent
        else:
            event = slicer.vtkMRMLMarkupsNode.PointModifiedEvent
        was_modifying = out.StartModify()
        if plan.source == "control_points":
            out.RemoveAllControlPoints()
            position: list[float] = [0.0, 0.0, 0.0]
            for index in range(node.GetNumberOfControlPoints()):
                node.GetNthControlPointPositionWorld(index, position)
                out.AddControlPoint(position[0], position[1], position[2],
                                    node.GetNthControlPointLabel(index))
        else:
            polydata = vtk.vtkPolyData()
            polydata.DeepCopy(node.GetCurveWorld() if plan.source == "curve"
                              else _worldSurface(node))
            out.SetAndObservePolyData(polydata)
        pushes_itself = not was_modifying and out.GetCustomModifiedEventPending(event) > 0
        out.EndModify(was_modifying)
        if not pushes_itself:
            self.connector.PushNode(out)

    def _outgoing(self, class_name: str, device: str) -> Any:
        node = slicer.mrmlScene.GetFirstNode(device, class_name)
        if node is None:
            node = slicer.mrmlScene.AddNewNodeByClass(class_name, device)
        registered = {self.connector.GetOutgoingMRMLNode(i).GetID()
                      for i in range(self.connector.GetNumberOfOutgoingMRMLNodes())
                      if self.connector.GetOutgoingMRMLNode(i) is not None}
        if node.GetID() not in registered and not self.connector.RegisterOutgoingMRMLNode(node):
            raise RuntimeError(f"3D Slicer's connector refused {class_name} {device!r} as an "
                               "outgoing node")
        return node

    def watch(self, node: Any) -> None:
        """Forward a connector node's updates to the client as Messages. The connector
        ends its node modification once per received message, so ModifiedEvent (text) and
        TransformModifiedEvent (transforms) fire once per message, or once per batch for
        messages read during a blocking command; the node is handed on at the next `poll`
        (the display's newest value, once per tick)."""
        key = node.GetID()
        if key in self._node_observers or key in self._bundles:
            return
        if node.IsA("vtkMRMLIGTLTrackingDataBundleNode"):
            # Its connector updates the element nodes, never the bundle: no event to observe.
            self._bundles[key] = bundle = _Bundle(node)
            self._forwardBundle(bundle)
            return
        event = (slicer.vtkMRMLTransformNode.TransformModifiedEvent
                 if node.IsA("vtkMRMLTransformNode") else
                 slicer.vtkMRMLModelNode.MeshModifiedEvent if node.IsA("vtkMRMLModelNode")
                 else vtk.vtkCommand.ModifiedEvent)

        def changed(caller: Any, _event: Any) -> None:
            self._changed.pop(key, None)  # to the end: handed on in the order of change
            self._changed[key] = caller
        tag = node.AddObserver(event, changed)
        self._node_observers[key] = (node, tag)
        self._forward(node)

    def unwatch(self, node: Any) -> None:
        self._bundles.pop(node.GetID(), None)
        self._changed.pop(node.GetID(), None)
        entry = self._node_observers.pop(node.GetID(), None)
        if entry is not None:
            entry[0].RemoveObserver(entry[1])

    def _forward(self, node: Any) -> None:
        attributes = {name: node.GetAttribute(name) for name in node.GetAttributeNames()}
        if node.IsA("vtkMRMLLinearTransformNode"):
            message = message_from_node(node.GetName(), attributes, matrix=_rows(node))
        elif node.IsA("vtkMRMLTextNode"):
            message = message_from_node(node.GetName(), attributes, text=node.GetText())
        elif node.IsA("vtkMRMLIGTLStatusNode"):
            message = message_from_node(node.GetName(), attributes, status=(
                node.GetCode(), node.GetErrorName() or "", node.GetStatusString() or ""))
        elif node.IsA("vtkMRMLModelNode"):  # a robot's mesh: the client counts it in
            model = _modelArrays(node.GetPolyData())
            if model is None:
                return
            message = message_from_node(node.GetName(), attributes, model=model)
        else:
            return
        if message is not None and self._listener is not None:
            try:
                self._listener.on_message(message)
            except Exception:  # noqa: BLE001 - inside a VTK callback
                log.exception("handling %s failed", node.GetName())

    def _forwardBundle(self, bundle: _Bundle) -> None:
        """The bundle's elements that moved since last handed on, as one TDATA for the
        client (its robot takes each element on its own)."""
        node = bundle.node
        count = node.GetNumberOfTransformNodes()
        if count != len(bundle.elements):  # new links: every element is handed on again
            bundle.elements = [node.GetTransformNode(i) for i in range(count)]
            bundle.handed = [-1] * count
            bundle.attributes = {name: node.GetAttribute(name)
                                 for name in node.GetAttributeNames()}
        if self._listener is None:
            return
        moved = []
        for i, element in enumerate(bundle.elements):
            mtime = element.GetMTime()
            if mtime != bundle.handed[i]:
                bundle.handed[i] = mtime
                moved.append(element)
        if not moved:
            return
        message = message_from_node(node.GetName(), bundle.attributes, poses=(
            [element.GetName() for element in moved],
            np.array([_values(element) for element in moved], dtype=np.float64)))
        try:
            self._listener.on_message(message)  # type: ignore[arg-type]
        except Exception:  # noqa: BLE001 - inside the module's timer
            log.exception("handling %s failed", node.GetName())

    def close(self) -> None:
        self._bundles.clear()
        self._changed.clear()
        for tag in self._connector_tags:
            self.connector.RemoveObserver(tag)
        self._connector_tags = []
        if self._heartbeat is not None:
            self._heartbeat[0].RemoveObserver(self._heartbeat[1])
            self._heartbeat = None
        for node, tag in self._node_observers.values():
            node.RemoveObserver(tag)
        self._node_observers.clear()
        self._listener = None


_MATRIX = vtk.vtkMatrix4x4()  # read into, on the main thread only


def _values(transformNode: Any) -> tuple[float, ...]:
    """A linear transform node's matrix to its parent, its 16 numbers row by row."""
    transformNode.GetMatrixTransformToParent(_MATRIX)
    return tuple(_MATRIX.GetData())  # one call, not 16 GetElement


def _rows(transformNode: Any) -> list[list[float]]:
    """A linear transform node's matrix to its parent, as 4 rows."""
    values = _values(transformNode)
    return [list(values[i:i + 4]) for i in range(0, 16, 4)]


def _modelArrays(polydata: Any) -> Optional[tuple[Any, Any]]:
    """A model's points (N, 3) and polygons as ``[n, i0..i(n-1), ...]``, as the connector
    received them; None while it has no points."""
    if polydata is None or polydata.GetNumberOfPoints() == 0:
        return None
    from vtk.util.numpy_support import vtk_to_numpy
    legacy = vtk.vtkIdTypeArray()
    polydata.GetPolys().ExportLegacyFormat(legacy)
    return vtk_to_numpy(polydata.GetPoints().GetData()), vtk_to_numpy(legacy)


def _worldSurface(modelNode: Any) -> Any:
    """A model's surface in world coordinates (its parent transforms applied), as
    triangles: the daemon's Mesh/Marker codecs refuse triangle strips."""
    transform = vtk.vtkGeneralTransform()
    slicer.vtkMRMLTransformNode.GetTransformBetweenNodes(
        modelNode.GetParentTransformNode(), None, transform)
    toWorld = vtk.vtkTransformPolyDataFilter()
    toWorld.SetTransform(transform)
    toWorld.SetInputData(modelNode.GetPolyData())
    triangles = vtk.vtkTriangleFilter()
    triangles.SetInputConnection(toWorld.GetOutputPort())
    triangles.Update()
    return triangles.GetOutput()



"""ROS2Bridge: 3D Slicer module for the slicer-ros2-bridge daemon (no Slicer build needed).

Install: add this folder (slicer_client/slicer_module/ROS2Bridge) to Edit > Application
Settings > Modules > Additional module paths and restart Slicer (5.4 or newer: the
parameter node wrapper used here first shipped in 5.4; it needs the SlicerOpenIGTLink
extension). The repository root is put on sys.path from this file's location, so
`protocol` and `slicer_client` are found in a clone with nothing else to install. Built as
the SlicerROS2Bridge extension (the repository's CMakeLists.txt), both packages are
installed beside this file instead.

Transport: Slicer's own OpenIGTLinkIF connector node (client mode). Commands go through
`vtkSlicerOpenIGTLinkCommand`; what arrives becomes MRML nodes made by the connector; this
module only parents, colours and files them as the scene planner (slicer_client/scene_plan.py)
says.

The reference SlicerROS2's API: where SlicerROS2 itself is not installed, this module
answers its entry points (slicer_client/reference/entry_points.py), so a script written for
it runs with no line changed: `slicer.util.getModuleLogic('ROS2')` gives the logic
(`Spin()`, `GetDefaultROS2Node()`...; used before Connect, it connects to the host and port
of this module's settings), and `slicer.mrmlScene.AddNewNodeByClass("vtkMRMLROS2NodeNode")`
a ROS node. `slicer.util.getModuleLogic('ROS2Bridge')` offers the same methods. Observers
and callbacks run on Slicer's main thread, in this module's 20 ms spin (the reference's 50
Hz timer), never while a command waits.

Verified against (every Slicer/MRML/VTK call below was read in these sources; the list with
the facts relied on is in slicer_client/README.md, "Verified against"):
- openigtlink/SlicerOpenIGTLink d090ca4 (2025-11-13): OpenIGTLinkIF/MRML/
  vtkMRMLIGTLConnectorNode.{h,cxx}, vtkSlicerOpenIGTLinkCommand.{h,cxx},
  OpenIGTLinkIF/Logic/vtkSlicerOpenIGTLinkIFLogic.cxx, qSlicerOpenIGTLinkIFModule.cxx,
  GenericSerialDeviceRemoteControl.py (Python use of commands);
- IGSIO/OpenIGTLinkIO d7f6aef (2025-07-18): Logic/igtlioConnector.cxx, Logic/igtlioCommand.{h,cxx},
  Converter/igtlioStringConverter.cxx, Converter/igtlioPolyDataConverter.cxx;
- Slicer/Slicer 583e9b3 (main) and tags v5.2.0/v5.4.0: Base/Python/slicer/ScriptedLoadableModule.py,
  util.py, parameterNodeWrapper/{wrapper,guiConnectors,validators}.py,
  Utilities/Templates/Modules/Scripted/TemplateKey.py, Libs/MRML/Core/vtkMRMLScene.{h,cxx},
  vtkMRMLNode.h, vtkMRMLTextNode.{h,cxx}, vtkMRMLTransformNode.cxx,
  vtkMRMLTransformableNode.h, vtkMRMLDisplayNode.h, vtkMRMLDisplayableNode.h,
  vtkMRMLSubjectHierarchyNode.h.
Not verifiable here: anything at run time (Slicer cannot run on the build machine), the
PythonQt/VTK wrapping of each overload (assumed from the public headers and from the
SlicerOpenIGTLink Python modules that make the same calls).
"""

import json
import logging
import os
import sys
import time

# In a clone (module added as an additional module path) the packages are three folders up;
# installed as an extension they sit beside this file, on Slicer's path already.
_REPO_ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..", ".."))
if os.path.isfile(os.path.join(_REPO_ROOT, "slicer_client", "__init__.py")) \
        and _REPO_ROOT not in sys.path:
    sys.path.insert(0, _REPO_ROOT)

from typing import Annotated  # noqa: E402  (Python 3.9+, as Slicer 5.4+ ships)

import ctk  # noqa: E402
import numpy as np  # noqa: E402
import qt  # noqa: E402
import slicer  # noqa: E402
import vtk  # noqa: E402
from slicer.parameterNodeWrapper import WithinRange, parameterNodeWrapper  # noqa: E402
from slicer.ScriptedLoadableModule import (ScriptedLoadableModule,  # noqa: E402
                                           ScriptedLoadableModuleLogic,
                                           ScriptedLoadableModuleTest,
                                           ScriptedLoadableModuleWidget)
from slicer.util import VTKObservationMixin  # noqa: E402

from protocol.liveness import HEARTBEAT_DEVICE  # noqa: E402
from slicer_client.bridge_state import BridgeState  # noqa: E402
from slicer_client.client import Client, read_key_file  # noqa: E402
from slicer_client.connection import CommandTimeoutError, ConnectionClosedError  # noqa: E402
from slicer_client.connector_codec import (SLICER_TEXT_ENCODING, build_command,  # noqa: E402
                                           message_from_node, outgoing_content, parse_reply)
from slicer_client.joint_sliders import joint_sliders, slider_positions  # noqa: E402
from slicer_client.reference.entry_points import install as install_entry_points  # noqa: E402
from slicer_client.scene_plan import (MARKERS_FOLDER, ROBOTS_FOLDER,  # noqa: E402
                                      describe_bridges, metadata_from_attributes, plan_node,
                                      robot_status_lines, stale_lines,
                                      stale_marker_nodes)
from slicer_client.send_plan import KIND_ORDER, SEND_TYPES, plan_send  # noqa: E402

CONNECTOR_NAME = "ROS2BridgeConnector"
SPIN_INTERVAL_MS = 20  # the reference spins its node at 50 Hz
CONNECT_WAIT_S = 10.0  # a script's first reference call waits this long for the daemon
log = logging.getLogger("ROS2Bridge")


class ROS2Bridge(ScriptedLoadableModule):
    def __init__(self, parent):
        ScriptedLoadableModule.__init__(self, parent)
        self.parent.title = "ROS2 Bridge"
        self.parent.categories = ["IGT"]
        self.parent.dependencies = ["OpenIGTLinkIF"]
        self.parent.contributors = ["slicer-ros2-bridge contributors"]
        self.parent.helpText = (
            "Connects 3D Slicer to ROS 2 through the slicer-ros2-bridge daemon over "
            "OpenIGTLink: topics, tf, parameters and robots. Start the daemon "
            "(<code>slicer-ros2-bridge run</code>), then press Connect.")
        self.parent.acknowledgementText = (
            "Mirrors the API of SlicerROS2 (rosmed/slicer_ros2_module) out of process.")
        # Once every module is loaded: is SlicerROS2 there to answer its own name?
        slicer.app.connect("startupCompleted()", _installReferenceEntryPoints)


class _ReferenceLogic:
    """`getModuleLogic('ROS2')` before this module's GUI exists: the module logic is made
    (and connected) only when a reference method is first called."""

    def __getattr__(self, name):
        return getattr(slicer.util.getModuleLogic("ROS2Bridge"), name)


def _installReferenceEntryPoints():
    if install_entry_points(slicer, _ReferenceLogic()):
        log.info("answering SlicerROS2's getModuleLogic('ROS2') (SlicerROS2 is not installed)")

# The fixed frame markers are placed in and models are sent in, by default: the demo robot's
# root (REP 105's robot base frame), which a graph without a "world" frame still has.
DEFAULT_FRAME = "base_link"


@parameterNodeWrapper
class ROS2BridgeParameterNode:
    """GUI state and the saved bridges (bridgeState: slicer_client BridgeState JSON)."""

    host: str = "127.0.0.1"
    port: Annotated[int, WithinRange(1, 65535)] = 18944  # the QSpinBox connector sets the range
    # The defaults fit `slicer-ros2-bridge demo` (its robot, its root frame base_link).
    robotName: str = "demo"
    robotNode: str = "/robot_state_publisher"
    robotParameter: str = "robot_description"
    # The writers' key (`slicer-ros2-bridge keygen`): presented on each connection, so this
    # module may change ROS on a daemon that asks for it (docs/deployment.md).
    keyFile: str = ""
    bridgeState: str = ""


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
    (bridge/knock.py), and the connector then reconnects at once. (Restarting the connector
    here would start a blocking connect() with no timeout, which a later Stop() waits for.)
    """

    watches_silence = True
    # The connector puts each value into the scene itself, whatever its age: the daemon
    # cuts a dead link before its backlog ages past the freshness bound.
    drops_late_values = False

    def __init__(self, connector, clock=time.monotonic):
        self.connector = connector
        self.address = f"{connector.GetServerHostname()}:{connector.GetServerPort()}"
        self._clock = clock
        self._listener = None
        self._node_observers = {}  # node id -> (node, tag)
        self._connector_tags = []
        self._first = True
        self._up_now = False  # the listener was told "connected" and not "lost" since
        self._dead_after = 0.0  # seconds without a heartbeat that mean a dead link (0: off)
        self._heard = 0.0  # when the last heartbeat came (clock)
        self._silent_since = None  # clock, while the heartbeat is missing on a live socket
        self._heartbeat = None  # (node, tag) of the heartbeat's STATUS node
        self.heartbeats = 0  # heard on this transport

    @property
    def connected(self):
        return self._socket_up() and self._silent_since is None

    @property
    def silent(self):
        """The heartbeat stopped on a socket the connector still holds."""
        return self._silent_since is not None

    def _socket_up(self):
        return self.connector.GetState() == slicer.vtkMRMLIGTLConnectorNode.StateConnected

    def set_listener(self, listener):
        self._listener = listener
        for event, handler in ((slicer.vtkMRMLIGTLConnectorNode.ConnectedEvent,
                                self._onConnectedEvent),
                               (slicer.vtkMRMLIGTLConnectorNode.DisconnectedEvent,
                                self._onDisconnectedEvent)):
            self._connector_tags.append(self.connector.AddObserver(event, handler))
        if self.connected:
            self._up()  # errors reach whoever made the Client

    def _up(self):
        first, self._first = self._first, False
        self._up_now = True
        self._silent_since = None
        self._listener.on_connected(self.command, first)

    def _onConnectedEvent(self, caller=None, event=None):
        if self._up_now or self._listener is None:
            return
        self._silent_since = None  # a new socket
        try:
            self._up()
        except Exception:  # noqa: BLE001 - inside a VTK callback: log, keep the connector
            log.exception("re-creating the bridges on %s failed", self.address)

    def _onDisconnectedEvent(self, caller=None, event=None):
        self._down("the connector lost the daemon (it retries itself)")

    def expect_data_within(self, seconds):
        """The daemon sends this connection a heartbeat (hello asked for it)."""
        self._dead_after = max(0.0, float(seconds))
        self._heard = self._clock()

    def _watchStatusNodes(self):
        """Observe the STATUS nodes the connector makes: the heartbeat's (counted), and
        each stream's stale/live condition (handed to the client, which marks the
        subscriber stale as slicer_client does)."""
        for i in range(self.connector.GetNumberOfIncomingMRMLNodes()):
            node = self.connector.GetIncomingMRMLNode(i)
            if node is None or not node.IsA("vtkMRMLIGTLStatusNode"):
                continue
            if node.GetName() != HEARTBEAT_DEVICE:
                self.watch(node)
            elif self._heartbeat is None or self._heartbeat[0] is not node:
                if self._heartbeat is not None:
                    self._heartbeat[0].RemoveObserver(self._heartbeat[1])
                tag = node.AddObserver(vtk.vtkCommand.ModifiedEvent, self._onHeartbeat)
                self._heartbeat = (node, tag)
                node.SetHideFromEditors(True)  # plumbing, not data for the user

    def _onHeartbeat(self, caller=None, event=None):
        self._heard = self._clock()
        self.heartbeats += 1

    def poll(self):
        """Called from the module's timer: report a loss the connector has not yet sent,
        or a heartbeat gone missing; and a heartbeat back on the same socket."""
        if not self._socket_up():
            self._silent_since = None
            self._down("the connector lost the daemon (it retries itself)")
            return
        if self._listener is None:
            return
        self.connector.PeriodicProcess()  # what has come is counted before judging silence
        self._watchStatusNodes()
        if not self._dead_after:
            return
        now = self._clock()
        if self._silent_since is not None:
            if self._heard > self._silent_since:  # the same socket carries data again
                try:
                    self._up()
                except Exception:  # noqa: BLE001 - the next loss or reconnect retries
                    log.exception("re-creating the bridges on %s failed", self.address)
            return
        silence = now - self._heard
        if self._up_now and silence > self._dead_after:
            self._silent_since = now
            self._down(f"no heartbeat from the daemon for {silence:.1f} s: the link to "
                       f"{self.address} is down (a pulled cable?); the connector reconnects "
                       "when it is back")

    def _down(self, reason):
        if not self._up_now or self._listener is None:
            return
        self._up_now = False
        log.warning("%s", reason)
        self._listener.on_disconnected(reason)

    def _requireConnected(self, what):
        if self._silent_since is not None:
            raise ConnectionClosedError(
                f"{what}: no heartbeat from the daemon at {self.address} for more than "
                f"{self._dead_after:g} s (the link is down)")
        if not self._socket_up():
            raise ConnectionClosedError(
                f"{what}: 3D Slicer's connector is not connected to the daemon at "
                f"{self.address} (it keeps retrying; start it with `slicer-ros2-bridge run`)")

    def command(self, op, arguments=None, *, timeout=5.0):
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

    def send(self, message):
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

    def sendNode(self, device, plan, node):
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
            position = [0.0, 0.0, 0.0]
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

    def _outgoing(self, class_name, device):
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

    def watch(self, node):
        """Forward a connector node's updates to the client as Messages. The connector
        ends its node modification once per received message, so ModifiedEvent (text) and
        TransformModifiedEvent (transforms) fire once per message, or once per batch for
        messages read during a blocking command."""
        if node.GetID() in self._node_observers:
            return
        event = (slicer.vtkMRMLTransformNode.TransformModifiedEvent
                 if node.IsA("vtkMRMLTransformNode") else vtk.vtkCommand.ModifiedEvent)
        tag = node.AddObserver(event, lambda caller, _event: self._forward(caller))
        self._node_observers[node.GetID()] = (node, tag)
        self._forward(node)

    def unwatch(self, node):
        entry = self._node_observers.pop(node.GetID(), None)
        if entry is not None:
            entry[0].RemoveObserver(entry[1])

    def _forward(self, node):
        attributes = {name: node.GetAttribute(name) for name in node.GetAttributeNames()}
        if node.IsA("vtkMRMLLinearTransformNode"):
            matrix = vtk.vtkMatrix4x4()
            node.GetMatrixTransformToParent(matrix)
            values = [[matrix.GetElement(i, j) for j in range(4)] for i in range(4)]
            message = message_from_node(node.GetName(), attributes, matrix=values)
        elif node.IsA("vtkMRMLTextNode"):
            message = message_from_node(node.GetName(), attributes, text=node.GetText())
        elif node.IsA("vtkMRMLIGTLStatusNode"):
            message = message_from_node(node.GetName(), attributes, status=(
                node.GetCode(), node.GetErrorName() or "", node.GetStatusString() or ""))
        else:
            return
        if message is not None and self._listener is not None:
            try:
                self._listener.on_message(message)
            except Exception:  # noqa: BLE001 - inside a VTK callback
                log.exception("handling %s failed", node.GetName())

    def close(self):
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


def _worldSurface(modelNode):
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


def nodeKind(node):
    """The "Send to ROS" kind of a node (send_plan.KIND_ORDER, most specific first)."""
    for kind in KIND_ORDER:
        if node.IsA(kind):
            return kind
    return node.GetClassName()


class ROS2BridgeLogic(ScriptedLoadableModuleLogic, VTKObservationMixin):
    """All networking: the connector, the slicer_client Client bound to it, the scene
    builder and the saved bridges."""

    def __init__(self):
        ScriptedLoadableModuleLogic.__init__(self)
        VTKObservationMixin.__init__(self)
        self.connector = None
        self.transport = None
        self.client = None
        self._key = None  # the writers' key, when connect() was given one
        self.problems = []  # errors met outside a button's handler, shown in the GUI
        self._planned = set()  # node ids already placed
        self._timer = qt.QTimer()
        self._timer.setInterval(200)  # new connector nodes are placed within 0.2 s
        self._timer.connect("timeout()", self._onTimer)
        self._spinTimer = qt.QTimer()
        self._spinTimer.setInterval(SPIN_INTERVAL_MS)
        self._spinTimer.connect("timeout()", self.Spin)
        self.addObserver(slicer.mrmlScene, slicer.mrmlScene.StartSaveEvent, self._onSave)
        self.addObserver(slicer.mrmlScene, slicer.mrmlScene.StartCloseEvent,
                         self._onSceneStartClose)

    def getParameterNode(self):
        return ROS2BridgeParameterNode(super().getParameterNode())

    def cleanup(self):
        """Disconnect and stop observing the scene (tests, module unload)."""
        self.disconnect()
        self.removeObservers()

    # --- connection ---------------------------------------------------------------------
    def connect(self, host, port, keyFile=""):
        self._key = read_key_file(keyFile) if keyFile else None  # a bad file: said now
        if self.connector is None:
            self.connector = slicer.mrmlScene.GetFirstNode(CONNECTOR_NAME,
                                                           "vtkMRMLIGTLConnectorNode")
        if self.connector is None:
            self.connector = slicer.mrmlScene.AddNewNodeByClass("vtkMRMLIGTLConnectorNode",
                                                                CONNECTOR_NAME)
        self.connector.Stop()  # returns 0 when it was not running
        self.connector.SetTypeClient(str(host), int(port))
        if not self.connector.Start():
            raise RuntimeError(f"3D Slicer's connector did not start (client of {host}:{port})")
        self.removeObservers(self._onConnected)
        self.addObserver(self.connector, slicer.vtkMRMLIGTLConnectorNode.ConnectedEvent,
                         self._onConnected)
        self._timer.start()
        self._spinTimer.start()
        if self.isConnected():
            self._onConnected()

    def disconnect(self):
        self._timer.stop()
        self._spinTimer.stop()
        if self.connector is not None:
            self.removeObservers(self._onConnected)
            self.connector.Stop()
        if self.transport is not None:
            self.transport.close()
        self.transport = None
        self.client = None

    def isConnected(self):
        """Connected, and the daemon's heartbeat comes (a pulled cable leaves the
        connector's socket looking connected)."""
        if self.transport is not None:
            return self.transport.connected
        return (self.connector is not None and self.connector.GetState()
                == slicer.vtkMRMLIGTLConnectorNode.StateConnected)

    def isLinkSilent(self):
        """The connector's socket looks connected but the daemon's heartbeat stopped."""
        return self.transport is not None and self.transport.silent

    def isActive(self):
        """The connector runs (connected or retrying)."""
        return (self.connector is not None and self.connector.GetState()
                != slicer.vtkMRMLIGTLConnectorNode.StateOff)

    def _onConnected(self, caller=None, event=None):
        if self.client is not None:
            return  # the transport re-syncs the existing client itself
        transport = ConnectorTransport(self.connector)
        try:
            # Callbacks wait for this module's spin: they run on the main thread.
            client = Client(transport, callbacks="spin",
                            key=self._key)  # sends hello (and the key)
        except Exception as error:
            transport.close()
            if caller is None:
                raise
            log.exception("the daemon at %s did not answer hello", transport.address)
            self.problems.append(f"The daemon at {transport.address} did not answer: {error}")
            return
        self.transport, self.client = transport, client
        saved = self.getParameterNode().bridgeState
        if saved:
            try:
                client.restore(BridgeState.from_json(saved))
            except Exception as error:  # noqa: BLE001 - a bad saved bridge must not stop the rest
                log.exception("restoring the saved bridges failed")
                self.problems.append(f"Restoring the scene's saved bridges failed: {error}")

    def requireClient(self):
        if self.client is None:
            raise RuntimeError("not connected to the slicer-ros2-bridge daemon: press Connect "
                               "(and start the daemon with `slicer-ros2-bridge run`)")
        return self.client

    # --- the reference's logic (vtkSlicerROS2Logic) -------------------------------------------
    def referenceLogic(self):
        """The reference's logic over this module's client; a script that calls it before
        Connect gets connected to the settings' host and port (waiting up to 10 s)."""
        if self.client is None and not self.isActive():
            parameters = self.getParameterNode()
            self.connect(parameters.host, parameters.port)
        deadline = time.monotonic() + CONNECT_WAIT_S
        while self.client is None and time.monotonic() < deadline:
            slicer.app.processEvents()  # runs the connector's timer: it connects
            time.sleep(0.01)
        return self.requireClient().logic

    def Spin(self):  # noqa: N802
        """Run the callbacks of what arrived (the spin timer calls it every 20 ms)."""
        if self.client is not None:
            self.client.Spin()

    def GetDefaultROS2Node(self):  # noqa: N802 - the reference's name
        return self.referenceLogic().GetDefaultROS2Node()

    def CreateROS2Node(self, name=""):  # noqa: N802
        return self.referenceLogic().CreateROS2Node(name)

    def AddRobot(self, robotName, parameterNodeName, parameterName="robot_description",  # noqa: N802,N803
                 fixedFrame="", tfPrefix=""):  # noqa: N803
        return self.referenceLogic().AddRobot(robotName, parameterNodeName, parameterName,
                                              fixedFrame, tfPrefix)

    def RemoveRobot(self, robotName):  # noqa: N802,N803
        return self.referenceLogic().RemoveRobot(robotName)

    # --- robots and bridges -------------------------------------------------------------
    def loadRobot(self, name, node, parameter):
        robot = self.requireClient().robot(name, node=node, parameter=parameter)
        self._saveState()
        self.updateScene()
        return robot

    def removeRobot(self, name):
        robot = self.requireClient().find("create_robot", name)
        if robot is not None:
            robot.remove()
        for node in list(slicer.util.getNodesByClass("vtkMRMLNode")):
            if node.GetScene() is None or node.GetAttribute("OpenIGTLink.ros2.robot") != name:
                continue
            self._removeNode(node)
        sh = slicer.vtkMRMLSubjectHierarchyNode.GetSubjectHierarchyNode(slicer.mrmlScene)
        folder = sh.GetItemByName(f"robot {name}")
        if folder:
            sh.RemoveItem(folder)
        self._saveState()

    def _removeNode(self, node):
        label = slicer.mrmlScene.GetFirstNode(f"{node.GetName()} label",
                                              "vtkMRMLMarkupsFiducialNode")
        if label is not None and node.IsA("vtkMRMLTextNode"):
            self._removeNode(label)  # a text marker's labelled point goes with it
        if self.transport is not None:
            self.transport.unwatch(node)
        self._planned.discard(node.GetID())
        displays = []
        if node.IsA("vtkMRMLDisplayableNode"):
            displays = [node.GetNthDisplayNode(i) for i in range(node.GetNumberOfDisplayNodes())]
        slicer.mrmlScene.RemoveNode(node)  # display nodes are not removed with it
        for display in displays:
            if display is not None:
                slicer.mrmlScene.RemoveNode(display)

    # --- markers ------------------------------------------------------------------------
    def addMarkers(self, topic, type, fixed_frame):
        """Show a Marker/MarkerArray/Path/PolygonStamped/PointStamped topic as models
        placed by tf in `fixed_frame` (models under "ROS2 markers")."""
        markers = self.requireClient().markers(topic, type, fixed_frame)
        self._saveState()
        self.updateScene()
        return markers

    def removeMarkers(self, topic):
        client = self.requireClient()
        markers = client.find("create_marker_subscriber", topic)
        resolved = markers.resolved_topic if markers is not None else "/" + topic.lstrip("/")
        client.remove_bridge("create_marker_subscriber", topic)  # ours or another client's
        for node in list(slicer.util.getNodesByClass("vtkMRMLNode")):
            if node.GetScene() is not None and node.GetAttribute("OpenIGTLink.ros2.role") \
                    in ("marker", "marker_topic") \
                    and node.GetAttribute("OpenIGTLink.ros2.topic") == resolved:
                self._removeNode(node)
        self._saveState()

    def _removeStaleMarkers(self):
        """Remove the model nodes of markers the daemon deleted (its topic's list of live
        markers no longer holds them: DELETE, DELETEALL, lifetime)."""
        if self.client is None:
            return
        live = {r.resolved_topic: r.live for r in self.client.resources()
                if r.spec.op == "create_marker_subscriber" and r.live is not None}
        if not live:
            return
        nodes = {}
        by_name = {}
        for i in range(self.connector.GetNumberOfIncomingMRMLNodes()):
            node = self.connector.GetIncomingMRMLNode(i)
            if node is None or node.GetAttribute("OpenIGTLink.ros2.role") != "marker":
                continue
            attributes = {n: node.GetAttribute(n) for n in node.GetAttributeNames()}
            nodes[node.GetName()] = metadata_from_attributes(attributes)
            by_name[node.GetName()] = node
        for device in stale_marker_nodes(nodes, live):
            self._removeNode(by_name[device])

    def _placeLabel(self, node, plan):
        """A text marker (a text node) as a markups point labelled with its text, under
        its frame's transform; updated each tick, since the text node's content changes."""
        name = f"{node.GetName()} label"
        label = slicer.mrmlScene.GetFirstNode(name, "vtkMRMLMarkupsFiducialNode")
        if label is None:
            label = slicer.mrmlScene.AddNewNodeByClass("vtkMRMLMarkupsFiducialNode", name)
            label.SetDescription(plan.display_name)
        if plan.label_parent is not None:
            parent = slicer.mrmlScene.GetFirstNode(plan.label_parent,
                                                   "vtkMRMLLinearTransformNode")
            if parent is not None and label.GetTransformNodeID() != parent.GetID():
                label.SetAndObserveTransformNodeID(parent.GetID())
        x, y, z = plan.label_position
        text = node.GetText() or ""
        if label.GetNumberOfControlPoints() == 0:
            label.AddControlPoint(vtk.vtkVector3d(x, y, z), text)
        else:
            label.SetNthControlPointPosition(0, x, y, z)
            label.SetNthControlPointLabel(0, text)
        display = label.GetDisplayNode()
        if display is not None and plan.colour is not None:
            display.SetSelectedColor(*plan.colour)

    def _updateMarkerLabels(self):
        for i in range(self.connector.GetNumberOfIncomingMRMLNodes()):
            node = self.connector.GetIncomingMRMLNode(i)
            if node is None or not node.IsA("vtkMRMLTextNode") \
                    or node.GetAttribute("OpenIGTLink.ros2.role") != "marker":
                continue
            attributes = {n: node.GetAttribute(n) for n in node.GetAttributeNames()}
            plan = plan_node(node.GetName(), metadata_from_attributes(attributes))
            if plan.label_position is not None:
                self._placeLabel(node, plan)

    # --- Slicer -> ROS ------------------------------------------------------------------
    def sendToROS(self, node, topic, frame, rosType=None):
        """Publish a model or markups node on ``topic`` in ``frame`` (metres in ROS):
        creates the publisher (the daemon judges the topic and the frame) and pushes the
        node's data once. Returns the Publisher."""
        if node is None:
            raise ValueError("select a model or markups node to send")
        plan = plan_send(nodeKind(node), topic, rosType or None)
        client = self.requireClient()
        publisher = client.publisher(topic, plan.ros_type, frame=frame or None,
                                     labels_topic=plan.labels_topic)
        self.transport.sendNode(publisher.device, plan, node)
        self._saveState()
        return publisher

    # --- moving a robot -----------------------------------------------------------------
    def _robot(self, robotName):
        robot = self.requireClient().find("create_robot", robotName)
        if robot is None:
            raise RuntimeError(f"no robot {robotName!r}: load it first")
        return robot

    def jointSliders(self, robotName):
        """One slider spec per actuated joint of a loaded robot (mimic joints follow)."""
        return joint_sliders(self._robot(robotName).joints(refresh=True)["joints"])

    def setJoints(self, robotName, sliders, values):
        """Publish the joint state the sliders say (display units: degrees, mm); the
        daemon checks the URDF limits and adds the mimic joints."""
        return self._robot(robotName).set_joints(slider_positions(sliders, values))

    def robotNames(self):
        if self.client is None:
            return []
        return [r.name for r in self.client.resources() if r.spec.op == "create_robot"]

    def bridgeLines(self):
        return describe_bridges(self.requireClient().list_bridges())

    def staleLines(self):
        """This client's streams that the daemon says are stale, for the GUI: a frozen
        robot must not look live. The daemon pushes each change as a STATUS on the
        stream's device (no listing, no command)."""
        if self.client is None:
            return []
        return stale_lines(self.client.resources())

    def robotLines(self):
        """Load progress and warnings of every robot, for the GUI (not only the log)."""
        if self.client is None:
            return []
        return robot_status_lines([r for r in self.client.resources()
                                   if r.spec.op == "create_robot"])

    # --- scene building -----------------------------------------------------------------
    def _onTimer(self):
        if self.transport is not None:
            self.transport.poll()
        self.updateScene()

    def updateScene(self):
        """Place the connector's new nodes as the scene planner says."""
        if self.connector is None or self.connector.GetScene() is None:
            return
        link_devices = {}
        if self.client is not None:
            for robot in self.client.resources():
                for link in getattr(robot, "links", {}).values():
                    if link.device:
                        link_devices[(robot.name, link.name)] = link.device
        for i in range(self.connector.GetNumberOfIncomingMRMLNodes()):
            node = self.connector.GetIncomingMRMLNode(i)
            if node is None or node.GetID() in self._planned:
                continue
            attributes = {n: node.GetAttribute(n) for n in node.GetAttributeNames()}
            metadata = metadata_from_attributes(attributes)
            if "ros2.role" not in metadata:
                continue  # attributes not there yet: next tick
            plan = plan_node(node.GetName(), metadata, rgba_mean=self._rgbaMean(node),
                             link_devices=link_devices)
            if plan.parent_device is not None and node.IsA("vtkMRMLTransformableNode"):
                parent = slicer.mrmlScene.GetFirstNode(plan.parent_device,
                                                       "vtkMRMLLinearTransformNode")
                if parent is None:
                    continue  # its link transform has not arrived yet: next tick
                node.SetAndObserveTransformNodeID(parent.GetID())
            self._apply(node, plan)
            if self.transport is not None:
                self.transport.watch(node)
            self._planned.add(node.GetID())
        self._removeStaleMarkers()
        self._updateMarkerLabels()

    @staticmethod
    def _rgbaMean(node):
        if not node.IsA("vtkMRMLModelNode") or node.GetPolyData() is None:
            return None
        array = node.GetPolyData().GetPointData().GetArray("RGBA")
        if array is None or array.GetNumberOfTuples() == 0:
            return None
        return np.asarray(slicer.util.arrayFromModelPointData(node, "RGBA")).mean(axis=0)

    def _apply(self, node, plan):
        node.SetDescription(plan.display_name)  # node names stay = device names (see planner)
        if plan.colour is not None and node.IsA("vtkMRMLModelNode"):
            display = node.GetDisplayNode()
            if display is None:
                node.CreateDefaultDisplayNodes()
                display = node.GetDisplayNode()
            display.SetColor(*plan.colour)
            display.SetOpacity(plan.opacity)
            if plan.point_colours:  # per-point marker colours, shown as they are (0..1)
                display.SetActiveScalar("RGBA", vtk.vtkAssignAttribute.POINT_DATA)
                display.SetScalarRangeFlagFromString("UseDirectMapping")
                display.SetScalarVisibility(True)
            else:
                display.SetScalarVisibility(False)
        if plan.folder:
            sh = slicer.vtkMRMLSubjectHierarchyNode.GetSubjectHierarchyNode(slicer.mrmlScene)
            top_name = (ROBOTS_FOLDER if plan.kind.startswith("robot") else
                        MARKERS_FOLDER if plan.kind in ("marker", "marker_text") else None)
            top = sh.GetItemByName(top_name) if top_name else None
            if top_name and not top:
                top = sh.CreateFolderItem(sh.GetSceneItemID(), top_name)
            parent = top or sh.GetSceneItemID()
            folder = sh.GetItemChildWithName(parent, plan.folder)
            if not folder:
                folder = sh.CreateFolderItem(parent, plan.folder)
            item = sh.GetItemByDataNode(node)
            if item:
                sh.SetItemParent(item, folder)

    # --- saving -------------------------------------------------------------------------
    def _saveState(self):
        if self.client is not None:
            self.getParameterNode().bridgeState = self.client.state().to_json()

    def _onSave(self, caller=None, event=None):
        self._saveState()

    def _onSceneStartClose(self, caller=None, event=None):
        # The connector node leaves the scene; no timer would process it any more.
        self.disconnect()
        self.connector = None
        self._planned.clear()


class ROS2BridgeWidget(ScriptedLoadableModuleWidget, VTKObservationMixin):
    def __init__(self, parent=None):
        ScriptedLoadableModuleWidget.__init__(self, parent)
        VTKObservationMixin.__init__(self)
        self.logic = None
        self._parameterNode = None
        self._parameterNodeGuiTag = None

    def setup(self):
        ScriptedLoadableModuleWidget.setup(self)
        self.logic = ROS2BridgeLogic()
        form = qt.QFormLayout()
        box = qt.QWidget()
        box.setLayout(form)
        self.layout.addWidget(box)

        self.hostEdit = qt.QLineEdit()
        self.portSpin = qt.QSpinBox()
        self.keyFileEdit = qt.QLineEdit()
        self.keyFileEdit.placeholderText = ("writers' key file (needed to change ROS on a "
                                            "remote daemon)")
        self.connectButton = qt.QPushButton("Connect")
        self.connectButton.checkable = True
        self.statusLabel = qt.QLabel("Not connected")
        form.addRow("Host:", self.hostEdit)
        form.addRow("Port:", self.portSpin)
        form.addRow("Key file:", self.keyFileEdit)
        form.addRow(self.connectButton)
        form.addRow("Status:", self.statusLabel)

        self.robotNameEdit = qt.QLineEdit()
        self.robotNodeEdit = qt.QLineEdit()
        self.robotParameterEdit = qt.QLineEdit()
        self.loadRobotButton = qt.QPushButton("Load robot")
        self.anotherRobotButton = qt.QPushButton("+")
        self.anotherRobotButton.toolTip = "Another robot: a new name, the same defaults"
        self.robotCombo = qt.QComboBox()
        self.removeRobotButton = qt.QPushButton("Remove robot")
        form.addRow("Robot name:", self.robotNameEdit)
        form.addRow("Node:", self.robotNodeEdit)
        form.addRow("Parameter:", self.robotParameterEdit)
        row = qt.QHBoxLayout()
        row.addWidget(self.loadRobotButton)
        row.addWidget(self.anotherRobotButton)
        form.addRow(row)
        form.addRow(self.robotCombo, self.removeRobotButton)
        self.robotStatusLabel = qt.QLabel("")
        self.robotStatusLabel.wordWrap = True
        form.addRow("Robots:", self.robotStatusLabel)
        self.staleLabel = qt.QLabel("")
        self.staleLabel.wordWrap = True
        self.staleLabel.styleSheet = "color: #b36b00; font-weight: bold"
        form.addRow(self.staleLabel)
        self.problemsLabel = qt.QLabel("")
        self.problemsLabel.wordWrap = True
        self.problemsLabel.styleSheet = "color: #b00020"
        form.addRow(self.problemsLabel)

        # Markers: the same calls as the robot controls (QLineEdit, QComboBox, QPushButton).
        self.markerTopicEdit = qt.QLineEdit()
        self.markerTopicEdit.text = "/visualization_marker_array"
        self.markerTypeCombo = qt.QComboBox()
        for name in ("MarkerArray", "Marker", "Path", "PolygonStamped", "PointStamped"):
            self.markerTypeCombo.addItem(name)
        self.markerFrameEdit = qt.QLineEdit()
        self.markerFrameEdit.text = DEFAULT_FRAME
        self.addMarkersButton = qt.QPushButton("Show markers")
        self.removeMarkersButton = qt.QPushButton("Remove markers")
        form.addRow("Marker topic:", self.markerTopicEdit)
        form.addRow("Type:", self.markerTypeCombo)
        form.addRow("Fixed frame:", self.markerFrameEdit)
        form.addRow(self.addMarkersButton, self.removeMarkersButton)

        self.bridgeList = qt.QListWidget()
        self.refreshButton = qt.QPushButton("Refresh bridges")
        form.addRow("Active bridges:", self.bridgeList)
        form.addRow(self.refreshButton)

        # Send to ROS: a model (Mesh / Marker) or markups (PoseArray, PointStamped, Path).
        sendBox = ctk.ctkCollapsibleButton()
        sendBox.text = "Send to ROS"
        self.layout.addWidget(sendBox)
        sendForm = qt.QFormLayout(sendBox)
        self.sendNodeSelector = slicer.qMRMLNodeComboBox()
        self.sendNodeSelector.nodeTypes = list(KIND_ORDER)
        self.sendNodeSelector.addEnabled = False
        self.sendNodeSelector.removeEnabled = False
        self.sendNodeSelector.noneEnabled = True
        self.sendNodeSelector.setMRMLScene(slicer.mrmlScene)
        self.sendTypeCombo = qt.QComboBox()
        self.sendTopicEdit = qt.QLineEdit("/slicer/model")
        self.sendFrameEdit = qt.QLineEdit(DEFAULT_FRAME)
        self.sendButton = qt.QPushButton("Send to ROS")
        sendForm.addRow("Node:", self.sendNodeSelector)
        sendForm.addRow("As:", self.sendTypeCombo)
        sendForm.addRow("Topic:", self.sendTopicEdit)
        sendForm.addRow("Frame:", self.sendFrameEdit)
        sendForm.addRow(self.sendButton)

        # Joints: one slider per actuated joint of the robot chosen above.
        jointsBox = ctk.ctkCollapsibleButton()
        jointsBox.text = "Robot joints"
        self.layout.addWidget(jointsBox)
        jointsLayout = qt.QVBoxLayout(jointsBox)
        self.showJointsButton = qt.QPushButton("Show joints of the selected robot")
        jointsLayout.addWidget(self.showJointsButton)
        self.jointsForm = qt.QFormLayout()
        jointsLayout.addLayout(self.jointsForm)
        self._sliders = []  # JointSlider specs of the robot shown
        self._sliderWidgets = {}  # joint name -> ctkSliderWidget
        self._slidersRobot = ""
        self.layout.addStretch(1)
        self.sendNodeSelector.connect("currentNodeChanged(vtkMRMLNode*)", self.onSendNodeChanged)
        self.sendButton.connect("clicked(bool)", self.onSend)
        self.showJointsButton.connect("clicked(bool)", self.onShowJoints)

        self.connectButton.connect("toggled(bool)", self.onConnectToggled)
        self.loadRobotButton.connect("clicked(bool)", self.onLoadRobot)
        self.anotherRobotButton.connect("clicked(bool)", self.onAnotherRobot)
        self.removeRobotButton.connect("clicked(bool)", self.onRemoveRobot)
        self.refreshButton.connect("clicked(bool)", self.onRefresh)
        self.addMarkersButton.connect("clicked(bool)", self.onAddMarkers)
        self.removeMarkersButton.connect("clicked(bool)", self.onRemoveMarkers)
        self.addObserver(slicer.mrmlScene, slicer.mrmlScene.StartCloseEvent,
                         self.onSceneStartClose)
        self.addObserver(slicer.mrmlScene, slicer.mrmlScene.EndCloseEvent, self.onSceneEndClose)
        self.initializeParameterNode()
        self._statusTimer = qt.QTimer()
        self._statusTimer.setInterval(500)
        self._statusTimer.connect("timeout()", self.updateStatus)
        self._statusTimer.start()

    def cleanup(self):
        self.removeObservers()
        self._statusTimer.stop()
        self.setParameterNode(None)
        if self.logic is not None:
            self.logic.cleanup()

    def enter(self):
        self.initializeParameterNode()

    def onSceneStartClose(self, caller, event):
        self.setParameterNode(None)

    def onSceneEndClose(self, caller, event):
        if self.parent.isEntered:
            self.initializeParameterNode()

    def initializeParameterNode(self):
        self.setParameterNode(self.logic.getParameterNode())

    def setParameterNode(self, parameterNode):
        if self._parameterNode is not None and self._parameterNodeGuiTag is not None:
            self._parameterNode.disconnectGui(self._parameterNodeGuiTag)
            self._parameterNodeGuiTag = None
        self._parameterNode = parameterNode
        if self._parameterNode is not None:
            # Widgets made in code: map parameter names to widgets explicitly
            # (connectGui looks for the "SlicerParameterName" property of .ui widgets).
            self._parameterNodeGuiTag = self._parameterNode.connectParametersToGui({
                "host": self.hostEdit, "port": self.portSpin, "keyFile": self.keyFileEdit,
                "robotName": self.robotNameEdit,
                "robotNode": self.robotNodeEdit, "robotParameter": self.robotParameterEdit})

    def updateStatus(self):
        if self.logic.isConnected():
            info = self.logic.client.daemon_info if self.logic.client else {}
            self.statusLabel.text = (f"Connected to {info.get('node', 'the daemon')} "
                                     f"({self.logic.transport.address})"
                                     if self.logic.transport else "Connected")
        elif self.logic.isLinkSilent():
            self.statusLabel.text = ("LINK LOST: no heartbeat from the daemon; what is shown "
                                     "is not live (waiting for the link to come back)")
        elif self.logic.isActive():
            self.statusLabel.text = "Waiting for the daemon (retrying)..."
        else:
            self.statusLabel.text = "Not connected"
        self.robotStatusLabel.text = "\n".join(self.logic.robotLines())
        self.problemsLabel.text = "\n".join(self.logic.problems[-5:])
        self.staleLabel.text = "\n".join(self.logic.staleLines())
        active = self.logic.isActive()
        if self.connectButton.checked != active:  # e.g. after a scene close
            wasBlocked = self.connectButton.blockSignals(True)
            self.connectButton.checked = active
            self.connectButton.blockSignals(wasBlocked)

    def onConnectToggled(self, on):
        with slicer.util.tryWithErrorDisplay("Failed to (dis)connect.", waitCursor=True):
            if on:
                self.logic.connect(self._parameterNode.host, self._parameterNode.port,
                                   self._parameterNode.keyFile)
            else:
                self.logic.disconnect()
            self.updateStatus()

    def onLoadRobot(self):
        with slicer.util.tryWithErrorDisplay("Failed to load the robot.", waitCursor=True):
            p = self._parameterNode
            self.logic.loadRobot(p.robotName, p.robotNode, p.robotParameter)
            self._refreshRobots()

    def onAnotherRobot(self):
        with slicer.util.tryWithErrorDisplay("Failed to prepare another robot."):
            names = set(self.logic.robotNames())
            index = 2
            while f"robot{index}" in names:
                index += 1
            self._parameterNode.robotName = f"robot{index}"

    def onRemoveRobot(self):
        with slicer.util.tryWithErrorDisplay("Failed to remove the robot.", waitCursor=True):
            name = self.robotCombo.currentText
            if name:
                self.logic.removeRobot(name)
            self._refreshRobots()

    def onAddMarkers(self):
        with slicer.util.tryWithErrorDisplay("Failed to show the markers.", waitCursor=True):
            self.logic.addMarkers(self.markerTopicEdit.text, self.markerTypeCombo.currentText,
                                  self.markerFrameEdit.text)
            self.onRefresh()

    def onRemoveMarkers(self):
        with slicer.util.tryWithErrorDisplay("Failed to remove the markers.", waitCursor=True):
            self.logic.removeMarkers(self.markerTopicEdit.text)
            self.onRefresh()

    def onRefresh(self):
        with slicer.util.tryWithErrorDisplay("Failed to list the bridges."):
            self.bridgeList.clear()
            for line in self.logic.bridgeLines():
                self.bridgeList.addItem(line)

    def onSendNodeChanged(self, node):
        self.sendTypeCombo.clear()
        if node is not None:
            for rosType in SEND_TYPES.get(nodeKind(node), ()):
                self.sendTypeCombo.addItem(rosType)

    def onSend(self):
        with slicer.util.tryWithErrorDisplay("Failed to send to ROS.", waitCursor=True):
            self.logic.sendToROS(self.sendNodeSelector.currentNode(), self.sendTopicEdit.text,
                                 self.sendFrameEdit.text, self.sendTypeCombo.currentText)
            self.onRefresh()

    def onShowJoints(self):
        with slicer.util.tryWithErrorDisplay("Failed to read the robot's joints.",
                                             waitCursor=True):
            name = self.robotCombo.currentText
            sliders = self.logic.jointSliders(name)
            while self.jointsForm.rowCount() > 0:
                self.jointsForm.removeRow(0)
            self._sliders, self._sliderWidgets, self._slidersRobot = sliders, {}, name
            for spec in sliders:
                widget = ctk.ctkSliderWidget()
                widget.decimals = 1 if spec.unit == "deg" else 2
                widget.singleStep = 0.5 if spec.unit == "deg" else 0.1
                widget.minimum, widget.maximum = spec.minimum, spec.maximum
                widget.value = spec.initial
                widget.suffix = " deg" if spec.unit == "deg" else " mm"
                if spec.followers:
                    widget.toolTip = "Also moves (mimic): " + ", ".join(spec.followers)
                widget.connect("valueChanged(double)", self.onSliderMoved)
                self._sliderWidgets[spec.name] = widget
                self.jointsForm.addRow(spec.name + ":", widget)

    def onSliderMoved(self, _value):
        with slicer.util.tryWithErrorDisplay("Failed to move the robot."):
            values = {name: widget.value for name, widget in self._sliderWidgets.items()}
            self.logic.setJoints(self._slidersRobot, self._sliders, values)

    def _refreshRobots(self):
        self.robotCombo.clear()
        for name in self.logic.robotNames():
            self.robotCombo.addItem(name)
        self.onRefresh()


class ROS2BridgeTest(ScriptedLoadableModuleTest):
    """Runs inside 3D Slicer (see slicer_client/slicer_module/selftest.py). The daemon part
    needs a daemon: set ROS2BRIDGE_TEST_PORT to its port, else that part is skipped."""

    def setUp(self):
        slicer.mrmlScene.Clear(0)

    def runTest(self):
        self.setUp()
        self.test_scene_placement()
        self.setUp()
        self.test_daemon_round_trip()

    def test_scene_placement(self):
        self.delayDisplay("Scene planner applied to real MRML nodes")
        logic = ROS2BridgeLogic()
        link = slicer.mrmlScene.AddNewNodeByClass("vtkMRMLLinearTransformNode", "omni:base")
        model = slicer.mrmlScene.AddNewNodeByClass("vtkMRMLModelNode", "omni:base:0")
        for node, role in ((link, "robot_link"), (model, "robot_visual")):
            node.SetAttribute("OpenIGTLink.ros2.role", role)
            node.SetAttribute("OpenIGTLink.ros2.robot", "omni")
            node.SetAttribute("OpenIGTLink.ros2.link", "base")
        model.SetAttribute("OpenIGTLink.ros2.visual", "0")
        model.SetAttribute("OpenIGTLink.ros2.color", "1 0 0 1")
        metadata = metadata_from_attributes(
            {n: model.GetAttribute(n) for n in model.GetAttributeNames()})
        plan = plan_node(model.GetName(), metadata)
        model.SetAndObserveTransformNodeID(link.GetID())
        logic._apply(model, plan)
        self.assertEqual(model.GetParentTransformNode().GetName(), "omni:base")
        self.assertEqual(tuple(model.GetDisplayNode().GetColor()), (1.0, 0.0, 0.0))
        sh = slicer.vtkMRMLSubjectHierarchyNode.GetSubjectHierarchyNode(slicer.mrmlScene)
        folder = sh.GetItemParent(sh.GetItemByDataNode(model))
        self.assertEqual(sh.GetItemName(folder), "robot omni")
        self.assertEqual(sh.GetItemName(sh.GetItemParent(folder)), ROBOTS_FOLDER)
        logic.cleanup()
        self.delayDisplay("Scene placement passed")

    def test_daemon_round_trip(self):
        port = os.environ.get("ROS2BRIDGE_TEST_PORT")
        if not port:
            self.delayDisplay("ROS2BRIDGE_TEST_PORT not set: daemon round trip skipped")
            return
        logic = ROS2BridgeLogic()
        try:
            logic.connect("127.0.0.1", int(port))
            deadline = time.monotonic() + 10.0
            while logic.client is None and time.monotonic() < deadline:
                slicer.app.processEvents()  # runs OpenIGTLinkIF's 5 ms connector timer
                time.sleep(0.01)
            self.assertTrue(logic.isConnected(), f"no daemon at 127.0.0.1:{port}")
            self.assertIsNotNone(logic.client, "connected, but the hello failed (see log)")
            rosNode = logic.GetDefaultROS2Node()  # noqa: N806
            sub = rosNode.CreateAndAddSubscriberNode("String", "/selftest_string")
            pub = rosNode.CreateAndAddPublisherNode("String", "/selftest_string")
            deadline = time.monotonic() + 15.0  # ROS discovery can take a few seconds
            while time.monotonic() < deadline:
                pub.Publish("hello from Slicer")
                for _ in range(20):
                    slicer.app.processEvents()
                    time.sleep(0.01)
                logic.updateScene()
                if sub.GetLastMessage() == "hello from Slicer":
                    break
            self.assertEqual(sub.GetLastMessage(), "hello from Slicer")
            # The daemon's heartbeat reaches the module as a STATUS node's modifications.
            deadline = time.monotonic() + 10.0
            while logic.transport.heartbeats < 2 and time.monotonic() < deadline:
                slicer.app.processEvents()
                logic.transport.poll()
                time.sleep(0.05)
            self.assertGreaterEqual(logic.transport.heartbeats, 2)
            self.assertTrue(logic.isConnected() and not logic.isLinkSilent())
            self.assertIn("subscriber: /selftest_string [std_msgs/msg/String] as "
                          "selftest_string", logic.bridgeLines())
            state = json.loads(BridgeState.from_json(logic.client.state().to_json()).to_json())
            self.assertEqual(len(state["bridges"]), 2)
            try:
                logic.client.command("list_bridges", timeout=5.0)
            except CommandTimeoutError:
                self.fail("list_bridges through the connector timed out")
        finally:
            logic.cleanup()
        self.delayDisplay("Daemon round trip passed")

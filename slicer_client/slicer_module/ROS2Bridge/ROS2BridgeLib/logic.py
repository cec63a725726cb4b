"""ROS2BridgeLogic: all of the ROS2Bridge module's networking and scene work, usable from
scripts without its GUI (`slicer.util.getModuleLogic('ROS2Bridge')`, or made directly).
It owns Slicer's connector node, the slicer_client Client bound to it through
`ConnectorTransport`, the placing of what arrives (as slicer_client/scene_plan.py says),
the saved bridges, and the reference SlicerROS2 logic's methods."""

import logging
import time
from typing import Any, Mapping, Optional, Sequence

import numpy as np
import qt
import slicer
import vtk
from slicer.ScriptedLoadableModule import ScriptedLoadableModuleLogic
from slicer.util import VTKObservationMixin

from protocol import commands as c
from protocol.conversions import metres_to_mm
from protocol.naming import KEY_ROBOT
from protocol.polydata import RGBA_ATTRIBUTE
from slicer_client.bridge_state import BridgeState
from slicer_client.client import Client, read_key_file
from slicer_client.recording import Recording
from slicer_client.joint_sliders import JointSlider, joint_sliders, slider_positions
from slicer_client.reference.logic import ROS2Logic
from slicer_client.reference.nodes import ROS2Node, RobotNode
from slicer_client.resources import MarkerSubscriber, Publisher, Robot
from slicer_client.scene_plan import (ATTRIBUTE_PREFIX, MARKERS_FOLDER, ROBOTS_FOLDER, NodePlan,
                                      describe_bridges, link_metadata,
                                      metadata_from_attributes, plan_node,
                                      robot_status_lines, stale_lines, stale_marker_nodes,
                                      vertex_per_point)
from slicer_client.send_plan import KIND_ORDER, plan_send

from .motion import (OBSTACLE_TOPICS, OBSTACLE_TYPE, MotionPreview, ik_status, obstacle_name,
                     segmentation_surface, target_matrix)
from .parameters import ROS2BridgeParameterNode
from .scene_nodes import SceneNodes, register_node_classes
from .sequences import record_bag
from .transport import ConnectorTransport

__all__ = ["CONNECTOR_NAME", "CONNECT_WAIT_S", "SPIN_INTERVAL_MS", "ROS2BridgeLogic",
           "nodeKind"]

CONNECTOR_NAME = "ROS2BridgeConnector"
SPIN_INTERVAL_MS = 20  # the reference spins its node at 50 Hz
DISTANCE_TOPICS = "/slicer/distance"  # watchDistance's topics: <this>/<link>_to_<obstacle>
DISTANCE_RATE_HZ = 30.0  # what a display shows
MAX_BAG_SAMPLES = 2000  # bagToSequences: each sample is a copy of every streamed node
PATH_PREVIEW_SAMPLES = 50  # configurations of a planned path the preview scrubs through
MOTION_INTERVAL_MS = 33  # a dragged target is solved again at most this often (30 Hz)
CONNECT_WAIT_S = 10.0  # a script's first reference call waits this long for the daemon
log = logging.getLogger("ROS2Bridge")


def playback_line(status: c.PlaybackResult) -> str:
    """A player's clock in words, for the Playback section."""
    state = "ended" if status.ended else "paused" if status.paused else "playing"
    return (f"{status.bag}: {status.offset:.2f} of {status.duration:.2f} s, {state}, "
            f"rate {status.rate:g}" + (", looping" if status.loop else ""))


def nodeKind(node: Any) -> str:
    """The "Send to ROS" kind of a node (send_plan.KIND_ORDER, most specific first)."""
    for kind in KIND_ORDER:
        if node.IsA(kind):
            return kind
    return str(node.GetClassName())


class ROS2BridgeLogic(ScriptedLoadableModuleLogic, VTKObservationMixin):
    """All networking: the connector, the slicer_client Client bound to it, the scene
    builder and the saved bridges."""

    def __init__(self) -> None:
        ScriptedLoadableModuleLogic.__init__(self)
        VTKObservationMixin.__init__(self)
        self.connector: Any = None  # Slicer's vtkMRMLIGTLConnectorNode, once connect() made it
        self.transport: Optional[ConnectorTransport] = None
        self.client: Optional[Client] = None
        self._key: Optional[bytes] = None  # the writers' key, when connect() was given one
        self.problems: list[str] = []  # errors met outside a button's handler, shown in the GUI
        self.recording: Optional[Recording] = None  # the last one started from here
        self._planned: set[str] = set()  # node ids already placed
        # (incoming nodes, links the client knows, link nodes of bundles) when the last
        # scan placed every node; None: scan at the next tick. While it holds and no node
        # came (the connector's NewDeviceEvent) or went, a tick does not scan.
        self._settledAt: Optional[tuple[int, int, int]] = None
        self._bundles: dict[str, Any] = {}  # id -> a robot's tracking-data bundle node
        self._roleless: set[str] = set()  # ids of nodes a scan found with no ros2.role
        # Text markers' nodes, by id: [node, its MTime when last labelled].
        self._markerTexts: dict[str, list[Any]] = {}
        self._timer = qt.QTimer()
        self._timer.setInterval(200)  # new connector nodes are placed within 0.2 s
        self._timer.connect("timeout()", self._onTimer)
        # Motion (issue 46): the followed target, re-solved at the display's rate.
        self._previews: dict[str, MotionPreview] = {}
        self._following: Optional[tuple[str, Any, str]] = None  # robot, target node, tip
        self._targetMoved = False
        self.motionStatus = ""
        self.lastIk: Optional[c.SolveIkResult] = None
        # model node ID -> (robot, topic, frame, obstacle); those moved since last sent
        self._obstacles: dict[str, tuple[str, str, str, str]] = {}
        self._obstaclesMoved: set[str] = set()
        self.execution: Any = None  # the GoalHandle of the latest executeMotion
        self.pathBrowser: Any = None  # the sequence browser of the latest previewPath
        self.distances: dict[tuple[str, str], Any] = {}  # (link, obstacle) -> subscriber
        self._motionTimer = qt.QTimer()
        self._motionTimer.setInterval(MOTION_INTERVAL_MS)
        self._motionTimer.connect("timeout()", self._onMotionTimer)
        self._spinTimer = qt.QTimer()
        self._spinTimer.setInterval(SPIN_INTERVAL_MS)
        self._spinTimer.connect("timeout()", self.Spin)
        # A scene opened before Connect keeps its reference nodes as their classes.
        register_node_classes(slicer.mrmlScene)
        self.addObserver(slicer.mrmlScene, slicer.mrmlScene.StartSaveEvent, self._onSave)
        self.addObserver(slicer.mrmlScene, slicer.mrmlScene.StartCloseEvent,
                         self._onSceneStartClose)
        self.addObserver(slicer.mrmlScene, slicer.mrmlScene.EndImportEvent,
                         self._onSceneEndImport)

    def getParameterNode(self) -> ROS2BridgeParameterNode:
        return ROS2BridgeParameterNode(super().getParameterNode())

    def cleanup(self) -> None:
        """Disconnect and stop observing the scene (tests, module unload)."""
        self.disconnect()
        self.removeObservers()

    # --- connection ---------------------------------------------------------------------
    def connect(self, host: str, port: int, keyFile: str = "") -> None:
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
        self.removeObservers(self._onNewDevice)
        self.addObserver(self.connector, slicer.vtkMRMLIGTLConnectorNode.NewDeviceEvent,
                         self._onNewDevice)
        self._timer.start()
        self._spinTimer.start()
        if self.isConnected():
            self._onConnected()

    def disconnect(self) -> None:
        self._timer.stop()
        self._spinTimer.stop()
        if self.connector is not None:
            self.removeObservers(self._onConnected)
            self.removeObservers(self._onNewDevice)
            self.connector.Stop()
        if self.transport is not None:
            self.transport.close()
        self.transport = None
        self.client = None

    def isConnected(self) -> bool:
        """Connected, and the daemon's heartbeat comes (a pulled cable leaves the
        connector's socket looking connected)."""
        if self.transport is not None:
            return self.transport.connected
        return bool(self.connector is not None and self.connector.GetState()
                    == slicer.vtkMRMLIGTLConnectorNode.StateConnected)

    def isLinkSilent(self) -> bool:
        """The connector's socket looks connected but the daemon's heartbeat stopped."""
        return self.transport is not None and self.transport.silent

    def isActive(self) -> bool:
        """The connector runs (connected or retrying)."""
        return bool(self.connector is not None and self.connector.GetState()
                    != slicer.vtkMRMLIGTLConnectorNode.StateOff)

    def _onConnected(self, caller: Any = None, event: Any = None) -> None:
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
        # The reference's nodes are MRML nodes of this scene (scene_nodes.py).
        client.logic.nodes = SceneNodes(slicer.mrmlScene)
        saved = self.getParameterNode().bridgeState
        if saved:
            try:
                client.restore(BridgeState.from_json(saved))
            except Exception as error:  # noqa: BLE001 - a bad saved bridge must not stop the rest
                log.exception("restoring the saved bridges failed")
                self.problems.append(f"Restoring the scene's saved bridges failed: {error}")
        self._adoptSavedNodes()

    def _adoptSavedNodes(self) -> None:
        """The reference nodes of an opened scene, made again over this client."""
        if self.client is not None:
            self.problems += self.client.logic.nodes.adopt(self.client.logic)

    def _onSceneEndImport(self, caller: Any = None, event: Any = None) -> None:
        self._settledAt = None
        self._adoptSavedNodes()  # connected already: else _onConnected does it

    def requireClient(self) -> Client:
        if self.client is None:
            raise RuntimeError("not connected to the slicer-ros2-bridge daemon: press Connect "
                               "(and start the daemon with `slicer-ros2-bridge run`)")
        return self.client

    # --- the reference's logic (vtkSlicerROS2Logic) -------------------------------------------
    def referenceLogic(self) -> ROS2Logic:
        """The reference's logic over this module's client; a script that calls it before
        Connect gets connected to the settings' host and port (waiting up to 10 s)."""
        if self.client is None and not self.isActive():
            parameters = self.getParameterNode()
            self.connect(parameters.host, parameters.port)
        deadline = time.monotonic() + CONNECT_WAIT_S
        while self.client is None and time.monotonic() < deadline:
            slicer.app.processEvents()  # runs the connector's timer: it connects
            time.sleep(0.01)
        logic: ROS2Logic = self.requireClient().logic
        return logic

    def Spin(self) -> None:  # noqa: N802
        """Run the callbacks of what arrived (the spin timer calls it every 20 ms). The
        connector's messages are taken in first: a script that spins in a loop of its own
        (as SlicerROS2's tests do) keeps Slicer's event loop, and so the connector's and
        this module's timers, from running, and must still receive."""
        self._onTimer()
        if self.client is not None:
            self.client.Spin()

    def GetDefaultROS2Node(self) -> ROS2Node:  # noqa: N802 - the reference's name
        return self.referenceLogic().GetDefaultROS2Node()

    def CreateROS2Node(self, name: str = "") -> ROS2Node:  # noqa: N802
        return self.referenceLogic().CreateROS2Node(name)

    def AddRobot(self, robotName: str, parameterNodeName: str,  # noqa: N802,N803
                 parameterName: str = "robot_description",  # noqa: N803
                 fixedFrame: str = "", tfPrefix: str = "") -> RobotNode:  # noqa: N803
        return self.referenceLogic().AddRobot(robotName, parameterNodeName, parameterName,
                                              fixedFrame, tfPrefix)

    def RemoveRobot(self, robotName: str) -> bool:  # noqa: N802,N803
        return self.referenceLogic().RemoveRobot(robotName)

    # --- a player's clock (slicer-ros2-bridge play BAG) ------------------------------------
    def playbackStatus(self) -> c.PlaybackResult:
        """The bag's clock when connected to a player (the live daemon refuses it)."""
        return self.requireClient().playback()

    def pausePlayback(self) -> c.PlaybackResult:
        return self.requireClient().pause()

    def resumePlayback(self) -> c.PlaybackResult:
        return self.requireClient().resume()

    def seekPlayback(self, offset: float) -> c.PlaybackResult:
        """Play from ``offset`` s into the bag: the robot shows its pose at that time."""
        return self.requireClient().seek(offset)

    def setPlaybackRate(self, rate: float) -> c.PlaybackResult:
        return self.requireClient().set_rate(rate)

    def bagToSequences(self, start: float = 0.0, end: Optional[float] = None,
                       step: float = 0.1) -> Any:
        """The bag a player plays (or the part from `start` to `end` s) as Slicer sequences:
        the player is paused and sought to every `step` s; what the connector's nodes hold
        at each time (link transforms, tf lookups, images, point clouds, text) is recorded,
        one sequence per node, indexed by the bag's clock, under one sequence browser whose
        proxies are the nodes: scrubbing it moves the robot. Returns the browser."""
        status = self.pausePlayback()
        last = status.duration if end is None else min(float(end), status.duration)
        if not (step > 0 and 0 <= start <= last):
            raise ValueError(f"expected 0 <= start <= end <= {status.duration:g} s and a "
                             f"step > 0, got {start:g}, {last:g}, {step:g}")
        count = int(round((last - start) / step)) + 1
        if count > MAX_BAG_SAMPLES:
            raise ValueError(f"expected at most {MAX_BAG_SAMPLES} samples, got {count} (a "
                             f"larger step, or a part of the bag)")
        offsets = [min(last, start + i * step) for i in range(count)]
        return record_bag(slicer.mrmlScene, self.connector, status.bag, offsets,
                          self.seekPlayback)

    # --- robots and bridges -------------------------------------------------------------
    def loadRobot(self, name: str, node: str, parameter: str) -> Robot:
        robot = self.requireClient().robot(name, node=node, parameter=parameter)
        self._saveState()
        self.updateScene()
        return robot

    def removeRobot(self, name: str) -> None:
        robot = self.requireClient().find(c.CreateRobot.op, name)
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

    def _removeNode(self, node: Any) -> None:
        label = slicer.mrmlScene.GetFirstNode(f"{node.GetName()} label",
                                              "vtkMRMLMarkupsFiducialNode")
        if label is not None and node.IsA("vtkMRMLTextNode"):
            self._removeNode(label)  # a text marker's labelled point goes with it
        if self.transport is not None:
            self.transport.unwatch(node)
        if node.IsA("vtkMRMLModelNode") and self.hasObserver(
                node, slicer.vtkMRMLModelNode.MeshModifiedEvent, self._onPointsModified):
            self.removeObserver(node, slicer.vtkMRMLModelNode.MeshModifiedEvent,
                                self._onPointsModified)
        self._planned.discard(node.GetID())
        self._bundles.pop(node.GetID(), None)
        self._markerTexts.pop(node.GetID(), None)
        self._settledAt = None
        displays: list[Any] = []
        if node.IsA("vtkMRMLDisplayableNode"):
            displays = [node.GetNthDisplayNode(i) for i in range(node.GetNumberOfDisplayNodes())]
        slicer.mrmlScene.RemoveNode(node)  # display nodes are not removed with it
        for display in displays:
            if display is not None:
                slicer.mrmlScene.RemoveNode(display)

    # --- markers ------------------------------------------------------------------------
    def addMarkers(self, topic: str, type: str, fixed_frame: str) -> MarkerSubscriber:
        """Show a Marker/MarkerArray/Path/PolygonStamped/PointStamped topic as models
        placed by tf in `fixed_frame` (models under "ROS2 markers")."""
        markers = self.requireClient().markers(topic, type, fixed_frame)
        self._saveState()
        self.updateScene()
        return markers

    def removeMarkers(self, topic: str) -> None:
        client = self.requireClient()
        markers = client.find(c.CreateMarkerSubscriber.op, topic)
        resolved = (markers.resolved_topic if isinstance(markers, MarkerSubscriber)
                    else "/" + topic.lstrip("/"))
        client.remove_bridge(c.CreateMarkerSubscriber.op, topic)  # ours or another client's
        for node in list(slicer.util.getNodesByClass("vtkMRMLNode")):
            if node.GetScene() is not None and node.GetAttribute("OpenIGTLink.ros2.role") \
                    in ("marker", "marker_topic") \
                    and node.GetAttribute("OpenIGTLink.ros2.topic") == resolved:
                self._removeNode(node)
        self._saveState()

    def _removeStaleMarkers(self) -> None:
        """Remove the model nodes of markers the daemon deleted (its topic's list of live
        markers no longer holds them: DELETE, DELETEALL, lifetime)."""
        if self.client is None:
            return
        live = {r.resolved_topic: r.live for r in self.client.resources()
                if isinstance(r, MarkerSubscriber) and r.live is not None}
        if not live:
            return
        nodes: dict[str, dict[str, str]] = {}
        by_name: dict[str, Any] = {}
        for i in range(self.connector.GetNumberOfIncomingMRMLNodes()):
            node = self.connector.GetIncomingMRMLNode(i)
            if node is None or node.GetAttribute("OpenIGTLink.ros2.role") != "marker":
                continue
            attributes = {n: node.GetAttribute(n) for n in node.GetAttributeNames()}
            nodes[node.GetName()] = metadata_from_attributes(attributes)
            by_name[node.GetName()] = node
        for device in stale_marker_nodes(nodes, live):
            self._removeNode(by_name[device])

    def _placeLabel(self, node: Any, plan: NodePlan,
                    position: tuple[float, float, float]) -> None:
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
        x, y, z = position
        text = node.GetText() or ""
        if label.GetNumberOfControlPoints() == 0:
            label.AddControlPoint(vtk.vtkVector3d(x, y, z), text)
        else:
            label.SetNthControlPointPosition(0, x, y, z)
            label.SetNthControlPointLabel(0, text)
        display = label.GetDisplayNode()
        if display is not None and plan.colour is not None:
            display.SetSelectedColor(*plan.colour)

    def _updateMarkerLabels(self) -> None:
        """Move and relabel the labelled point of each text marker that changed."""
        for entry in tuple(self._markerTexts.values()):
            node, labelled = entry
            if node.GetMTime() == labelled:
                continue
            entry[1] = node.GetMTime()
            attributes = {n: node.GetAttribute(n) for n in node.GetAttributeNames()}
            plan = plan_node(node.GetName(), metadata_from_attributes(attributes))
            if plan.label_position is not None:
                self._placeLabel(node, plan, plan.label_position)

    # --- Slicer -> ROS ------------------------------------------------------------------
    def sendToROS(self, node: Any, topic: str, frame: str,
                  rosType: Optional[str] = None) -> Publisher:
        """Publish a model or markups node on ``topic`` in ``frame`` (metres in ROS):
        creates the publisher (the daemon judges the topic and the frame) and pushes the
        node's data once. Returns the Publisher."""
        if node is None:
            raise ValueError("select a model or markups node to send")
        plan = plan_send(nodeKind(node), topic, rosType or None)
        client = self.requireClient()
        publisher = client.publisher(topic, plan.ros_type, frame=frame or None,
                                     labels_topic=plan.labels_topic)
        assert self.transport is not None  # made together with the client
        self.transport.sendNode(publisher.device, plan, node)
        self._saveState()
        return publisher

    # --- moving a robot -----------------------------------------------------------------
    # --- recording (a ROS 2 bag the daemon writes on its machine) ---------------------------
    def startRecording(self, path: str, topics: Sequence[str] = (),
                       overwrite: bool = False) -> Recording:
        """Have the daemon record into ``path`` (absolute, .mcap, on the daemon's machine):
        ``topics``, or without any what it bridges. One recording at a time from here."""
        if self.recording is not None and self.recording.running:
            raise RuntimeError(f"already recording into {self.recording.path}: stop it first")
        if not path.strip():
            raise ValueError("expected a bag path on the daemon's machine (/data/x.mcap), "
                             "got an empty one")
        self.recording = self.requireClient().record(path.strip(), list(topics),
                                                     overwrite=overwrite)
        return self.recording

    def stopRecording(self) -> dict[str, Any]:
        """Finish the bag; its final counts."""
        if self.recording is None or not self.recording.running:
            raise RuntimeError("not recording")
        return self.recording.stop()

    def recordingLine(self) -> str:
        """The file and the elapsed time while recording (no round trip: the GUI's timer
        calls it), the final counts after."""
        rec = self.recording
        if rec is None:
            return ""
        if rec.running:
            return f"Recording {rec.path}: {rec.elapsed:.0f} s"
        final = rec.status()
        error = f"; {final['error']}" if final.get("error") else ""
        return (f"Recorded {rec.path}: {final['messages']} messages, {final['dropped']} "
                f"dropped, {rec.elapsed:.1f} s{error}")

    def _robot(self, robotName: str) -> Robot:
        robot = self.requireClient().find(c.CreateRobot.op, robotName)
        if not isinstance(robot, Robot):
            raise RuntimeError(f"no robot {robotName!r}: load it first")
        return robot

    # --- motion from Slicer (issue 46) -------------------------------------------------
    def solveIk(self, robotName: str, targetNode: Any, tip: str) -> c.SolveIkResult:
        """Solve for `tip` of the robot at `targetNode` (a transform node or a markups
        point, anywhere in the scene) and place the robot's preview at the answer: green
        when solved, red at the best attempt when not. The robot does not move. Returns the
        daemon's answer; `motionStatus` says it in words."""
        robot = self._robot(robotName)
        preview = self._previews.get(robotName)
        if preview is None:
            preview = self._previews[robotName] = MotionPreview(slicer.mrmlScene, robotName)
        target_world = target_matrix(targetNode)
        if preview.root is None:  # once per robot: which scene transform is its root link
            preview.find_root(robot.ik(np.eye(4), tip=tip).links)
        # The daemon takes the target in the root link's frame.
        root_world = preview.root_world()
        result = robot.ik(np.linalg.inv(root_world) @ target_world, tip=tip)
        preview.show(result.links, root_world, result.solved)
        self.lastIk = result
        self.motionStatus = ik_status(tip, result)
        return result

    def previewPath(self, robotName: str, positions: Optional[Mapping[str, float]] = None,
                    *, samples: int = PATH_PREVIEW_SAMPLES) -> dict[str, Any]:
        """Plan the joint-space path to `positions` (default: the last solve's) and show
        it as a sequence the preview robot scrubs through (Slicer's sequence browser
        ``<robot>:preview path``, index: time in s). A read: nothing moves. Returns the
        plan (``clear``, ``collision`` naming the link and the obstacle when it is not)."""
        if positions is None:
            if self.lastIk is None or not self.lastIk.solved:
                raise RuntimeError("nothing to plan to: solve for a target first")
            positions = self.lastIk.positions
        robot = self._robot(robotName)
        preview = self._previews.get(robotName)
        if preview is None or preview.root is None:
            raise RuntimeError("solve for a target first: the preview robot shows the path")
        plan = robot.plan(positions, preview=samples)
        self.pathBrowser = preview.show_path(plan["preview"], preview.root_world())
        collision = plan.get("collision") or {}
        self.motionStatus = (f"Path planned: {plan['checked']} configurations clear, "
                             f"{plan['duration_s']:.1f} s" if plan["clear"] else
                             f"Path blocked: link {collision.get('link')!r} touches "
                             f"obstacle {collision.get('obstacle')!r}")
        return plan

    def followTarget(self, robotName: str, targetNode: Any, tip: str) -> None:
        """Solve again whenever `targetNode` moves, at most once per display frame (the
        newest position wins); `stopFollowing` ends it."""
        self.stopFollowing()
        self.solveIk(robotName, targetNode, tip)  # refuses a bad robot, target or tip now
        self._following = (robotName, targetNode, tip)
        event = (slicer.vtkMRMLTransformNode.TransformModifiedEvent
                 if targetNode.IsA("vtkMRMLTransformNode")
                 else slicer.vtkMRMLMarkupsNode.PointModifiedEvent)
        self.addObserver(targetNode, event, self._onTargetMoved)
        self._motionTimer.start()

    def stopFollowing(self) -> None:
        if self._following is not None:
            target = self._following[1]
            for event in (slicer.vtkMRMLTransformNode.TransformModifiedEvent,
                          slicer.vtkMRMLMarkupsNode.PointModifiedEvent):
                if self.hasObserver(target, event, self._onTargetMoved):
                    self.removeObserver(target, event, self._onTargetMoved)
        self._following = None
        self._targetMoved = False
        if not self._obstacles:
            self._motionTimer.stop()

    def removePreview(self, robotName: str) -> None:
        preview = self._previews.pop(robotName, None)
        if preview is not None:
            preview.remove()

    def addObstacle(self, robotName: str, modelNode: Any, frame: str) -> str:
        """Make a model (or a segmentation: its segments' closed surfaces, as one model
        under its transform) of the scene an obstacle of the robot: sent to ROS as a Marker
        (``/slicer/obstacles/<name>``, its surface in the scene's world, which is `frame`:
        the frame the robot is shown in), and sent again whenever it moves or changes, at
        most every 33 ms. Solving, planning and executing then keep clear of it; returns
        the obstacle's name (the model's, made a ROS name)."""
        if modelNode is None:
            raise ValueError("choose a model or a segmentation node as the obstacle")
        name = obstacle_name(modelNode.GetName())
        if modelNode.IsA("vtkMRMLSegmentationNode"):
            modelNode = segmentation_surface(modelNode)
        if not modelNode.IsA("vtkMRMLModelNode"):
            raise ValueError(f"expected a model or a segmentation node as the obstacle, got "
                             f"{modelNode.GetClassName()} {modelNode.GetName()!r}")
        topic = f"{OBSTACLE_TOPICS}/{name}"
        robot = self._robot(robotName)
        robot.set_obstacle(name, topic, type="Marker")  # sent as OBSTACLE_TYPE below
        self.sendToROS(modelNode, topic, frame, OBSTACLE_TYPE)
        self._obstacles[modelNode.GetID()] = (robotName, topic, frame, name)
        for event in (slicer.vtkMRMLTransformableNode.TransformModifiedEvent,
                      slicer.vtkMRMLModelNode.MeshModifiedEvent):
            if not self.hasObserver(modelNode, event, self._onObstacleMoved):
                self.addObserver(modelNode, event, self._onObstacleMoved)
        self._motionTimer.start()
        return name

    def removeObstacle(self, modelNode: Any) -> None:
        entry = self._obstacles.pop(modelNode.GetID(), None)
        if entry is None:
            return
        for event in (slicer.vtkMRMLTransformableNode.TransformModifiedEvent,
                      slicer.vtkMRMLModelNode.MeshModifiedEvent):
            if self.hasObserver(modelNode, event, self._onObstacleMoved):
                self.removeObserver(modelNode, event, self._onObstacleMoved)
        self._robot(entry[0]).remove_obstacle(entry[3])

    def executeMotion(self, robotName: str, positions: Optional[Mapping[str, float]] = None,
                      *, action: str = c.DEFAULT_TRAJECTORY_ACTION,
                      durationS: Optional[float] = None) -> Any:  # noqa: N803
        """Move the robot to `positions` (default: the last solve's, when it solved) along
        the planned joint-space path, through its FollowJointTrajectory `action`. A path
        that touches an obstacle is refused before anything moves (the error names the
        link and the obstacle). A write. Returns the goal's handle (also `execution`)."""
        if positions is None:
            if self.lastIk is None or not self.lastIk.solved:
                raise RuntimeError("nothing to execute: solve for a target first")
            positions = self.lastIk.positions
        self.execution = self._robot(robotName).execute(positions, action=action,
                                                        duration_s=durationS)
        self.motionStatus = f"Executing on {action}"
        return self.execution

    def watchDistance(self, robotName: str, link: str, obstacle: str) -> Any:
        """Stream the distance from `link` to `obstacle` to this scene: the daemon publishes
        it on ROS (std_msgs/Float64, metres, `DISTANCE_RATE_HZ`; a write) and this module
        subscribes to that topic, so it arrives as other streams do, with no request per
        value. Returns the subscriber; `distanceLine()` shows the newest values in mm."""
        topic = f"{DISTANCE_TOPICS}/{obstacle_name(link)}_to_{obstacle_name(obstacle)}"
        self._robot(robotName).publish_distance(link, obstacle, topic,
                                                rate_hz=DISTANCE_RATE_HZ)
        subscriber = self.requireClient().subscribe(topic, "Float64")
        self.distances[(link, obstacle)] = subscriber
        self._saveState()
        return subscriber

    def watchDistances(self, robotName: str, link: str) -> list[str]:
        """`watchDistance` from `link` to each obstacle this module made for the robot;
        their names."""
        obstacles = [entry[3] for entry in self._obstacles.values() if entry[0] == robotName]
        if not obstacles:
            raise RuntimeError(f"robot {robotName!r} has no obstacle: make a model one first")
        for obstacle in obstacles:
            self.watchDistance(robotName, link, obstacle)
        return obstacles

    def distanceMm(self, link: str, obstacle: str) -> Optional[float]:
        """The newest streamed distance (mm), None before the first."""
        subscriber = self.distances.get((link, obstacle))
        if subscriber is None or subscriber.last_value is None:
            return None
        return float(metres_to_mm(float(subscriber.last_value)))

    def distanceLine(self) -> str:
        lines = []
        for link, obstacle in self.distances:
            value = self.distanceMm(link, obstacle)
            lines.append(f"{link} to {obstacle}: " + ("waiting for the first distance"
                                                      if value is None else f"{value:.1f} mm"))
        return "\n".join(lines)

    def motionLine(self) -> str:
        """The Motion section's status: the last solve, or the execution and its state."""
        line = self.motionStatus
        if self.execution is not None and self.motionStatus.startswith("Executing"):
            line = f"{self.motionStatus}: {self.execution.status}"
        distance = self.distanceLine()
        return f"{line}\n{distance}" if line and distance else line or distance

    def _onTargetMoved(self, caller: Any = None, event: Any = None) -> None:
        self._targetMoved = True  # solved at the next tick: drags come faster than frames

    def _onObstacleMoved(self, caller: Any = None, event: Any = None) -> None:
        if caller is not None:
            self._obstaclesMoved.add(caller.GetID())  # sent at the next tick

    def _onMotionTimer(self) -> None:
        moved, self._obstaclesMoved = self._obstaclesMoved, set()
        for nodeId in moved:
            entry = self._obstacles.get(nodeId)
            node = slicer.mrmlScene.GetNodeByID(nodeId)
            if entry is None or node is None:
                continue
            try:
                self.sendToROS(node, entry[1], entry[2], OBSTACLE_TYPE)
            except Exception as error:  # noqa: BLE001 - the others still go
                log.exception("sending the moved obstacle %s failed", entry[3])
                self.problems.append(f"The obstacle {entry[3]} was not sent again: {error}")
        if self._following is None or not self._targetMoved:
            return
        self._targetMoved = False
        try:
            self.solveIk(*self._following)
        except Exception as error:  # noqa: BLE001 - a failed solve must not stop the timer
            log.exception("solving for the moved target failed")
            self.motionStatus = f"Not solved: {error}"

    def jointSliders(self, robotName: str) -> list[JointSlider]:
        """One slider spec per actuated joint of a loaded robot (mimic joints follow)."""
        return joint_sliders(self._robot(robotName).joints(refresh=True)["joints"])

    def setJoints(self, robotName: str, sliders: Sequence[JointSlider],
                  values: Mapping[str, float]) -> dict[str, float]:
        """Publish the joint state the sliders say (display units: degrees, mm); the
        daemon checks the URDF limits and adds the mimic joints."""
        return self._robot(robotName).set_joints(slider_positions(sliders, values))

    def robotNames(self) -> list[str]:
        if self.client is None:
            return []
        return [r.name for r in self.client.resources() if isinstance(r, Robot)]

    def bridgeLines(self) -> list[str]:
        return describe_bridges(self.requireClient().list_bridges())

    def staleLines(self) -> list[str]:
        """This client's streams that the daemon says are stale, for the GUI: a frozen
        robot must not look live. The daemon pushes each change as a STATUS on the
        stream's device (no listing, no command)."""
        if self.client is None:
            return []
        return stale_lines(self.client.resources())

    def robotLines(self) -> list[str]:
        """Load progress and warnings of every robot, for the GUI (not only the log)."""
        if self.client is None:
            return []
        return robot_status_lines([r for r in self.client.resources()
                                   if isinstance(r, Robot)])

    # --- scene building -----------------------------------------------------------------
    def _onTimer(self) -> None:
        if self.transport is not None:
            self.transport.poll()
        self.updateScene()

    def _onNewDevice(self, caller: Any = None, event: Any = None) -> None:
        self._settledAt = None  # its content and attributes come after: scanned next tick

    def updateScene(self) -> None:
        """Place the connector's new nodes as the scene planner says. A tick scans the
        incoming nodes only while something may be unplaced (see `_settledAt`): at 50 Hz a
        scan of every node cost the main thread more than the nodes' messages."""
        if self.connector is None or self.connector.GetScene() is None:
            return
        robots = [r for r in self.client.resources() if isinstance(r, Robot)] \
            if self.client is not None else []
        now = (self.connector.GetNumberOfIncomingMRMLNodes(),
               sum(len(robot.links) for robot in robots),
               sum(b.GetNumberOfTransformNodes() for b in self._bundles.values()))
        if now != self._settledAt:
            self._settledAt = None
            if self._placeNew(robots):
                self._settledAt = now
        self._removeStaleMarkers()
        self._updateMarkerLabels()

    def _placeNew(self, robots: Sequence[Robot]) -> bool:
        """Place the nodes not placed yet; whether every one could be."""
        link_devices = {(robot.name, link.name): link.device for robot in robots
                        for link in robot.links.values() if link.device}
        placed = True
        for i in range(self.connector.GetNumberOfIncomingMRMLNodes()):
            node = self.connector.GetIncomingMRMLNode(i)
            if node is not None and node.IsA("vtkMRMLIGTLTrackingDataBundleNode"):
                self._bundles[node.GetID()] = node
                placed &= self._placeLinks(node, {d: key for key, d in link_devices.items()})
            if node is None or node.GetID() in self._planned:
                continue
            attributes = {n: node.GetAttribute(n) for n in node.GetAttributeNames()}
            metadata = metadata_from_attributes(attributes)
            if "ros2.role" not in metadata:
                # Attributes not there yet (look again next tick), or, still none a tick
                # later, a node that is not a bridge's (the heartbeat's): nothing to place.
                placed &= node.GetID() in self._roleless
                self._roleless.add(node.GetID())
                continue
            plan = plan_node(node.GetName(), metadata, rgba=self._rgba(node),
                             link_devices=link_devices)
            if plan.parent_device is not None and node.IsA("vtkMRMLTransformableNode"):
                parent = slicer.mrmlScene.GetFirstNode(plan.parent_device,
                                                       "vtkMRMLLinearTransformNode")
                if parent is None:
                    placed = False
                    continue  # its link transform has not arrived yet: next tick
                node.SetAndObserveTransformNodeID(parent.GetID())
            self._apply(node, plan)
            if self.transport is not None:
                self.transport.watch(node)
            if node.IsA("vtkMRMLTextNode") and metadata.get("ros2.role") == "marker":
                self._markerTexts[node.GetID()] = [node, -1]
            self._planned.add(node.GetID())
        return placed

    def _placeLinks(self, bundle: Any, links: Mapping[str, tuple[str, str]]) -> bool:
        """A robot's link nodes, which its connector makes from the elements of the robot's
        TDATA (more may come with later messages): each gets its link's attributes, name
        and folder, as the connector would give the node of a TRANSFORM. Whether every one
        of a robot this client loaded could be (another client's robot is not ours)."""
        poses = metadata_from_attributes(
            {n: bundle.GetAttribute(n) for n in bundle.GetAttributeNames()})
        robot = poses.get(KEY_ROBOT, "")
        ours = any(name == robot for name, _ in links.values())
        placed = True
        for j in range(bundle.GetNumberOfTransformNodes()):
            node = bundle.GetTransformNode(j)
            if node.GetID() in self._planned:
                continue
            named = links.get(node.GetName())
            if named is None:
                placed = not ours  # its link devices not known yet: next tick
                continue
            metadata = link_metadata(poses, *named)
            for key, value in metadata.items():
                node.SetAttribute(ATTRIBUTE_PREFIX + key, value)
            self._apply(node, plan_node(node.GetName(), metadata))
            self._planned.add(node.GetID())
        return placed

    @staticmethod
    def _rgba(node: Any) -> Optional[np.ndarray]:
        """The model's "RGBA" point array (the planner decides one colour or per point)."""
        if not node.IsA("vtkMRMLModelNode") or node.GetPolyData() is None:
            return None
        array = node.GetPolyData().GetPointData().GetArray(RGBA_ATTRIBUTE)
        if array is None or array.GetNumberOfTuples() == 0:
            return None
        return np.asarray(slicer.util.arrayFromModelPointData(node, RGBA_ATTRIBUTE))

    @staticmethod
    def _onPointsModified(node: Any, event: Any = None) -> None:
        """One vertex per point of a point-like model (scene_plan.is_point_like): the
        connector keeps the first point of the daemon's one polyvertex cell."""
        polydata = node.GetPolyData()
        if polydata is None or polydata.GetNumberOfVerts() in (0, polydata.GetNumberOfPoints()):
            return  # not drawn as vertices, or done
        from vtk.util.numpy_support import numpy_to_vtkIdTypeArray
        offsets, connectivity = vertex_per_point(polydata.GetNumberOfPoints())
        # In place: SetVerts would fire MeshModifiedEvent again, and the transport would
        # hand the client this message twice.
        polydata.GetVerts().SetData(numpy_to_vtkIdTypeArray(offsets, deep=True),
                                    numpy_to_vtkIdTypeArray(connectivity, deep=True))
        polydata.DeleteCells()  # its cell map, if built, held the one vertex

    def _apply(self, node: Any, plan: NodePlan) -> None:
        node.SetDescription(plan.display_name)  # node names stay = device names (see planner)
        if plan.colour is not None and node.IsA("vtkMRMLModelNode"):
            display = node.GetDisplayNode()
            if display is None:
                node.CreateDefaultDisplayNodes()
                display = node.GetDisplayNode()
            display.SetColor(*plan.colour)
            display.SetOpacity(plan.opacity)
            if plan.point_colours:  # the points' own colours, shown as they are (0..1)
                display.SetActiveScalar(RGBA_ATTRIBUTE, vtk.vtkAssignAttribute.POINT_DATA)
                display.SetScalarRangeFlagFromString("UseDirectMapping")
                display.SetScalarVisibility(True)
            else:
                display.SetScalarVisibility(False)
        if plan.point_like and node.IsA("vtkMRMLModelNode"):
            # The connector makes a new polydata for each message: redo it on each one.
            if not self.hasObserver(node, slicer.vtkMRMLModelNode.MeshModifiedEvent,
                                    self._onPointsModified):
                self.addObserver(node, slicer.vtkMRMLModelNode.MeshModifiedEvent,
                                 self._onPointsModified)
            self._onPointsModified(node)
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
            else:  # no plugin made its item (Slicer's Qt plugins do, its core does not)
                sh.CreateItem(folder, node)

    # --- saving -------------------------------------------------------------------------
    def _saveState(self) -> None:
        if self.client is not None:
            self.getParameterNode().bridgeState = self.client.state().to_json()

    def _onSave(self, caller: Any = None, event: Any = None) -> None:
        self._saveState()

    def _onSceneStartClose(self, caller: Any = None, event: Any = None) -> None:
        # The connector node leaves the scene; no timer would process it any more.
        self.disconnect()
        self.connector = None
        self._planned.clear()
        self._bundles.clear()
        self._markerTexts.clear()
        self._roleless.clear()
        self._settledAt = None



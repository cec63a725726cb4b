"""ROS2Bridge: 3D Slicer module for the slicer-ros2-bridge daemon (no Slicer build needed).

Laid out as Slicer's scripted-module template (Utilities/Templates/Modules/Scripted): this
file holds the module, its widget (wiring only: the GUI is Resources/UI/ROS2Bridge.ui) and
its self-test; the code is in ROS2BridgeLib/ beside it (`logic`: ROS2BridgeLogic, what
scripts use; `transport`: ConnectorTransport; `parameters`: the parameter node;
`reference`: SlicerROS2's entry points; `scene_nodes`: its nodes as MRML nodes). Slicer puts
this folder on sys.path when it loads the module, so ROS2BridgeLib is found; the names
scripts and tests use are re-exported here.

Install (Slicer 5.4 or newer: the parameter node wrapper used here first shipped in 5.4;
it needs the SlicerOpenIGTLink extension). The module imports the client packages
`protocol` and `slicer_client`, and does not look for them itself:
- as the SlicerROS2Bridge extension (the repository's CMakeLists.txt), both are installed
  beside this file, on Slicer's path; nothing else to do;
- from a clone: build the client wheel (`python3 tools/build_client_wheel.py`, or `make
  client-wheel`), install it into Slicer's Python (console:
  `slicer.util.pip_install("<clone>/dist/slicer_ros2_bridge_client-0.1.0-py3-none-any.whl")`),
  then add this folder (slicer_client/slicer_module/ROS2Bridge) to Edit > Application
  Settings > Modules > Additional module paths and restart Slicer. Without the packages the
  module does not load, and its ImportError names these commands.

Transport: Slicer's own OpenIGTLinkIF connector node (client mode). Commands go through
`vtkSlicerOpenIGTLinkCommand`; what arrives becomes MRML nodes made by the connector; this
module only parents, colours and files them as the scene planner (slicer_client/scene_plan.py)
says.

The reference SlicerROS2's API: where SlicerROS2 itself is not installed, this module
answers its entry points (slicer_client/reference/entry_points.py), so a script written for
it runs with no line changed: `slicer.util.getModuleLogic('ROS2')` gives the logic
(`Spin()`, `GetDefaultROS2Node()`...; used before Connect, it connects to the host and port
of this module's settings), and `slicer.mrmlScene.AddNewNodeByClass("vtkMRMLROS2NodeNode")`
a ROS node. Its nodes are MRML nodes of the scene (ROS2BridgeLib/scene_nodes.py: the
reference's IDs and names, VTK's observers, saved with the scene and made again once the
module is connected). `slicer.util.getModuleLogic('ROS2Bridge')` offers the same methods.
Observers and callbacks run on Slicer's main thread, in this module's 20 ms spin (the
reference's 50 Hz timer), never while a command waits; a script's own `Spin()` takes in what
the connector received.

Verified against (every Slicer/MRML/VTK call in this folder was read in these sources; the
list with the facts relied on is in slicer_client/README.md, "Verified against"):
- openigtlink/SlicerOpenIGTLink d090ca4 (2025-11-13): OpenIGTLinkIF/MRML/
  vtkMRMLIGTLConnectorNode.{h,cxx}, vtkSlicerOpenIGTLinkCommand.{h,cxx},
  OpenIGTLinkIF/Logic/vtkSlicerOpenIGTLinkIFLogic.cxx, qSlicerOpenIGTLinkIFModule.cxx,
  GenericSerialDeviceRemoteControl.py (Python use of commands);
- IGSIO/OpenIGTLinkIO d7f6aef (2025-07-18): Logic/igtlioConnector.cxx, Logic/igtlioCommand.{h,cxx},
  Converter/igtlioStringConverter.cxx, Converter/igtlioPolyDataConverter.cxx;
- Slicer/Slicer 583e9b3 (main) and tags v5.2.0/v5.4.0: Base/Python/slicer/ScriptedLoadableModule.py
  (resourcePath, runTest's `<Module>Test` lookup), util.py (loadUI, childWidgetVariables,
  findChildren, pip_install), parameterNodeWrapper/{wrapper,guiConnectors,validators}.py
  (connectGui and the SlicerParameterName property), Utilities/Templates/Modules/Scripted/
  {TemplateKey.py,Resources/UI/TemplateKey.ui,CMakeLists.txt},
  CMake/SlicerMacroBuildScriptedModule.cmake, Modules/Scripted/ExtensionWizard/CMakeLists.txt
  (a `<Module>Lib` package in SCRIPTS), Base/QTGUI/qSlicerScriptedLoadableModuleFactory.cxx
  (the module's folder appended to sys.path), Libs/MRML/Widgets/qMRMLWidget.h,
  qMRMLNodeComboBox.h, Libs/MRML/Core/vtkMRMLScene.{h,cxx}, vtkMRMLNode.h,
  vtkMRMLTextNode.{h,cxx}, vtkMRMLTransformNode.cxx, vtkMRMLTransformableNode.h,
  vtkMRMLDisplayNode.h, vtkMRMLDisplayableNode.h, vtkMRMLSubjectHierarchyNode.h.
Not verifiable here: anything at run time (Slicer cannot run on the build machine), the
PythonQt/VTK wrapping of each overload (assumed from the public headers and from the
SlicerOpenIGTLink Python modules that make the same calls).
"""

import json
import os
import time
from typing import Any, Optional

import ctk
import qt
import slicer
from slicer.ScriptedLoadableModule import (ScriptedLoadableModule, ScriptedLoadableModuleTest,
                                           ScriptedLoadableModuleWidget)
from slicer.util import VTKObservationMixin

# ROS2BridgeLib first: it says what to install when the client packages are missing.
from ROS2BridgeLib.logic import ROS2BridgeLogic, nodeKind, playback_line
from ROS2BridgeLib.parameters import DEFAULT_FRAME, ROS2BridgeParameterNode
from ROS2BridgeLib.reference import installReferenceEntryPoints
from ROS2BridgeLib.transport import ConnectorTransport
from protocol import commands as c
from slicer_client.bridge_state import BridgeState
from slicer_client.connection import CommandTimeoutError
from slicer_client.joint_sliders import JointSlider
from slicer_client.scene_plan import ROBOTS_FOLDER, metadata_from_attributes, plan_node
from slicer_client.send_plan import SEND_TYPES

# The names scripts and tests take from this module, wherever they are defined.
__all__ = ["DEFAULT_FRAME", "ConnectorTransport", "ROS2Bridge", "ROS2BridgeLogic",
           "ROS2BridgeParameterNode", "ROS2BridgeTest", "ROS2BridgeWidget", "nodeKind"]

STATUS_INTERVAL_MS = 500  # how often the widget's status lines are refreshed


class ROS2Bridge(ScriptedLoadableModule):
    def __init__(self, parent: Any) -> None:
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
        slicer.app.connect("startupCompleted()", installReferenceEntryPoints)


class ROS2BridgeWidget(ScriptedLoadableModuleWidget, VTKObservationMixin):
    """The GUI (Resources/UI/ROS2Bridge.ui) wired to ROS2BridgeLogic; the parameter node
    keeps the fields whose .ui widgets carry a SlicerParameterName."""

    logic: ROS2BridgeLogic  # made in setup(); slicer.util.getModuleLogic reads it

    def __init__(self, parent: Any = None) -> None:
        ScriptedLoadableModuleWidget.__init__(self, parent)
        VTKObservationMixin.__init__(self)
        self.ui: Any = None  # the .ui's named widgets, as attributes
        self._parameterNode: Optional[ROS2BridgeParameterNode] = None
        self._parameterNodeGuiTag: Optional[int] = None
        self._sliders: list[JointSlider] = []  # JointSlider specs of the robot shown
        self._sliderWidgets: dict[str, Any] = {}  # joint name -> ctkSliderWidget
        self._slidersRobot = ""

    def setup(self) -> None:
        ScriptedLoadableModuleWidget.setup(self)
        uiWidget = slicer.util.loadUI(self.resourcePath("UI/ROS2Bridge.ui"))
        self.layout.addWidget(uiWidget)
        self.ui = slicer.util.childWidgetVariables(uiWidget)
        # The .ui passes the scene on to its MRML widgets (mrmlSceneChanged -> setMRMLScene).
        uiWidget.setMRMLScene(slicer.mrmlScene)
        self.logic = ROS2BridgeLogic()

        ui = self.ui
        for button, signal, handler in (
                (ui.connectButton, "toggled(bool)", self.onConnectToggled),
                (ui.loadRobotButton, "clicked(bool)", self.onLoadRobot),
                (ui.anotherRobotButton, "clicked(bool)", self.onAnotherRobot),
                (ui.removeRobotButton, "clicked(bool)", self.onRemoveRobot),
                (ui.refreshButton, "clicked(bool)", self.onRefresh),
                (ui.addMarkersButton, "clicked(bool)", self.onAddMarkers),
                (ui.removeMarkersButton, "clicked(bool)", self.onRemoveMarkers),
                (ui.sendNodeSelector, "currentNodeChanged(vtkMRMLNode*)", self.onSendNodeChanged),
                (ui.sendButton, "clicked(bool)", self.onSend),
                (ui.showJointsButton, "clicked(bool)", self.onShowJoints),
                (ui.recordButton, "toggled(bool)", self.onRecordToggled),
                (ui.motionSolveButton, "clicked(bool)", self.onSolveIk),
                (ui.motionFollowCheckBox, "toggled(bool)", self.onFollowToggled),
                (ui.motionPathButton, "clicked(bool)", self.onPreviewPath),
                (ui.motionExecuteButton, "clicked(bool)", self.onExecuteMotion),
                (ui.addObstacleButton, "clicked(bool)", self.onAddObstacle),
                (ui.watchDistanceButton, "clicked(bool)", self.onWatchDistance),
                (ui.playbackPauseButton, "toggled(bool)", self.onPauseToggled),
                (ui.seekButton, "clicked(bool)", self.onSeek),
                (ui.rateButton, "clicked(bool)", self.onSetRate),
                (ui.toSequencesButton, "clicked(bool)", self.onBagToSequences)):
            button.connect(signal, handler)
        self.addObserver(slicer.mrmlScene, slicer.mrmlScene.StartCloseEvent,
                         self.onSceneStartClose)
        self.addObserver(slicer.mrmlScene, slicer.mrmlScene.EndCloseEvent, self.onSceneEndClose)
        self.initializeParameterNode()
        self._statusTimer = qt.QTimer()
        self._statusTimer.setInterval(STATUS_INTERVAL_MS)
        self._statusTimer.connect("timeout()", self.updateStatus)
        self._statusTimer.start()

    def cleanup(self) -> None:
        self.removeObservers()
        if hasattr(self, "_statusTimer"):  # setup() may have failed before making it
            self._statusTimer.stop()
        self.setParameterNode(None)
        if hasattr(self, "logic"):
            self.logic.cleanup()

    def enter(self) -> None:
        self.initializeParameterNode()

    def onSceneStartClose(self, caller: Any, event: Any) -> None:
        self.setParameterNode(None)

    def onSceneEndClose(self, caller: Any, event: Any) -> None:
        if self.parent.isEntered:
            self.initializeParameterNode()

    def initializeParameterNode(self) -> None:
        self.setParameterNode(self.logic.getParameterNode())

    def setParameterNode(self, parameterNode: Optional[ROS2BridgeParameterNode]) -> None:
        if self._parameterNode is not None and self._parameterNodeGuiTag is not None:
            self._parameterNode.disconnectGui(self._parameterNodeGuiTag)
            self._parameterNodeGuiTag = None
        self._parameterNode = parameterNode
        if self._parameterNode is not None:
            # The .ui's widgets name their parameter in a "SlicerParameterName" property.
            self._parameterNodeGuiTag = self._parameterNode.connectGui(self.ui)

    def _parameters(self) -> ROS2BridgeParameterNode:
        """The parameter node the GUI shows (the scene's one, made if a close dropped it)."""
        if self._parameterNode is None:
            self.initializeParameterNode()
        assert self._parameterNode is not None
        return self._parameterNode

    def updateStatus(self) -> None:
        logic, ui = self.logic, self.ui
        if logic.isConnected():
            info = logic.client.daemon_info if logic.client else {}
            ui.statusLabel.text = (f"Connected to {info.get('node', 'the daemon')} "
                                   f"({logic.transport.address})"
                                   if logic.transport else "Connected")
        elif logic.isLinkSilent():
            ui.statusLabel.text = ("LINK LOST: no heartbeat from the daemon; what is shown "
                                   "is not live (waiting for the link to come back)")
        elif logic.isActive():
            ui.statusLabel.text = "Waiting for the daemon (retrying)..."
        else:
            ui.statusLabel.text = "Not connected"
        ui.robotStatusLabel.text = "\n".join(logic.robotLines())
        ui.problemsLabel.text = "\n".join(logic.problems[-5:])
        ui.staleLabel.text = "\n".join(logic.staleLines())
        ui.recordLabel.text = logic.recordingLine()
        recording = logic.recording is not None and logic.recording.running
        if ui.recordButton.checked != recording:  # stopped by another client, a full disk
            wasBlocked = ui.recordButton.blockSignals(True)
            ui.recordButton.checked = recording
            ui.recordButton.blockSignals(wasBlocked)
        ui.motionStatusLabel.text = logic.motionLine()  # a followed target's newest solve
        active = logic.isActive()
        if ui.connectButton.checked != active:  # e.g. after a scene close
            wasBlocked = ui.connectButton.blockSignals(True)
            ui.connectButton.checked = active
            ui.connectButton.blockSignals(wasBlocked)

    def onConnectToggled(self, on: bool) -> None:
        with slicer.util.tryWithErrorDisplay("Failed to (dis)connect.", waitCursor=True):
            if on:
                p = self._parameters()
                self.logic.connect(p.host, p.port, p.keyFile)
            else:
                self.logic.disconnect()
            self.updateStatus()

    def onLoadRobot(self) -> None:
        with slicer.util.tryWithErrorDisplay("Failed to load the robot.", waitCursor=True):
            p = self._parameters()
            self.logic.loadRobot(p.robotName, p.robotNode, p.robotParameter)
            self._refreshRobots()

    def onAnotherRobot(self) -> None:
        with slicer.util.tryWithErrorDisplay("Failed to prepare another robot."):
            names = set(self.logic.robotNames())
            index = 2
            while f"robot{index}" in names:
                index += 1
            self._parameters().robotName = f"robot{index}"

    def onRemoveRobot(self) -> None:
        with slicer.util.tryWithErrorDisplay("Failed to remove the robot.", waitCursor=True):
            name = self.ui.robotCombo.currentText
            if name:
                self.logic.removeRobot(name)
            self._refreshRobots()

    def onAddMarkers(self) -> None:
        with slicer.util.tryWithErrorDisplay("Failed to show the markers.", waitCursor=True):
            self.logic.addMarkers(self.ui.markerTopicEdit.text,
                                  self.ui.markerTypeCombo.currentText,
                                  self.ui.markerFrameEdit.text)
            self.onRefresh()

    def onRemoveMarkers(self) -> None:
        with slicer.util.tryWithErrorDisplay("Failed to remove the markers.", waitCursor=True):
            self.logic.removeMarkers(self.ui.markerTopicEdit.text)
            self.onRefresh()

    def onRefresh(self) -> None:
        with slicer.util.tryWithErrorDisplay("Failed to list the bridges."):
            self.ui.bridgeList.clear()
            for line in self.logic.bridgeLines():
                self.ui.bridgeList.addItem(line)

    def onSendNodeChanged(self, node: Any) -> None:
        self.ui.sendTypeCombo.clear()
        if node is not None:
            for rosType in SEND_TYPES.get(nodeKind(node), ()):
                self.ui.sendTypeCombo.addItem(rosType)

    def onSend(self) -> None:
        with slicer.util.tryWithErrorDisplay("Failed to send to ROS.", waitCursor=True):
            self.logic.sendToROS(self.ui.sendNodeSelector.currentNode(),
                                 self.ui.sendTopicEdit.text, self.ui.sendFrameEdit.text,
                                 self.ui.sendTypeCombo.currentText)
            self.onRefresh()

    def onShowJoints(self) -> None:
        with slicer.util.tryWithErrorDisplay("Failed to read the robot's joints.",
                                             waitCursor=True):
            name = self.ui.robotCombo.currentText
            sliders = self.logic.jointSliders(name)
            form = self.ui.jointsWidget.layout()  # the .ui's (empty) jointsFormLayout
            while form.rowCount() > 0:
                form.removeRow(0)
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
                form.addRow(spec.name + ":", widget)

    def onRecordToggled(self, on: bool) -> None:
        with slicer.util.tryWithErrorDisplay("Failed to start or stop the recording.",
                                             waitCursor=True):
            if on:
                self.logic.startRecording(self._parameters().recordPath)
            else:
                self.logic.stopRecording()
        self.updateStatus()

    def onSliderMoved(self, _value: float) -> None:
        with slicer.util.tryWithErrorDisplay("Failed to move the robot."):
            values = {name: float(widget.value) for name, widget in self._sliderWidgets.items()}
            self.logic.setJoints(self._slidersRobot, self._sliders, values)

    def onSolveIk(self) -> None:
        with slicer.util.tryWithErrorDisplay("Failed to solve for the target.",
                                             waitCursor=True):
            self.logic.solveIk(self.ui.robotCombo.currentText,
                               self.ui.motionTargetSelector.currentNode(),
                               self.ui.motionTipEdit.text.strip())
        self.ui.motionStatusLabel.text = self.logic.motionStatus

    def onFollowToggled(self, on: bool) -> None:
        if not on:
            self.logic.stopFollowing()
            return
        with slicer.util.tryWithErrorDisplay("Failed to follow the target."):
            try:
                self.logic.followTarget(self.ui.robotCombo.currentText,
                                        self.ui.motionTargetSelector.currentNode(),
                                        self.ui.motionTipEdit.text.strip())
            except Exception:
                self.ui.motionFollowCheckBox.checked = False
                raise
        self.ui.motionStatusLabel.text = self.logic.motionStatus

    def onPreviewPath(self) -> None:
        with slicer.util.tryWithErrorDisplay("Failed to plan the path.", waitCursor=True):
            self.logic.previewPath(self.ui.robotCombo.currentText)
        self.ui.motionStatusLabel.text = self.logic.motionStatus

    def onExecuteMotion(self) -> None:
        with slicer.util.tryWithErrorDisplay("Failed to execute the motion.", waitCursor=True):
            self.logic.executeMotion(self.ui.robotCombo.currentText)
        self.ui.motionStatusLabel.text = self.logic.motionStatus

    def onAddObstacle(self) -> None:
        with slicer.util.tryWithErrorDisplay("Failed to make the model an obstacle.",
                                             waitCursor=True):
            name = self.logic.addObstacle(self.ui.robotCombo.currentText,
                                          self.ui.obstacleSelector.currentNode(),
                                          self.ui.obstacleFrameEdit.text.strip())
            self.ui.motionStatusLabel.text = f"Obstacle {name} added"

    def onWatchDistance(self) -> None:
        with slicer.util.tryWithErrorDisplay("Failed to stream the distance.",
                                             waitCursor=True):
            self.logic.watchDistances(self.ui.robotCombo.currentText,
                                      self.ui.motionTipEdit.text.strip())

    def onPauseToggled(self, on: bool) -> None:
        with slicer.util.tryWithErrorDisplay("Failed to pause or resume the bag."):
            status = self.logic.pausePlayback() if on else self.logic.resumePlayback()
            self.ui.playbackLabel.text = playback_line(status)

    def onSeek(self) -> None:
        with slicer.util.tryWithErrorDisplay("Failed to seek the bag.", waitCursor=True):
            self.ui.playbackLabel.text = playback_line(
                self.logic.seekPlayback(float(self.ui.seekSpin.value)))

    def onSetRate(self) -> None:
        with slicer.util.tryWithErrorDisplay("Failed to set the bag's rate."):
            self.ui.playbackLabel.text = playback_line(
                self.logic.setPlaybackRate(float(self.ui.rateSpin.value)))

    def onBagToSequences(self) -> None:
        with slicer.util.tryWithErrorDisplay("Failed to make the bag sequences.",
                                             waitCursor=True):
            browser = self.logic.bagToSequences(step=float(self.ui.sequenceStepSpin.value))
            self.ui.playbackLabel.text = f"Sequences made: browse {browser.GetName()}"

    def _refreshRobots(self) -> None:
        self.ui.robotCombo.clear()
        for name in self.logic.robotNames():
            self.ui.robotCombo.addItem(name)
        self.onRefresh()


class ROS2BridgeTest(ScriptedLoadableModuleTest):
    """Runs inside 3D Slicer (see slicer_client/slicer_module/selftest.py). The daemon part
    needs a daemon: set ROS2BRIDGE_TEST_PORT to its port, else that part is skipped."""

    def setUp(self) -> None:
        slicer.mrmlScene.Clear(0)

    def runTest(self) -> None:
        self.setUp()
        self.test_scene_placement()
        self.setUp()
        self.test_daemon_round_trip()

    def test_scene_placement(self) -> None:
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

    def test_daemon_round_trip(self) -> None:
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
            transport, client = logic.transport, logic.client
            assert transport is not None and client is not None  # connected, checked above
            deadline = time.monotonic() + 10.0
            while transport.heartbeats < 2 and time.monotonic() < deadline:
                slicer.app.processEvents()
                transport.poll()
                time.sleep(0.05)
            self.assertGreaterEqual(transport.heartbeats, 2)
            self.assertTrue(logic.isConnected() and not logic.isLinkSilent())
            self.assertIn("subscriber: /selftest_string [std_msgs/msg/String] as "
                          "selftest_string", logic.bridgeLines())
            state = json.loads(BridgeState.from_json(client.state().to_json()).to_json())
            self.assertEqual(len(state["bridges"]), 2)
            try:
                client.request(c.ListBridges(), timeout=5.0)
            except CommandTimeoutError:
                self.fail("list_bridges through the connector timed out")
        finally:
            logic.cleanup()
        self.delayDisplay("Daemon round trip passed")

"""ROS2Bridge: 3D Slicer module for the slicer-ros2-bridge daemon (no Slicer build needed).

Install: add this folder (slicer_client/slicer_module/ROS2Bridge) to Edit > Application
Settings > Modules > Additional module paths and restart Slicer. The repository root is
put on sys.path from this file's location, so `protocol` and `slicer_client` are found
in a clone with nothing else to install.

Transport: Slicer's own OpenIGTLinkIF connector node (client mode). Commands go through
`vtkSlicerOpenIGTLinkCommand`; what arrives becomes MRML nodes made by the connector; this
module only parents, colours and files them as the scene planner (slicer_client/scene_plan.py)
says. The reference CamelCase API is
`slicer.util.getModuleLogic('ROS2Bridge').GetDefaultROS2Node()`.
"""

import json
import os
import sys

_REPO_ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..", ".."))
if _REPO_ROOT not in sys.path:
    sys.path.insert(0, _REPO_ROOT)

import numpy as np  # noqa: E402
import qt  # noqa: E402
import slicer  # noqa: E402
import vtk  # noqa: E402
from slicer.ScriptedLoadableModule import (ScriptedLoadableModule,  # noqa: E402
                                           ScriptedLoadableModuleLogic,
                                           ScriptedLoadableModuleTest,
                                           ScriptedLoadableModuleWidget)
from slicer.parameterNodeWrapper import parameterNodeWrapper  # noqa: E402
from slicer.util import VTKObservationMixin  # noqa: E402

from protocol.messages import String, Transform  # noqa: E402
from slicer_client.bridge_state import BridgeState  # noqa: E402
from slicer_client.client import Client  # noqa: E402
from slicer_client.connection import CommandTimeoutError  # noqa: E402
from slicer_client.connector_codec import build_command, message_from_node, parse_reply  # noqa: E402
from slicer_client.scene_plan import (ROBOTS_FOLDER, describe_bridges,  # noqa: E402
                                      metadata_from_attributes, plan_node)

CONNECTOR_NAME = "ROS2BridgeConnector"


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


@parameterNodeWrapper
class ROS2BridgeParameterNode:
    """GUI state and the saved bridges (bridgeState: slicer_client BridgeState JSON)."""

    host: str = "127.0.0.1"
    port: int = 18944
    robotName: str = "robot"
    robotNode: str = "/robot_state_publisher"
    robotParameter: str = "robot_description"
    bridgeState: str = ""


class ConnectorTransport:
    """slicer_client's Transport over an OpenIGTLinkIF connector node (see transport.py).
    Commands block the GUI thread (Slicer keeps receiving meanwhile); received data comes
    from the connector's nodes, observed here and handed to the client as Messages."""

    def __init__(self, connector):
        self.connector = connector
        self.address = f"{connector.GetServerHostname()}:{connector.GetServerPort()}"
        self._listener = None
        self._node_observers = {}  # node id -> (node, tag)
        self._connector_tags = []
        self._first = True

    @property
    def connected(self):
        return self.connector.GetState() == slicer.vtkMRMLIGTLConnectorNode.StateConnected

    def set_listener(self, listener):
        self._listener = listener
        for event, handler in ((slicer.vtkMRMLIGTLConnectorNode.ConnectedEvent, self._up),
                               (slicer.vtkMRMLIGTLConnectorNode.DisconnectedEvent, self._down)):
            self._connector_tags.append(self.connector.AddObserver(event, handler))
        if self.connected:
            self._up()

    def _up(self, caller=None, event=None):
        first, self._first = self._first, False
        self._listener.on_connected(self.command, first)

    def _down(self, caller=None, event=None):
        self._listener.on_disconnected("the connector lost the daemon (it retries itself)")

    def command(self, op, arguments=None, *, timeout=5.0):
        name, text = build_command(op, arguments)
        cmd = slicer.vtkSlicerOpenIGTLinkCommand()
        cmd.SetName(name)
        cmd.SetCommandContent(text)
        cmd.SetBlocking(True)  # the connector processes incoming data while it waits
        cmd.SetTimeoutSec(timeout)
        self.connector.SendCommand(cmd)
        expired = getattr(slicer.vtkSlicerOpenIGTLinkCommand, "CommandExpired", None)
        error_message = getattr(cmd, "GetErrorMessage", lambda: "")()
        return parse_reply(op, cmd.GetResponseContent() or "",
                           expired=expired is not None and cmd.GetStatus() == expired,
                           timeout=timeout, error_message=error_message or "")

    def send(self, message):
        """Push a TRANSFORM or STRING under its device name through an outgoing node."""
        body = message.body
        if isinstance(body, Transform):
            node = self._outgoing("vtkMRMLLinearTransformNode", message.device_name)
            matrix = vtk.vtkMatrix4x4()
            for i in range(4):
                for j in range(4):
                    matrix.SetElement(i, j, float(body.matrix[i, j]))
            node.SetMatrixTransformToParent(matrix)
        elif isinstance(body, String):
            node = self._outgoing("vtkMRMLTextNode", message.device_name)
            node.SetText(body.text)
        else:
            raise TypeError(f"the connector transport sends TRANSFORM and STRING, not "
                            f"{message.type_name}")
        self.connector.PushNode(node)

    def _outgoing(self, class_name, device):
        node = slicer.mrmlScene.GetFirstNode(device, class_name)
        if node is None:
            node = slicer.mrmlScene.AddNewNodeByClass(class_name, device)
            self.connector.RegisterOutgoingMRMLNode(node)
        return node

    def watch(self, node):
        """Forward a connector node's updates to the client as Messages."""
        if node.GetID() in self._node_observers:
            return
        event = (slicer.vtkMRMLTransformNode.TransformModifiedEvent
                 if node.IsA("vtkMRMLTransformNode") else vtk.vtkCommand.ModifiedEvent)
        tag = node.AddObserver(event, lambda caller, _event: self._forward(caller))
        self._node_observers[node.GetID()] = (node, tag)
        self._forward(node)

    def _forward(self, node):
        attributes = {name: node.GetAttribute(name) for name in node.GetAttributeNames()}
        if node.IsA("vtkMRMLLinearTransformNode"):
            matrix = vtk.vtkMatrix4x4()
            node.GetMatrixTransformToParent(matrix)
            values = [[matrix.GetElement(i, j) for j in range(4)] for i in range(4)]
            message = message_from_node(node.GetName(), attributes, matrix=values)
        elif node.IsA("vtkMRMLTextNode"):
            message = message_from_node(node.GetName(), attributes, text=node.GetText())
        else:
            return
        if message is not None and self._listener is not None:
            self._listener.on_message(message)

    def close(self):
        for tag in self._connector_tags:
            self.connector.RemoveObserver(tag)
        for node, tag in self._node_observers.values():
            node.RemoveObserver(tag)
        self._node_observers.clear()


class ROS2BridgeLogic(ScriptedLoadableModuleLogic, VTKObservationMixin):
    """All networking: the connector, the slicer_client Client bound to it, the scene
    builder and the saved bridges."""

    def __init__(self):
        ScriptedLoadableModuleLogic.__init__(self)
        VTKObservationMixin.__init__(self)
        self.connector = None
        self.transport = None
        self.client = None
        self._planned = set()  # node ids already placed
        self._timer = qt.QTimer()
        self._timer.setInterval(200)  # new connector nodes are placed within 0.2 s
        self._timer.connect("timeout()", self.updateScene)
        self.addObserver(slicer.mrmlScene, slicer.mrmlScene.StartSaveEvent, self._onSave)

    def getParameterNode(self):
        return ROS2BridgeParameterNode(super().getParameterNode())

    # --- connection ---------------------------------------------------------------------
    def connect(self, host, port):
        if self.connector is None:
            self.connector = slicer.mrmlScene.GetFirstNode(CONNECTOR_NAME,
                                                           "vtkMRMLIGTLConnectorNode")
        if self.connector is None:
            self.connector = slicer.mrmlScene.AddNewNodeByClass("vtkMRMLIGTLConnectorNode",
                                                                CONNECTOR_NAME)
        self.connector.Stop()
        self.connector.SetTypeClient(host, int(port))
        self.connector.Start()
        self.addObserver(self.connector, slicer.vtkMRMLIGTLConnectorNode.ConnectedEvent,
                         self._onConnected)
        self._timer.start()
        if self.isConnected():
            self._onConnected()

    def disconnect(self):
        self._timer.stop()
        if self.connector is not None:
            self.removeObservers(self._onConnected)
            self.connector.Stop()
        if self.transport is not None:
            self.transport.close()
        self.transport = None
        self.client = None

    def isConnected(self):
        return (self.connector is not None and self.connector.GetState()
                == slicer.vtkMRMLIGTLConnectorNode.StateConnected)

    def _onConnected(self, caller=None, event=None):
        if self.client is not None:
            return  # the transport re-syncs the existing client itself
        self.transport = ConnectorTransport(self.connector)
        self.client = Client(self.transport)
        saved = self.getParameterNode().bridgeState
        if saved:
            self.client.restore(BridgeState.from_json(saved))

    def requireClient(self):
        if self.client is None:
            raise RuntimeError("not connected to the slicer-ros2-bridge daemon: press Connect "
                               "(and start the daemon with `slicer-ros2-bridge run`)")
        return self.client

    def GetDefaultROS2Node(self):  # noqa: N802 - the reference's name
        return self.requireClient().GetDefaultROS2Node()

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
            if node.GetAttribute("OpenIGTLink.ros2.robot") == name:
                slicer.mrmlScene.RemoveNode(node)
        sh = slicer.vtkMRMLSubjectHierarchyNode.GetSubjectHierarchyNode(slicer.mrmlScene)
        folder = sh.GetItemByName(f"robot {name}")
        if folder:
            sh.RemoveItem(folder)
        self._saveState()

    def robotNames(self):
        if self.client is None:
            return []
        return [r.name for r in self.client.resources() if r.spec.op == "create_robot"]

    def bridgeLines(self):
        return describe_bridges(self.requireClient().list_bridges())

    # --- scene building -----------------------------------------------------------------
    def updateScene(self):
        """Place the connector's new nodes as the scene planner says."""
        if self.connector is None:
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
            if plan.parent_device is not None:
                parent = slicer.mrmlScene.GetFirstNode(plan.parent_device,
                                                       "vtkMRMLLinearTransformNode")
                if parent is None:
                    continue  # its link transform has not arrived yet: next tick
                node.SetAndObserveTransformNodeID(parent.GetID())
            self._apply(node, plan)
            if self.transport is not None:
                self.transport.watch(node)
            self._planned.add(node.GetID())

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
            display.SetScalarVisibility(False)
        if plan.folder:
            sh = slicer.vtkMRMLSubjectHierarchyNode.GetSubjectHierarchyNode(slicer.mrmlScene)
            top = sh.GetItemByName(ROBOTS_FOLDER) if plan.kind.startswith("robot") else None
            if plan.kind.startswith("robot") and not top:
                top = sh.CreateFolderItem(sh.GetSceneItemID(), ROBOTS_FOLDER)
            parent = top or sh.GetSceneItemID()
            folder = sh.GetItemChildWithName(parent, plan.folder)
            if not folder:
                folder = sh.CreateFolderItem(parent, plan.folder)
            sh.SetItemParent(sh.GetItemByDataNode(node), folder)

    # --- saving -------------------------------------------------------------------------
    def _saveState(self):
        if self.client is not None:
            self.getParameterNode().bridgeState = self.client.state().to_json()

    def _onSave(self, caller=None, event=None):
        self._saveState()


class ROS2BridgeWidget(ScriptedLoadableModuleWidget, VTKObservationMixin):
    def __init__(self, parent=None):
        ScriptedLoadableModuleWidget.__init__(self, parent)
        VTKObservationMixin.__init__(self)
        self.logic = None
        self._parameterNode = None

    def setup(self):
        ScriptedLoadableModuleWidget.setup(self)
        self.logic = ROS2BridgeLogic()
        form = qt.QFormLayout()
        box = qt.QWidget()
        box.setLayout(form)
        self.layout.addWidget(box)

        self.hostEdit = qt.QLineEdit()
        self.portSpin = qt.QSpinBox()
        self.portSpin.setRange(1, 65535)
        self.connectButton = qt.QPushButton("Connect")
        self.connectButton.checkable = True
        self.statusLabel = qt.QLabel("Not connected")
        form.addRow("Host:", self.hostEdit)
        form.addRow("Port:", self.portSpin)
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

        self.bridgeList = qt.QListWidget()
        self.refreshButton = qt.QPushButton("Refresh bridges")
        form.addRow("Active bridges:", self.bridgeList)
        form.addRow(self.refreshButton)
        self.layout.addStretch(1)

        self.connectButton.connect("toggled(bool)", self.onConnectToggled)
        self.loadRobotButton.connect("clicked(bool)", self.onLoadRobot)
        self.anotherRobotButton.connect("clicked(bool)", self.onAnotherRobot)
        self.removeRobotButton.connect("clicked(bool)", self.onRemoveRobot)
        self.refreshButton.connect("clicked(bool)", self.onRefresh)
        self.addObserver(slicer.mrmlScene, slicer.mrmlScene.EndCloseEvent, self.onSceneEndClose)
        self.initializeParameterNode()
        self._statusTimer = qt.QTimer()
        self._statusTimer.setInterval(500)
        self._statusTimer.connect("timeout()", self.updateStatus)
        self._statusTimer.start()

    def cleanup(self):
        self.removeObservers()
        self._statusTimer.stop()

    def onSceneEndClose(self, caller, event):
        if self.parent.isEntered:
            self.initializeParameterNode()

    def initializeParameterNode(self):
        self._parameterNode = self.logic.getParameterNode()
        self._parameterNode.connectGui({
            "host": self.hostEdit, "port": self.portSpin, "robotName": self.robotNameEdit,
            "robotNode": self.robotNodeEdit, "robotParameter": self.robotParameterEdit})

    def updateStatus(self):
        if self.logic.isConnected():
            info = self.logic.client.daemon_info if self.logic.client else {}
            self.statusLabel.text = (f"Connected to {info.get('node', 'the daemon')} "
                                     f"({self.logic.transport.address})"
                                     if self.logic.transport else "Connected")
        elif self.logic.connector is not None:
            self.statusLabel.text = "Waiting for the daemon (retrying)..."
        else:
            self.statusLabel.text = "Not connected"

    def onConnectToggled(self, on):
        with slicer.util.tryWithErrorDisplay("Failed to (dis)connect.", waitCursor=True):
            if on:
                self.logic.connect(self._parameterNode.host, self._parameterNode.port)
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

    def onRefresh(self):
        with slicer.util.tryWithErrorDisplay("Failed to list the bridges."):
            self.bridgeList.clear()
            for line in self.logic.bridgeLines():
                self.bridgeList.addItem(line)

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
        self.delayDisplay("Scene placement passed")

    def test_daemon_round_trip(self):
        port = os.environ.get("ROS2BRIDGE_TEST_PORT")
        if not port:
            self.delayDisplay("ROS2BRIDGE_TEST_PORT not set: daemon round trip skipped")
            return
        logic = ROS2BridgeLogic()
        logic.connect("127.0.0.1", int(port))
        deadline = qt.QTime.currentTime().addSecs(10)
        while not logic.isConnected() and qt.QTime.currentTime() < deadline:
            slicer.app.processEvents()
        self.assertTrue(logic.isConnected(), f"no daemon at 127.0.0.1:{port}")
        rosNode = logic.GetDefaultROS2Node()  # noqa: N806
        sub = rosNode.CreateAndAddSubscriberNode("String", "/selftest_string")
        pub = rosNode.CreateAndAddPublisherNode("String", "/selftest_string")
        for _ in range(200):
            pub.Publish("hello from Slicer")
            slicer.app.processEvents()
            logic.updateScene()
            if sub.GetLastMessage() == "hello from Slicer":
                break
        self.assertEqual(sub.GetLastMessage(), "hello from Slicer")
        self.assertIn("subscriber: /selftest_string [std_msgs/msg/String] as selftest_string",
                      logic.bridgeLines())
        state = json.loads(BridgeState.from_json(logic.client.state().to_json()).to_json())
        self.assertEqual(len(state["bridges"]), 2)
        try:
            logic.client.command("list_bridges", timeout=5.0)
        except CommandTimeoutError:
            self.fail("list_bridges through the connector timed out")
        logic.disconnect()
        self.delayDisplay("Daemon round trip passed")

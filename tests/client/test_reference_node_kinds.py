"""The reference facade's other node kinds as a SlicerROS2 script uses them, against a real
daemon and real rclpy peers in other processes: a parameter node read with the reference's
out-argument overloads (``vtk.reference``), tf2 broadcasters driven by a transform node and
lookups that notify only on change, service clients (the reference's SetBoolString and any
``pkg/srv/Type``), action clients, marker subscribers, robots, and a ROS node's life
(``Create``, ``Destroy``, a daemon that went away)."""

from __future__ import annotations

import json
import logging
import threading
import time
from typing import Any, Callable

import numpy as np
import pytest

import slicer_client
from jointy_urdf import JOINTY_URDF
from slicer_client.matrices import as_numpy
from slicer_client.reference.messages import MessageValueError
from ros_echo import echo, until_received
from support import Processes, scaled, start_daemon, wait_until

pytestmark = pytest.mark.ros
vtk = pytest.importorskip("vtk", reason="the reference's out-arguments and transforms are "
                          "VTK objects; the test extra installs vtk")

GRIPPER = "control_msgs/action/GripperCommand"








def spin_until(rosLogic: Any, predicate: Callable[[], bool], what: str) -> None:  # noqa: N803
    def spun() -> bool:
        rosLogic.Spin()
        return predicate()
    wait_until(spun, timeout=20, what=what)


def test_parameter_node_with_the_reference_out_arguments(
        rosLogic: Any, processes: Processes, caplog: pytest.LogCaptureFixture) -> None:  # noqa: N803
    peer = processes.python("rn_params", "param_node.py", "rn_params")
    peer.wait_for_output("READY", timeout=30)
    rosNode = rosLogic.GetDefaultROS2Node()  # noqa: N806
    param = rosNode.CreateAndAddParameterNode("/rn_params")
    assert param.GetName() == "ros2:param:/rn_params"
    assert param.GetMonitoredNodeName() == "/rn_params"
    names = ["flag", "count", "ratio", "label", "blob", "flags"]
    for name in names:
        assert param.AddParameter(name)
    wait_until(lambda: all(param.IsParameterSet(n) for n in names), timeout=30,
               what="the tracked parameters")
    # Values came, so the node answered: ready, even if observe's reply said not yet.
    assert param.IsMonitoredNodeReady() and param.Spin()
    assert param.AddParameter("ratios")
    names.append("ratios")
    with caplog.at_level(logging.WARNING, logger="slicer_client"):
        assert not param.AddParameter("flag")  # already tracked
        assert not param.RemoveParameter("never_tracked")
        assert not param.IsParameterSet("never_tracked")
        assert not param.IsParameterSet("other", noWarning=True)
    warnings = [r.getMessage() for r in caplog.records if r.name == "slicer_client"]
    assert warnings == ["AddParameter: parameter flag of /rn_params is already tracked",
                        "RemoveParameter: parameter never_tracked of /rn_params is not "
                        "monitored",
                        "IsParameterSet: parameter never_tracked of /rn_params is not "
                        "monitored"]
    assert param.GetParameterNames() == names
    assert param.ListTrackedParameters() == "\n".join(names)
    # The reference's overloads with an out-argument: the value in it, the call says set.
    result = vtk.reference("")
    assert param.GetParameterType("count", result) is True and result.get() == "integer"
    unset = vtk.reference("x")
    assert param.GetParameterType("never_tracked", unset) is False and unset.get() == ""
    flag = vtk.reference(False)
    assert param.GetParameterAsBool("flag", flag) is True and flag.get() is True
    count = vtk.reference(0)
    assert param.GetParameterAsInteger("count", count) is True and count.get() == 3
    ratio = vtk.reference(0.0)
    assert param.GetParameterAsDouble("ratio", ratio) is True and ratio.get() == 3.0
    assert param.GetParameterAsDouble("count") == 3.0  # an integer reads as a double
    label: list = []  # a one-item list works as the out-argument too
    assert param.GetParameterAsString("label", label) is True and label == ["/rn_params"]
    # A parameter of another type: False, the out-argument emptied, a warning.
    wrong = vtk.reference(True)
    with caplog.at_level(logging.WARNING, logger="slicer_client"):
        assert param.GetParameterAsBool("count", wrong) is False
    assert wrong.get() is False
    assert "parameter 'count' of /rn_params is integer, not bool" in caplog.text
    with pytest.raises(KeyError, match="parameter 'missing' of /rn_params is not set"):
        param.GetParameterAsInteger("missing")
    with pytest.raises(TypeError, match="expected a vtk.reference .*got int"):
        param.GetParameterAsInteger("count", 5)
    assert param.GetParameterAsVectorOfIntegers("blob") == [0, 7, 255]
    assert param.PrintParameter("flag") == "true"
    assert param.PrintParameter("count") == "3"
    assert param.PrintParameter("flags") == "[true, false]"
    assert param.PrintParameter("missing") == "parameter not found"
    # Not in the reference (its node is read-only): the node itself sees the change.
    assert param.SetParameter("count", 5)
    changed = json.loads(peer.wait_for_output('"name": "count"').split("CHANGED ", 1)[1])
    assert changed == {"name": "count", "type": "integer", "value": 5}
    wait_until(lambda: param.PrintParameter("count") == "5", timeout=20,
               what="the change back in the node")
    assert rosNode.RemoveAndDeleteParameterNode("/rn_params")


class TransformNodeStandin:
    """What of a vtkMRMLTransformNode the broadcaster uses (Slicer is not installable
    here): its matrix and observers of TransformModifiedEvent."""

    TransformModifiedEvent = 15000

    def __init__(self) -> None:
        self.matrix = vtk.vtkMatrix4x4()
        self.observers: list = []

    def AddObserver(self, event: int, callback: Any) -> int:  # noqa: N802
        self.observers.append((event, callback))
        return len(self.observers)

    def GetMatrixTransformToParent(self, matrix: Any) -> None:  # noqa: N802
        matrix.DeepCopy(self.matrix)

    def move(self, x_mm: float) -> None:
        self.matrix.SetElement(0, 3, x_mm)
        for event, callback in self.observers:
            callback(self, event)


def test_broadcaster_follows_a_transform_node_and_a_lookup_on_change_only(
        rosLogic: Any, processes: Processes) -> None:  # noqa: N803
    rosNode = rosLogic.GetDefaultROS2Node()  # noqa: N806
    broadcaster = rosNode.CreateAndAddTf2BroadcasterNode("rn_world", "rn_tool")
    assert rosNode.GetTf2BroadcasterNodeByParentChild("rn_world", "rn_tool") is broadcaster
    assert broadcaster.IsParentAndChildSet()
    assert broadcaster.GetName() == "ros2:tf2broadcaster:rn_worldTorn_tool"
    assert broadcaster.GetNumberOfBroadcasts() == 0
    assert broadcaster.SetParentID("rn_world")  # the same pair: nothing to change
    transform = TransformNodeStandin()
    assert broadcaster.ObserveTransformNode(transform) == 1
    tf = echo(processes, "/tf", "tf2_msgs/msg/TFMessage")
    sent = until_received(lambda: transform.move(40.0), tf)
    frames = {t["child_frame_id"]: t for t in sent["transforms"]}
    assert frames["rn_tool"]["transform"]["translation"]["x"] == pytest.approx(0.040)
    assert broadcaster.GetNumberOfBroadcasts() >= 1

    lookup = rosNode.CreateAndAddTf2LookupNode("rn_world", "rn_tool")
    assert lookup.GetModifiedOnLookup()
    lookup.SetModifiedOnLookup(False)
    assert not lookup.GetModifiedOnLookup()
    seen: list[float] = []
    lookup.AddObserver("TransformModifiedEvent", lambda caller, event: seen.append(
        caller.GetMatrixTransformToParent().GetElement(0, 3)))
    # Notified when the transform changes (the first value may have come before the
    # observer): move the transform node until the lookup has seen the new place.
    spin_until(rosLogic, lambda: 41.0 in [round(v, 3) for v in seen] or
               bool(transform.move(41.0)), "the lookup to see 41 mm")
    # Spins with nothing new notify nobody (the reference's SetModifiedOnLookup(False)).
    count = len(seen)
    for _ in range(5):
        rosLogic.Spin()
    assert len(seen) == count
    target = vtk.vtkMatrix4x4()
    assert lookup.GetMatrixTransformToParent(target) is target
    assert target.GetElement(0, 3) == pytest.approx(41.0, abs=1e-3)
    assert rosNode.RemoveAndDeleteTf2LookupNode("rn_world", "rn_tool")
    assert rosNode.RemoveAndDeleteTf2BroadcasterNode("rn_world", "rn_tool")


def test_service_clients_the_reference_way(rosLogic: Any, processes: Processes) -> None:  # noqa: N803
    server = processes.python("rn_services", "service_server.py", "--namespace", "rn_srv")
    server.wait_for_output("READY", timeout=30)
    rosNode = rosLogic.GetDefaultROS2Node()  # noqa: N806
    node = rosNode.CreateAndAddServiceClientNode("vtkMRMLROS2ServiceClientSetBoolStringNode",
                                                 "/rn_srv/set_enabled")
    assert rosNode.CreateAndAddServiceClientNode("SetBoolString", "/rn_srv/set_enabled") \
        is node
    assert rosNode.GetServiceClientNodeByService("/rn_srv/set_enabled") is node
    assert node.GetName() == "ros2:srv:client:/rn_srv/set_enabled"
    assert node.GetService() == node.GetTopic() == "/rn_srv/set_enabled"
    assert node.GetROSType() == "std_srvs/srv/SetBool"
    assert node.GetSlicerTypeOut() == "vtkStdSrvsSetBoolResponse"
    assert (node.GetNumberOfCalls(), node.GetNumberOfRequestsSent()) == (0, 0)
    wait_until(node.PreRequestCheck, timeout=30, what="the service in the ROS graph")
    # The reference's hand-written SetBoolString: a request with Value, a response with
    # Result and Message.
    request = node.CreateBlankRequest()
    request.SetValue(True)
    assert request.GetValue() is True
    response = node.SendBlockingRequest(request, timeout=scaled(10))
    assert response.GetResult() is True and response.GetMessage() == "/rn_srv enabled=True"
    assert json.loads(server.wait_for_output("CALL set_enabled").split(" ", 2)[2]) == {
        "data": True}
    # A plain dict of the request's fields works as well.
    assert node.SendBlockingRequest({"data": False}, timeout=scaled(10)).GetResult() is False
    # Something that is not this service's request: refused before anything is sent.
    trigger = rosNode.CreateAndAddServiceClientNode("std_srvs/srv/Trigger", "/rn_srv/trigger")
    assert trigger.GetSlicerTypeIn() == "vtkStdSrvsTriggerRequest"
    with pytest.raises(MessageValueError, match="expected a std_srvs/srv/SetBool_Request "
                                                "request, got a std_srvs/srv/Trigger_Request"):
        node.SendBlockingRequest(trigger.CreateBlankRequest())
    with pytest.raises(MessageValueError, match="expected a request from "
                                                r"CreateBlankRequest\(\), got int"):
        node.SendBlockingRequest(5)
    assert (node.GetNumberOfCalls(), node.GetNumberOfRequestsSent()) == (4, 2)
    # Async: returns at once; the response and ModifiedEvent come in a later spin.
    done = threading.Event()
    trigger.AddObserver("ModifiedEvent", lambda caller, event: done.set())
    assert trigger.SendAsyncRequest() == 1
    spin_until(rosLogic, done.is_set, "the async response's ModifiedEvent")
    assert trigger.GetLastResponseStatus()
    assert trigger.GetLastResponse().GetMessage().startswith("triggered")
    # A service nobody serves: not in the graph, and the async call ends without a response.
    absent = rosNode.CreateAndAddServiceClientNode("std_srvs/srv/Trigger", "/rn_srv/absent")
    assert not absent.PreRequestCheck()
    assert absent.SendAsyncRequest(timeout=0.5) == 1
    time.sleep(0)  # (the call runs on its own thread)
    wait_until(lambda: not absent.GetLastResponseStatus() and
               absent.GetNumberOfRequestsSent() == 1, timeout=20, what="the failed call")
    assert absent.GetLastResponse() is None
    assert rosNode.RemoveAndDeleteServiceClientNode("/rn_srv/absent")
    assert not rosNode.RemoveAndDeleteServiceClientNode("/rn_srv/absent")


def test_action_client_node_before_and_after_a_rejected_goal(
        rosLogic: Any, processes: Processes) -> None:  # noqa: N803
    server = processes.python("rn_gripper", "gripper_action_server.py", "--action",
                              "/rn_gripper", "--steps", "2", "--period", "0.05")
    server.wait_for_output("READY", timeout=30)
    rosNode = rosLogic.GetDefaultROS2Node()  # noqa: N806
    action = rosNode.CreateAndAddActionClientNode(GRIPPER, "/rn_gripper")
    assert action.GetName() == "ros2:action:/rn_gripper"
    assert action.GetAction() == action.GetTopic() == "/rn_gripper"
    assert action.GetROSType() == GRIPPER
    assert (action.GetGoalStatus(), action.GetNumberOfFeedbacks()) == ("", 0)
    assert action.GetLastFeedback() is None and action.GetLastResult() is None
    assert action.CancelGoal() is False
    with pytest.raises(RuntimeError, match="no goal sent to /rn_gripper yet"):
        action.WaitForResult(1.0)
    ended = threading.Event()
    action.AddObserver("ModifiedEvent", lambda caller, event: ended.set()
                       if caller.GetGoalStatus() not in ("sending", "accepted", "executing")
                       else None)
    # The server rejects a negative effort: SendGoal says so, naming the field.
    with pytest.raises(slicer_client.CommandRefusedError, match="REJECTED: goal"):
        action.SendGoal({"command": {"position": 0.1, "max_effort": -1.0}},
                        timeout=scaled(10))
    assert action.GetGoalStatus() == ""
    action.SendGoal({"command": {"position": 0.2, "max_effort": 1.0}}, timeout=scaled(10))
    assert action.WaitForResult(scaled(10))["position"] == pytest.approx(0.2)
    assert action.GetLastFeedback()["position"] == pytest.approx(0.2)
    spin_until(rosLogic, ended.is_set, "the goal's end")
    assert action.GetGoalStatus() == "succeeded"
    # A server that dies during the goal: the goal ends without a result.
    processes.python("rn_dying", "gripper_action_server.py", "--action", "/rn_dying",
                     "--steps", "50", "--period", "0.05", "--die-after", "1"
                     ).wait_for_output("READY", timeout=30)
    dying = rosNode.CreateAndAddActionClientNode(GRIPPER, "/rn_dying")
    lost = threading.Event()
    dying.AddObserver("ModifiedEvent", lambda caller, event: lost.set()
                      if caller.GetGoalStatus() not in ("sending", "accepted", "executing")
                      else None)
    dying.SendGoal({"command": {"position": 0.3, "max_effort": 1.0}}, timeout=scaled(10))
    spin_until(rosLogic, lost.is_set, "the end of the goal whose server died")
    assert dying.GetGoalStatus() not in ("succeeded", "canceled")
    assert dying.GetLastResult() is None
    # Destroy lets go of action and service nodes too.
    rosNode.CreateAndAddServiceClientNode("std_srvs/srv/Trigger", "/rn_dropped")
    rosNode.Destroy()
    assert rosNode.GetActionClientNodeByName("/rn_gripper") is None
    assert rosNode.GetServiceClientNodeByService("/rn_dropped") is None
    assert not rosNode.GetSpinning()


def test_marker_and_robot_nodes_and_a_named_ros_node(rosLogic: Any,  # noqa: N803
                                                     processes: Processes) -> None:
    rsp = processes.python("rn_rsp", "param_node.py", "robot_state_publisher", "--namespace",
                           "rn_jointy", "--description", JOINTY_URDF)
    rsp.wait_for_output("READY", timeout=30)
    node = rosLogic.CreateROS2Node("rn_named")
    assert node.GetROS2NodeName() == "rn_named" and node.GetName() == "ros2:node:rn_named"
    assert node.GetSpinning()
    markers = node.CreateAndAddMarkerSubscriberNode("Marker", "/rn_markers", "rn_world")
    assert markers.GetName() == "ros2:markers:/rn_markers"
    assert markers.GetTopic() == "/rn_markers" and markers.GetFixedFrame() == "rn_world"
    assert markers.GetNumberOfMarkers() == 0
    assert node.GetMarkerSubscriberNodeByTopic("/rn_markers") is markers
    robot = node.CreateAndAddRobotNode("rn_jointy", "/rn_jointy/robot_state_publisher")
    # Its links come with tf (no state publisher runs here); the URDF is loaded first.
    robot.resource._wait(lambda: robot.resource.state == "loaded", scaled(30), "the URDF")
    assert robot.GetName() == "ros2:robot:rn_jointy" and robot.GetRobotName() == "rn_jointy"
    assert robot.GetJointNames() == ["shoulder", "spin", "slide"]
    with pytest.raises(KeyError, match="robot rn_jointy has no joint 'elbow'"):
        robot.GetJointLimits("elbow")
    echo_states = echo(processes, "/rn_jointy/joint_states", "sensor_msgs/msg/JointState")
    state = until_received(lambda: robot.SetJointPositions({"shoulder": 0.5}), echo_states)
    assert state["name"] == ["shoulder"] and state["position"] == [0.5]
    # Two ROS nodes of one client holding one bridge: it stays until the last lets go.
    other = rosLogic.CreateROS2Node("rn_other")
    node.CreateAndAddSubscriberNode("String", "/rn_shared")
    other.CreateAndAddSubscriberNode("String", "/rn_shared")
    assert other.RemoveAndDeleteSubscriberNode("/rn_shared")
    assert [b for b in rosLogic.client.command("list_bridges")["bridges"]
            if b.get("topic") == "/rn_shared"]
    node.Spin()
    node.Destroy()
    assert node.GetRobotNodeByName("rn_jointy") is None
    assert not node.GetSpinning()
    listed = rosLogic.client.command("list_bridges")["bridges"]
    assert not [b for b in listed if b.get("name") == "rn_jointy"
                or b.get("topic") == "/rn_markers"]
    default = rosLogic.GetDefaultROS2Node()
    assert "vtkMRMLROS2ServiceClientSetBoolStringNode" in \
        default.RegisteredROS2ServiceClientNodes()
    assert not rosLogic.RemoveRobot("rn_never_loaded")
    assert default.GetROS2NodeName() == rosLogic.client.daemon_info.get("node",
                                                                        "/slicer_bridge")


def test_a_node_whose_daemon_went_away_says_it_is_not_spinning(
        processes: Processes, caplog: pytest.LogCaptureFixture) -> None:
    daemon = start_daemon(processes)
    client = slicer_client.connect("127.0.0.1", daemon.port, reconnect=False)
    try:
        rosNode = client.GetDefaultROS2Node()  # noqa: N806
        sub = rosNode.CreateAndAddSubscriberNode("String", "/rn_gone")
        assert rosNode.GetSpinning()
        rosNode.WarnIfNotSpinning("reading")  # connected: no warning
        daemon.child.stop()
        wait_until(lambda: not client.connected, timeout=20, what="the disconnection")
        with caplog.at_level(logging.WARNING, logger="slicer_client"):
            rosNode.WarnIfNotSpinning("publishing")
        assert not rosNode.GetSpinning()
        assert "is not spinning (not connected to the daemon) when publishing" in caplog.text
        assert sub.GetLastMessage() is None  # reads stay local
        with pytest.raises(slicer_client.BridgeClientError):
            rosNode.CreateAndAddPublisherNode("String", "/rn_gone_pub")
    finally:
        client.close()
    assert np.array_equal(as_numpy(np.eye(4)), np.eye(4))

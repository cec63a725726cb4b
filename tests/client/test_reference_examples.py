"""The reference SlicerROS2's documented Python examples, run through the CamelCase facade
against a real daemon and real rclpy peers (only the logic line differs)."""

from __future__ import annotations

import json
import threading

import numpy as np
import pytest

import slicer_client
from support import Processes, RunningDaemon, require_shared, scaled, start_daemon, wait_until

pytestmark = pytest.mark.ros


def echo(processes: Processes, topic: str, msg_type: str, *flags: str):
    child = processes.python(f"echo{topic.replace('/', '_')}", "echo_subscriber.py", topic,
                             msg_type, *flags)
    child.wait_for_output("READY", timeout=30)
    return child


def publish_until_received(pub, value, child, timeout: float = 20.0) -> dict:
    """Publish repeatedly until the rclpy peer prints a message (discovery races)."""
    import time
    deadline = time.monotonic() + scaled(timeout)
    while True:
        pub.Publish(value)
        try:
            line = child.wait_for_output("MSG ", timeout=0.2)
            return json.loads(line.split("MSG ", 1)[1])
        except AssertionError:
            if time.monotonic() > deadline:
                raise


class _Broadcasting:
    """Lets publish_until_received drive a broadcaster."""

    def __init__(self, broadcaster) -> None:
        self.broadcaster = broadcaster

    def Publish(self, matrix) -> None:  # noqa: N802
        self.broadcaster.Broadcast(matrix)


def test_publish_string_reaches_an_rclpy_subscriber(daemon: RunningDaemon,
                                                    processes: Processes) -> None:
    rosLogic = slicer_client.connect("127.0.0.1", daemon.port)  # noqa: N806
    try:
        rosNode = rosLogic.GetDefaultROS2Node()  # noqa: N806
        pub = rosNode.CreateAndAddPublisherNode('String', '/ref_my_string')
        assert rosNode.GetPublisherNodeByTopic('/ref_my_string') is pub
        peer = echo(processes, "/ref_my_string", "std_msgs/msg/String")
        assert publish_until_received(pub, 'hello', peer) == {"data": "hello"}
        wait_until(lambda: pub.Publish('hello') == 1, what="Publish to count the subscriber")
        assert rosNode.RemoveAndDeletePublisherNode('/ref_my_string')
        assert rosNode.GetPublisherNodeByTopic('/ref_my_string') is None
        assert not rosNode.RemoveAndDeletePublisherNode('/ref_my_string')
    finally:
        rosLogic.close()


def test_class_name_and_pose_stamped_in_mm_arrives_in_metres(daemon: RunningDaemon,
                                                             processes: Processes) -> None:
    with slicer_client.connect("127.0.0.1", daemon.port) as rosLogic:  # noqa: N806
        rosNode = rosLogic.GetDefaultROS2Node()  # noqa: N806
        pub = rosNode.CreateAndAddPublisherNode('vtkMRMLROS2PublisherPoseStampedNode',
                                                '/ref_pose')
        peer = echo(processes, "/ref_pose", "geometry_msgs/msg/PoseStamped")
        matrix = np.eye(4)
        matrix[0, 3] = 3.1415  # mm
        received = publish_until_received(pub, matrix, peer)
        assert received["pose"]["position"]["x"] == pytest.approx(0.0031415, abs=1e-9)
        assert received["pose"]["orientation"]["w"] == pytest.approx(1.0)
        assert pub.GetROSType() == "geometry_msgs/msg/PoseStamped"


def test_subscribe_string_message_count_yaml_and_observer(daemon: RunningDaemon) -> None:
    with slicer_client.connect("127.0.0.1", daemon.port) as rosLogic:  # noqa: N806
        rosNode = rosLogic.GetDefaultROS2Node()  # noqa: N806
        sub = rosNode.CreateAndAddSubscriberNode('String', '/ref_sub_string')
        pub = rosNode.CreateAndAddPublisherNode('String', '/ref_sub_string')
        observed = threading.Event()
        calls: list[tuple[object, str]] = []

        def callback(caller, event) -> None:
            calls.append((caller, event))
            observed.set()

        tag = sub.AddObserver('ModifiedEvent', callback)
        wait_until(lambda: pub.Publish('hello world') >= 1 and observed.wait(0.1),
                   timeout=20, what="the subscriber's ModifiedEvent")
        assert sub.GetLastMessage() == 'hello world'
        assert sub.GetLastMessageYAML() == 'data: hello world\n'
        assert sub.GetNumberOfMessages() >= 1
        assert calls[0] == (sub, 'ModifiedEvent')
        assert rosNode.GetSubscriberNodeByTopic('/ref_sub_string') is sub
        sub.RemoveObserver(tag)
        assert not sub.HasObserver('ModifiedEvent')
        assert rosNode.RemoveAndDeleteSubscriberNode('/ref_sub_string')
        assert rosNode.GetSubscriberNodeByTopic('/ref_sub_string') is None


def test_typed_scalars_and_arrays_come_back_as_slicer_values(daemon: RunningDaemon) -> None:
    with slicer_client.connect("127.0.0.1", daemon.port) as ros:
        rosNode = ros.GetDefaultROS2Node()  # noqa: N806
        for short, value in (('Int', 7), ('Double', 2.5), ('Bool', True),
                             ('DoubleArray', [1.5, 2.5]), ('IntTable', [[1, 2], [3, 4]])):
            topic = f"/ref_typed_{short.lower()}"
            sub = rosNode.CreateAndAddSubscriberNode(short, topic)
            pub = rosNode.CreateAndAddPublisherNode(short, topic)
            wait_until(lambda pub=pub, sub=sub, value=value: pub.Publish(value) >= 1
                       and sub.GetLastMessage() is not None,
                       timeout=20, what=f"a {short} message")
            assert sub.GetLastMessage() == value, short


def test_read_parameters_of_an_rclpy_node(daemon: RunningDaemon,
                                          processes: Processes) -> None:
    node = processes.python("params", "client_parameter_node.py", "client_param_peer")
    node.wait_for_output("READY", timeout=30)
    with slicer_client.connect("127.0.0.1", daemon.port) as rosLogic:  # noqa: N806
        rosNode = rosLogic.GetDefaultROS2Node()  # noqa: N806
        param = rosNode.CreateAndAddParameterNode('/client_param_peer')
        for name in ("flag", "count", "ratio", "label", "flags", "counts", "ratios",
                     "labels"):
            assert param.AddParameter(name)
        assert param.IsParameterSet('count')
        assert param.GetParameterType('count') == 'integer'
        assert param.GetParameterAsBool('flag') is True
        assert param.GetParameterAsInteger('count') == 42
        assert param.GetParameterAsDouble('ratio') == 2.5
        assert param.GetParameterAsString('label') == 'omni'
        assert param.GetParameterAsVectorOfBools('flags') == [True, False]
        assert param.GetParameterAsVectorOfIntegers('counts') == [1, 2, 3]
        assert param.GetParameterAsVectorOfDoubles('ratios') == [0.5, 1.5]
        assert param.GetParameterAsVectorOfStrings('labels') == ['a', 'b']
        assert param.PrintParameter('flags') == '[true, false]'
        assert param.GetParameterType('untracked') == ''
        with pytest.raises(TypeError, match="count.*integer, not string"):
            param.GetParameterAsString('count')
        # An observed change arrives as ParameterModifiedEvent.
        changed = threading.Event()
        param.AddObserver('ParameterModifiedEvent', lambda caller, event: changed.set())
        param.resource.set('count', 43)
        node.wait_for_output("SET count=43")
        assert changed.wait(10), "no ParameterModifiedEvent after the change"
        assert param.GetParameterAsInteger('count') == 43
        assert param.RemoveParameter('count') and not param.IsParameterSet('count')
        assert rosNode.GetParameterNodeByNode('/client_param_peer') is param
        assert rosNode.RemoveAndDeleteParameterNode('/client_param_peer')


def test_broadcast_a_transform_and_read_it_back_through_a_lookup(
        daemon: RunningDaemon, processes: Processes) -> None:
    with slicer_client.connect("127.0.0.1", daemon.port) as rosLogic:  # noqa: N806
        rosNode = rosLogic.GetDefaultROS2Node()  # noqa: N806
        broadcaster = rosNode.CreateAndAddTf2BroadcasterNode('ref_world', 'ref_needle')
        lookup = rosNode.CreateAndAddTf2LookupNode('ref_world', 'ref_needle')
        tf = echo(processes, "/tf", "tf2_msgs/msg/TFMessage")
        matrix = np.array([[0.0, -1.0, 0.0, 10.0], [1.0, 0.0, 0.0, 20.0],
                           [0.0, 0.0, 1.0, 30.0], [0, 0, 0, 1.0]])
        changed = threading.Event()
        lookup.AddObserver('ModifiedEvent', lambda caller, event: changed.set())
        wait_until(lambda: broadcaster.Broadcast(matrix) and changed.wait(0.2), timeout=20,
                   what="the lookup to see the broadcast")
        np.testing.assert_allclose(lookup.GetMatrixTransformToParent(), matrix, atol=1e-4)
        # The independent rclpy witness sees metres (broadcast until it has matched).
        sent = publish_until_received(_Broadcasting(broadcaster), matrix, tf)
        frames = {t["child_frame_id"]: t for t in sent["transforms"]}
        assert frames["ref_needle"]["header"]["frame_id"] == "ref_world"
        assert frames["ref_needle"]["transform"]["translation"]["x"] == pytest.approx(0.010)
        assert rosNode.GetTf2LookupNodeByParentChild('ref_world', 'ref_needle') is lookup
        assert rosNode.RemoveAndDeleteTf2LookupNode('ref_world', 'ref_needle')
        assert rosNode.RemoveAndDeleteTf2BroadcasterNode('ref_world', 'ref_needle')


def test_load_the_omni_robot(processes: Processes) -> None:
    omni = require_shared("robots/sensable_omni_model")
    daemon = start_daemon(processes, "--package-path", f"sensable_omni_model={omni}")
    rsp = processes.start("state_publisher", [
        __import__("sys").executable, "-u", "-m", "bridge.robots.state_publisher",
        str(omni / "urdf" / "omni.urdf")])
    rsp.wait_for_output("ready", timeout=30)
    # A state publisher (like ROS's) publishes tf only for joints it has states for.
    processes.python("joints", "robot_joint_state_publisher.py", "waist=0.5",
                     "shoulder=0.2", "elbow=-0.3", "yaw=0.0", "pitch=0.1", "roll=0.0")
    with slicer_client.connect("127.0.0.1", daemon.port) as rosLogic:  # noqa: N806
        rosNode = rosLogic.GetDefaultROS2Node()  # noqa: N806
        robot = rosNode.CreateAndAddRobotNode('omni', '/robot_state_publisher',
                                              'robot_description', 'base', '')
        robot.resource.wait_until_loaded(timeout=60)
        assert robot.GetNumberOfLinks() == 7
        assert robot.resource.mesh_count() == 7
        assert robot.GetLinkNames() == sorted(["base", "torso", "upper_arm", "lower_arm",
                                               "wrist", "tip", "stylus"])
        np.testing.assert_allclose(robot.GetLinkTransform('base'), np.eye(4), atol=1e-6)
        mesh = robot.resource.links['base'].meshes[0]
        assert len(mesh.points) > 100
        assert rosNode.GetRobotNodeByName('omni') is robot
        assert rosNode.RemoveAndDeleteRobotNode('omni')

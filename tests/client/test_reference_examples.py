"""The reference SlicerROS2's documented Python examples, run through the CamelCase facade
against a real daemon and real rclpy peers (only the logic line differs)."""

from __future__ import annotations

import json
import threading

import numpy as np
import pytest

import slicer_client
from slicer_client.matrices import as_numpy
from slicer_client.reference.vtk_values import array_values, table_columns
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
        # Arrays and tables come back as VTK's (vtk_values.py reads either kind).
        for short, value, read, expected in (
                ('Int', 7, None, 7), ('Double', 2.5, None, 2.5), ('Bool', True, None, True),
                ('DoubleArray', [1.5, 2.5], array_values, [1.5, 2.5]),
                ('IntTable', [[1, 2], [3, 4]], table_columns, [[1, 3], [2, 4]])):
            topic = f"/ref_typed_{short.lower()}"
            sub = rosNode.CreateAndAddSubscriberNode(short, topic)
            pub = rosNode.CreateAndAddPublisherNode(short, topic)
            wait_until(lambda pub=pub, sub=sub, value=value: pub.Publish(value) >= 1
                       and sub.GetLastMessage() is not None,
                       timeout=20, what=f"a {short} message")
            got = sub.GetLastMessage()
            assert (got if read is None else read(got)) == expected, short


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
        # As in the reference, values arrive from the node (at once when the daemon has
        # discovered it already, else when it does).
        wait_until(lambda: all(param.IsParameterSet(n) for n in ("flag", "count", "labels")),
                   timeout=30, what="the tracked parameters")
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
        # An observed change arrives as ParameterModifiedEvent, with the value readable in
        # the observer (earlier events, of values that came after the first ones, may still
        # be on their way: only the one that shows 43 counts).
        changed = threading.Event()

        def modified(caller, event) -> None:
            if caller.GetParameterAsInteger('count') == 43:
                changed.set()

        param.AddObserver('ParameterModifiedEvent', modified)
        param.resource.set('count', 43)
        node.wait_for_output("SET count=43")
        assert changed.wait(scaled(10)), "no ParameterModifiedEvent showing the change"
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
        np.testing.assert_allclose(as_numpy(lookup.GetMatrixTransformToParent(), rigid=False),
                                   matrix, atol=1e-4)
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
        np.testing.assert_allclose(as_numpy(robot.GetLinkTransform('base'), rigid=False),
                                   np.eye(4), atol=1e-6)
        mesh = robot.resource.links['base'].meshes[0]
        assert len(mesh.points) > 100
        assert rosNode.GetRobotNodeByName('omni') is robot
        assert rosNode.RemoveAndDeleteRobotNode('omni')


# ----------------------------------------------------------- the reference's doc examples
# One test per code block of SlicerROS2's docs (docs/pages/nodes/*.rst), each run with only
# the logic line changed. Lines that need 3D Slicer itself (`slicer.mrmlScene`, `vtk`) are
# run only where they can be.

def test_doc_topics_publishers_example(daemon: RunningDaemon, processes: Processes) -> None:
    rosLogic = slicer_client.connect("127.0.0.1", daemon.port)  # noqa: N806
    try:
        rosNode = rosLogic.GetDefaultROS2Node()  # noqa: N806
        # optional, shows which publishers are available
        assert "vtkMRMLROS2PublisherStringNode" in rosNode.RegisteredROS2PublisherNodes()
        # example with full class name
        pubString = rosNode.CreateAndAddPublisherNode('vtkMRMLROS2PublisherStringNode', '/doc_my_string')  # noqa: E501,N806
        strings = echo(processes, "/doc_my_string", "std_msgs/msg/String")
        assert publish_until_received(pubString, 'my first string', strings) == {
            "data": "my first string"}
        # example with short class name, Pose will be expanded to vtkMRMLROS2PublisherPoseNode
        pubMatrix = rosNode.CreateAndAddPublisherNode('Pose', '/doc_my_matrix')  # noqa: N806
        mat = pubMatrix.GetBlankMessage()  # a vtkMatrix4x4 in Slicer; the same API here
        mat.SetElement(0, 3, 3.1415)  # Modify the matrix so we can see something changing
        poses = echo(processes, "/doc_my_matrix", "geometry_msgs/msg/Pose")
        received = publish_until_received(pubMatrix, mat, poses)
        assert received["position"] == {"x": pytest.approx(0.0031415, abs=1e-12), "y": 0.0,
                                        "z": 0.0}
        assert received["orientation"]["w"] == pytest.approx(1.0)
        # GetBlankMessage gives the kind of value each publisher takes.
        assert pubString.GetBlankMessage() == ""
        blank = rosNode.CreateAndAddPublisherNode('DoubleArray', '/doc_da').GetBlankMessage()
        assert blank.GetClassName() == "vtkDoubleArray" and blank.GetNumberOfValues() == 0
        assert rosNode.RemoveAndDeletePublisherNode('/doc_my_string')
    finally:
        rosLogic.close()


def test_doc_topics_subscribers_example(daemon: RunningDaemon) -> None:
    with slicer_client.connect("127.0.0.1", daemon.port) as rosLogic:  # noqa: N806
        rosNode = rosLogic.GetDefaultROS2Node()  # noqa: N806
        assert "vtkMRMLROS2SubscriberStringNode" in rosNode.RegisteredROS2SubscriberNodes()
        subString = rosNode.CreateAndAddSubscriberNode('String', '/doc_sub_string')  # noqa: N806
        m_string = subString.GetLastMessage()
        assert m_string is None  # nothing published yet
        printed: list[str] = []
        got = threading.Event()

        def myCallback(caller=None, event=None):  # noqa: N802
            message = subString.GetLastMessage()
            printed.append("Last message received by subscriber: {}.".format(message))
            got.set()

        observerId = subString.AddObserver('ModifiedEvent', myCallback)  # noqa: N806
        # The doc sends with `ros2 topic pub`; here a publisher of this daemon does it.
        pub = rosNode.CreateAndAddPublisherNode('String', '/doc_sub_string')
        wait_until(lambda: pub.Publish('from ROS') >= 1 and got.wait(0.1), timeout=20,
                   what="the observer")
        assert printed[0] == "Last message received by subscriber: from ROS."
        m_string_yaml = subString.GetLastMessageYAML()
        assert m_string_yaml == "data: from ROS\n"
        subString.RemoveObserver(observerId)
        # The pose subscriber of the example, observed with Slicer's integer event id.
        subPose = rosNode.CreateAndAddSubscriberNode('Pose', '/doc_StylusToTracker')  # noqa: N806
        poses: list[np.ndarray] = []
        pose_seen = threading.Event()

        def updateTransforms(caller=None, event=None):  # noqa: N802
            poses.append(subPose.GetLastMessage())
            pose_seen.set()

        subPose.AddObserver(33, updateTransforms)  # vtkCommand.ModifiedEvent
        pose_pub = rosNode.CreateAndAddPublisherNode('Pose', '/doc_StylusToTracker')
        target = np.eye(4)
        target[:3, 3] = (10.0, 20.0, 30.0)
        wait_until(lambda: pose_pub.Publish(target) >= 1 and pose_seen.wait(0.1),
                   timeout=20, what="the pose observer")
        np.testing.assert_allclose(as_numpy(poses[-1]), target, atol=1e-9)


def test_doc_parameters_example_on_a_node_that_appears_later(
        daemon: RunningDaemon, processes: Processes) -> None:
    with slicer_client.connect("127.0.0.1", daemon.port) as rosLogic:  # noqa: N806
        rosNode = rosLogic.GetDefaultROS2Node()  # noqa: N806
        # setup to get parameter robot_description from node state_publisher
        parameterNode = rosNode.CreateAndAddParameterNode('doc_state_publisher')  # noqa: N806
        # The node is not running yet: the reference returns at once and reports "not set".
        assert parameterNode.AddParameter('robot_description') is True
        assert parameterNode.IsParameterSet('robot_description') is False
        assert parameterNode.GetParameterType('robot_description') == ""  # as the reference
        # Observed before the node starts: the value may arrive before READY is read.
        modified = threading.Event()
        parameterNode.AddObserver(1054, lambda caller, event: modified.set())  # int id
        node = processes.python("doc_params", "param_node.py", "doc_state_publisher",
                                "--description", "<robot name='doc'/>")
        node.wait_for_output("READY", timeout=30)
        wait_until(lambda: parameterNode.IsParameterSet('robot_description'), timeout=30,
                   what="the parameter once its node is there")
        robotDescription = None  # noqa: N806
        # check if parameter is set, C++ example is more detailed
        if parameterNode.IsParameterSet('robot_description'):
            # then check the type
            if parameterNode.GetParameterType('robot_description') == 'string':
                robotDescription = parameterNode.GetParameterAsString('robot_description')  # noqa: N806,E501
        assert robotDescription == "<robot name='doc'/>"
        # Observers run in their own thread, after the value is readable: waited for.
        assert modified.wait(timeout=30)
        assert rosNode.RemoveAndDeleteParameterNode('doc_state_publisher')
        # The daemon no longer lists the client that had waited for the node.
        listed = rosLogic.command("list_bridges")["bridges"]
        assert not [b for b in listed if b.get("node") == "/doc_state_publisher"]


def test_doc_tf2_broadcast_example(daemon: RunningDaemon, processes: Processes) -> None:
    vtk = pytest.importorskip("vtk", reason="the example builds a vtk.vtkMatrix4x4 (3D Slicer "
                              "has vtk; the facade's own matrices are tested above)")
    with slicer_client.connect("127.0.0.1", daemon.port) as rosLogic:  # noqa: N806
        rosNode = rosLogic.GetDefaultROS2Node()  # noqa: N806
        broadcaster = rosNode.CreateAndAddTf2BroadcasterNode('Parent', 'Child')
        # Broadcast a 4x4 matrix
        broadcastedMat = vtk.vtkMatrix4x4()  # noqa: N806
        broadcastedMat.SetElement(0, 3, 66.0)  # Set a default value
        tf = echo(processes, "/tf", "tf2_msgs/msg/TFMessage")
        sent = publish_until_received(_Broadcasting(broadcaster), broadcastedMat, tf)
        assert sent["transforms"][0]["transform"]["translation"]["x"] == pytest.approx(0.066)


def test_doc_tf2_lookup_example(daemon: RunningDaemon, processes: Processes) -> None:
    with slicer_client.connect("127.0.0.1", daemon.port) as rosLogic:  # noqa: N806
        rosNode = rosLogic.GetDefaultROS2Node()  # noqa: N806
        # Note that this next line will give you a repeated error if there is nothing
        # broadcasting to Parent -> Child
        lookupNode = rosNode.CreateAndAddTf2LookupNode('base', 'tool')  # noqa: N806
        # get the transform "manually": a transform node's matrix, identity until tf has it
        lookupMat = lookupNode.GetMatrixTransformToParent()  # noqa: N806
        np.testing.assert_array_equal(as_numpy(lookupMat), np.eye(4))
        # or use an observer, with the id Slicer gives TransformModifiedEvent
        seen = threading.Event()
        observerId = lookupNode.AddObserver(15000, lambda caller, event: seen.set())  # noqa: N806,F841,E501
        publisher = processes.python("doc_tf", "tf_publisher.py")
        publisher.wait_for_output("READY", timeout=30)
        assert seen.wait(30), "no TransformModifiedEvent once tf connected base and tool"
        lookupMat = as_numpy(lookupNode.GetMatrixTransformToParent())  # noqa: N806
        # tf_publisher.py: base -> tool is 0.5 m up and 90 degrees about z.
        np.testing.assert_allclose(lookupMat[:3, 3], [0.0, 0.0, 500.0], atol=1e-6)
        np.testing.assert_allclose(lookupMat[:3, :3], [[0, -1, 0], [1, 0, 0], [0, 0, 1]],
                                   atol=1e-6)


def test_tf2_nodes_set_to_another_pair_follow_it(daemon: RunningDaemon) -> None:
    """SetParentID / SetChildID, as the reference's: the node looks up (or broadcasts) the
    new pair from then on; the old pair's bridge goes, the node and its observers stay."""
    with slicer_client.connect("127.0.0.1", daemon.port) as rosLogic:  # noqa: N806
        rosNode = rosLogic.GetDefaultROS2Node()  # noqa: N806
        broadcaster = rosNode.CreateAndAddTf2BroadcasterNode('rt_world', 'rt_a')
        lookup = rosNode.CreateAndAddTf2LookupNode('rt_world', 'rt_a')
        seen: list[float] = []
        lookup.AddObserver('ModifiedEvent', lambda caller, event: seen.append(
            float(as_numpy(caller.GetMatrixTransformToParent(), rigid=False)[0, 3])))
        first = np.eye(4)
        first[0, 3] = 11.0
        wait_until(lambda: broadcaster.Broadcast(first) and 11.0 in seen, timeout=20,
                   what="the lookup to see the first pair's broadcast")

        assert broadcaster.SetChildID('rt_b') and lookup.SetChildID('rt_b')
        assert (broadcaster.GetParentID(), broadcaster.GetChildID()) == ('rt_world', 'rt_b')
        assert lookup.GetName() == "ros2:tf2lookup:rt_worldTort_b"
        assert rosNode.GetTf2LookupNodeByParentChild('rt_world', 'rt_b') is lookup
        assert rosNode.GetTf2LookupNodeByParentChild('rt_world', 'rt_a') is None
        listed = rosLogic.command("list_bridges")["bridges"]
        pairs = {(b["kind"], b["parent"], b["child"]) for b in listed
                 if b["kind"] in ("tf_lookup", "tf_broadcaster") and b["parent"] == "rt_world"}
        assert pairs == {("tf_lookup", "rt_world", "rt_b"), ("tf_broadcaster", "rt_world", "rt_b")}
        second = np.eye(4)
        second[0, 3] = 22.0
        wait_until(lambda: broadcaster.Broadcast(second) and 22.0 in seen, timeout=20,
                   what="the same lookup node to see the new pair")

        # As the reference: an empty id is refused, and so is a pair this node already has.
        assert not lookup.SetParentID('')
        other = rosNode.CreateAndAddTf2LookupNode('rt_world', 'rt_c')
        assert not lookup.SetChildID('rt_c')
        assert lookup.GetChildID() == 'rt_b' and other.GetChildID() == 'rt_c'
        assert rosNode.RemoveAndDeleteTf2LookupNode('rt_world', 'rt_b')
        assert rosNode.RemoveAndDeleteTf2BroadcasterNode('rt_world', 'rt_b')

"""SlicerROS2's own unit tests (Testing/Python/ROS2Tests.py of rosmed/slicer_ros2_module),
case by case, written here: the same calls and the same assertions, through the reference's
two entry points (a stand-in ``slicer`` module, reference_suite.py), with real VTK, against a
real daemon and real ROS peers. Where the reference spins a fixed 100 ms and then asserts,
these spin until what it waits for has come, then 100 ms more, then assert the same.

The turtlesim, parameter and service cases are in test_reference_suite_turtlesim.py."""

from __future__ import annotations

from typing import Iterator

import pytest

import slicer_client
from reference_suite import (TestObserverSubscriber, TestObserverTf2Lookup, slicer_standin,
                             spin_some, spin_until)
from support import RunningDaemon

pytestmark = pytest.mark.ros
vtk = pytest.importorskip("vtk", reason="the reference's cases build VTK objects (the test "
                          "extra installs vtk; 3D Slicer has it)")


@pytest.fixture
def slicer(daemon: RunningDaemon) -> Iterator[object]:
    client = slicer_client.connect("127.0.0.1", daemon.port)
    try:
        yield slicer_standin(client.logic)
    finally:
        client.close()


@pytest.fixture
def ros2Node(slicer) -> Iterator[object]:  # noqa: N802 - the reference's name
    node = slicer.mrmlScene.AddNewNodeByClass("vtkMRMLROS2NodeNode")
    node.Create("testNode")
    spin_some(slicer)
    yield node
    node.Destroy()
    spin_some(slicer)


class PubSub:
    """TestCreateAndAddPubSub's helpers, on one ROS node."""

    def __init__(self, slicer, ros2Node, type_name: str) -> None:  # noqa: N803
        self.slicer = slicer
        self.ros2Node = ros2Node
        self.testObs = TestObserverSubscriber()
        self.topic = "slicer_test_" + type_name.lower()
        self.testPub = ros2Node.CreateAndAddPublisherNode(type_name, self.topic)
        self.testSub = ros2Node.CreateAndAddSubscriberNode(type_name, self.topic)
        self.observerId = self.testSub.AddObserver("ModifiedEvent", self.testObs.Callback)
        spin_some(slicer)
        self.initSubMessageCount = self.testSub.GetNumberOfMessages()

    def generic_assertions(self) -> None:
        spin_until(self.slicer, lambda: self.testSub.GetNumberOfMessages()
                   > self.initSubMessageCount, "the message at the subscriber")
        finalSubMessageCount = self.testSub.GetNumberOfMessages()  # noqa: N806
        assert finalSubMessageCount - self.initSubMessageCount == 1, "Message not received"
        assert self.testSub.GetLastMessageYAML() == self.testObs.lastMessageYAML, \
            "Message not received correctly by observer"
        assert self.testObs.counter == 1, "Observer number of calls incorrect"

    def delete_pub_sub(self) -> None:
        self.testSub.RemoveObserver(self.observerId)
        assert self.ros2Node.RemoveAndDeletePublisherNode(self.topic), "Publisher not deleted"
        assert self.ros2Node.RemoveAndDeleteSubscriberNode(self.topic), "Subscriber not deleted"


def test_create_and_add_pub_sub_empty(slicer, ros2Node) -> None:  # noqa: N803
    case = PubSub(slicer, ros2Node, "Empty")
    sentString = ""  # noqa: N806
    case.testPub.Publish(sentString)
    case.generic_assertions()
    assert case.testSub.GetLastMessage() == sentString
    case.delete_pub_sub()


def test_create_and_add_pub_sub_string(slicer, ros2Node) -> None:  # noqa: N803
    case = PubSub(slicer, ros2Node, "String")
    sentString = "xkcd"  # noqa: N806
    case.testPub.Publish(sentString)
    case.generic_assertions()
    assert case.testSub.GetLastMessage() == sentString
    assert case.testSub.GetLastMessageYAML() == "data: xkcd\n"
    case.delete_pub_sub()


def test_create_and_add_pub_sub_matrix(slicer, ros2Node) -> None:  # noqa: N803
    case = PubSub(slicer, ros2Node, "Pose")
    sentMatrix = vtk.vtkMatrix4x4()  # noqa: N806
    sentMatrix.SetElement(2, 3, 3.1415)
    case.testPub.Publish(sentMatrix)
    case.generic_assertions()
    receivedMatrix = case.testSub.GetLastMessage()  # noqa: N806
    assert sentMatrix.GetElement(2, 3) == receivedMatrix.GetElement(2, 3)  # exact: lossless
    assert isinstance(receivedMatrix, vtk.vtkMatrix4x4)
    case.delete_pub_sub()


def test_create_and_add_pub_sub_double(slicer, ros2Node) -> None:  # noqa: N803
    case = PubSub(slicer, ros2Node, "Double")
    sentDouble = 3.1415  # noqa: N806
    case.testPub.Publish(sentDouble)
    spin_some(slicer)
    case.generic_assertions()
    assert case.testSub.GetLastMessage() == sentDouble
    case.delete_pub_sub()


def _filled(array, values):
    array.SetNumberOfValues(len(values))
    for i, value in enumerate(values):
        array.SetValue(i, value)
    return array


@pytest.mark.parametrize("type_name, array_type, sent", [
    ("IntArray", "vtkIntArray", [1, 2, 3, 4, 5]),
    ("DoubleArray", "vtkDoubleArray", [1.1, 2.2, 3.3, 4.4, 5.5])])
def test_create_and_add_pub_sub_int_and_double_array(slicer, ros2Node, type_name: str,  # noqa: N803
                                                     array_type: str, sent: list) -> None:
    """The reference's test_create_and_add_pub_sub_int_array and ..._double_array."""
    case = PubSub(slicer, ros2Node, type_name)
    sentArray = _filled(getattr(vtk, array_type)(), sent)  # noqa: N806
    case.testPub.Publish(sentArray)
    case.generic_assertions()
    received = case.testSub.GetLastMessage()
    assert isinstance(received, getattr(vtk, array_type))
    assert sentArray.GetNumberOfValues() == received.GetNumberOfValues()
    for i in range(sentArray.GetNumberOfValues()):
        assert sentArray.GetValue(i) == received.GetValue(i)
    case.delete_pub_sub()


def test_create_and_add_pub_sub_wrench_stamped(slicer, ros2Node) -> None:  # noqa: N803
    case = PubSub(slicer, ros2Node, "WrenchStamped")
    sentDoubleArray = [1.1, 2.2, 3.3, 4.4, 5.5, 6.6]  # noqa: N806
    sentWrenchStamped = case.testPub.GetBlankMessage()  # noqa: N806
    sentWrenchStamped.GetWrench().SetNumberOfValues(len(sentDoubleArray))
    for i, value in enumerate(sentDoubleArray):
        sentWrenchStamped.GetWrench().SetValue(i, value)
    case.testPub.Publish(sentWrenchStamped)
    case.generic_assertions()
    received = case.testSub.GetLastMessage()
    assert sentWrenchStamped.GetWrench().GetNumberOfValues() == \
        received.GetWrench().GetNumberOfValues()
    for i in range(sentWrenchStamped.GetWrench().GetNumberOfValues()):
        assert sentWrenchStamped.GetWrench().GetValue(i) == received.GetWrench().GetValue(i)
    case.delete_pub_sub()


def _pose(tx, ty, tz, r00, r01, r10, r11):
    pose = vtk.vtkMatrix4x4()
    for (row, col), value in {(0, 3): tx, (1, 3): ty, (2, 3): tz, (0, 0): r00, (0, 1): r01,
                              (1, 0): r10, (1, 1): r11}.items():
        pose.SetElement(row, col, value)
    return pose


def test_create_and_add_pub_sub_pose_array(slicer, ros2Node) -> None:  # noqa: N803
    case = PubSub(slicer, ros2Node, "PoseArray")
    samplePubMessage = case.testPub.GetBlankMessage()  # noqa: N806
    header = samplePubMessage.GetHeader()
    header.SetFrameId("test_frame")
    timestamp = header.GetStamp()
    timestamp.SetSec(123)
    timestamp.SetNanosec(456)
    # Three poses, rotations typed to three decimals as the reference's own test types them.
    poses = (_pose(1.0, 2.0, 3.0, 0, -1, 1, 0),
             _pose(4.0, 5.0, 6.0, 0.707, -0.707, 0.707, 0.707),
             _pose(7.0, 8.0, 9.0, 0.866, -0.5, 0.5, 0.866))
    samplePubMessage.SetPoses(poses)
    case.testPub.Publish(samplePubMessage)
    case.generic_assertions()
    receivedPoseArray = case.testSub.GetLastMessage()  # noqa: N806
    receivedHeader = receivedPoseArray.GetHeader()  # noqa: N806
    assert receivedHeader.GetFrameId() == "test_frame"
    assert receivedHeader.GetStamp().GetSec() == pytest.approx(123, abs=1e-3)
    assert receivedHeader.GetStamp().GetNanosec() == pytest.approx(456, abs=1e-3)
    assert len(receivedPoseArray.GetPoses()) == 3
    for i, sentPose in enumerate(poses):
        receivedPose = receivedPoseArray.GetPoses()[i]  # noqa: N806
        for row in range(4):
            for col in range(4):
                assert sentPose.GetElement(row, col) == pytest.approx(
                    receivedPose.GetElement(row, col), abs=5e-4), (i, row, col)
    case.delete_pub_sub()


def _table(array_type, columns):
    table = vtk.vtkTable()
    for values in columns:
        table.AddColumn(_filled(array_type(), values))
    return table


@pytest.mark.parametrize("type_name, array_type, columns", [
    ("IntTable", "vtkIntArray", [[3 * i for i in range(3)], [4 * i + 1 for i in range(3)]]),
    ("DoubleTable", "vtkDoubleArray", [[3.3 * i for i in range(3)],
                                       [4.4 * i + 1.1 for i in range(3)]])])
def test_create_and_add_pub_sub_int_and_double_n_array(slicer, ros2Node,  # noqa: N803
                                                       type_name: str, array_type: str,
                                                       columns: list) -> None:
    """The reference's test_create_and_add_pub_sub_int_n_array and ..._double_n_array."""
    case = PubSub(slicer, ros2Node, type_name)
    vtktable = _table(getattr(vtk, array_type), columns)
    case.testPub.Publish(vtktable)
    case.generic_assertions()
    received = case.testSub.GetLastMessage()
    assert vtktable.GetNumberOfColumns() == received.GetNumberOfColumns() == 2
    assert vtktable.GetNumberOfRows() == received.GetNumberOfRows() == 3
    for i in range(vtktable.GetNumberOfColumns()):
        for j in range(vtktable.GetNumberOfRows()):
            assert vtktable.GetValue(j, i) == received.GetValue(j, i)
    case.delete_pub_sub()


def test_pub_sub_deletion(slicer, ros2Node) -> None:  # noqa: N803
    ros2Node.CreateAndAddPublisherNode("vtkMRMLROS2PublisherStringNode", "test_string_xkcd")
    ros2Node.CreateAndAddSubscriberNode("vtkMRMLROS2SubscriberStringNode", "test_string_xkcd")
    assert ros2Node.RemoveAndDeletePublisherNode("test_string_xkcd"), \
        "Publisher which exists not removed"
    spin_some(slicer)
    assert not ros2Node.RemoveAndDeletePublisherNode("test_string_xkcd"), \
        "Publisher which used to exist removed"
    spin_some(slicer)
    assert not ros2Node.RemoveAndDeletePublisherNode("random_name"), \
        "Publisher which never existed removed"
    spin_some(slicer)
    assert ros2Node.RemoveAndDeleteSubscriberNode("test_string_xkcd"), \
        "Subscriber which exists not removed"
    spin_some(slicer)
    assert not ros2Node.RemoveAndDeleteSubscriberNode("test_string_xkcd"), \
        "Subscriber which used to exist removed"
    spin_some(slicer)
    assert not ros2Node.RemoveAndDeleteSubscriberNode("random_name"), \
        "Subscriber which never existed removed"


def test_broadcaster_functioning(slicer) -> None:
    ros2Node = slicer.mrmlScene.AddNewNodeByClass("vtkMRMLROS2NodeNode")  # noqa: N806
    ros2Node.Create("testNodeBroadcaster")
    spin_some(slicer)
    broadcaster = ros2Node.CreateAndAddTf2BroadcasterNode("Parent", "Child")
    lookupNode = ros2Node.CreateAndAddTf2LookupNode("Parent", "Child")  # noqa: N806
    observer = TestObserverTf2Lookup(vtk)
    observerId = lookupNode.AddObserver(  # noqa: N806
        slicer.vtkMRMLTransformNode.TransformModifiedEvent, observer.Callback)
    broadcastedMat = vtk.vtkMatrix4x4()  # noqa: N806
    broadcastedMat.SetElement(0, 3, 66)
    broadcaster.Broadcast(broadcastedMat)
    spin_until(slicer, lambda: observer.counter > 0, "the lookup to see the broadcast")
    lookupMat = vtk.vtkMatrix4x4()  # noqa: N806
    lookupNode.GetMatrixTransformToParent(lookupMat)
    assert lookupMat.GetElement(0, 3) == broadcastedMat.GetElement(0, 3)
    assert observer.counter > 1  # refreshed on every spin, as the reference's lookups are
    assert observer.lastTransform.GetElement(0, 3) == broadcastedMat.GetElement(0, 3)
    lookupNode.RemoveObserver(observerId)
    assert ros2Node.RemoveAndDeleteTf2LookupNode("Parent", "Child")
    assert not ros2Node.RemoveAndDeleteTf2LookupNode("Parent", "Child")
    assert ros2Node.RemoveAndDeleteTf2BroadcasterNode("Parent", "Child")
    assert not ros2Node.RemoveAndDeleteTf2BroadcasterNode("Parent", "Child")
    ros2Node.Destroy()

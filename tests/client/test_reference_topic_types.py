"""The reference facade's publishers and subscribers of the types its own unit tests leave
out (Wrench, Transform, tables fed from VTK tables, UInt8Image, images and point clouds by
any name), as a SlicerROS2 script calls them: real VTK values in, an independent rclpy echo
peer (another process) as the witness of what reaches ROS, and the facade's values back.
Also the errors such a script can hit: values of the wrong kind, a message object of
another type, a ragged table."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import slicer_client
from slicer_client.reference.messages import MessageValueError
from ros_echo import echo, until_received, until_got
from support import Processes

pytestmark = pytest.mark.ros
vtk = pytest.importorskip("vtk", reason="Slicer hands the facade VTK objects; the test "
                          "extra installs vtk")










def test_wrench_publisher_and_subscriber(rosLogic: Any, processes: Processes) -> None:
    rosNode = rosLogic.GetDefaultROS2Node()  # noqa: N806
    pub = rosNode.CreateAndAddPublisherNode("Wrench", "/tt_wrench")
    sub = rosNode.CreateAndAddSubscriberNode("vtkMRMLROS2SubscriberWrenchNode", "/tt_wrench")
    assert pub.GetROSType() == sub.GetROSType() == "geometry_msgs/msg/Wrench"
    blank = pub.GetBlankMessage()
    assert blank.GetClassName() == "vtkDoubleArray" and blank.GetNumberOfValues() == 6
    assert [blank.GetValue(i) for i in range(6)] == [0.0] * 6
    for i, value in enumerate((1.0, 2.0, 3.0, 0.1, 0.2, 0.3)):
        blank.SetValue(i, value)
    peer = echo(processes, "/tt_wrench", "geometry_msgs/msg/Wrench")
    assert until_received(lambda: pub.Publish(blank), peer) == {
        "force": {"x": 1.0, "y": 2.0, "z": 3.0}, "torque": {"x": 0.1, "y": 0.2, "z": 0.3}}
    got = until_got(pub, blank, sub, "the wrench back")
    assert isinstance(got, vtk.vtkDoubleArray)
    assert [got.GetValue(i) for i in range(6)] == [1.0, 2.0, 3.0, 0.1, 0.2, 0.3]
    # The node reads whole messages, so its client asked for no native values (issue 44:
    # each message once): none came, and the Pythonic reads of them say why.
    assert sub.GetNumberOfMessages() >= 1 and sub.resource.native is False
    assert sub.resource.count == 0 and sub.resource.last_message is None
    with pytest.raises(ValueError, match=r"last_value: this subscriber of /tt_wrench reads "
                                         r"its messages whole only \(native=False\)"):
        _ = sub.resource.last_value
    assert sub.GetSlicerType() == pub.GetSlicerType() == "vtkDoubleArray"
    # Not six values, or not numbers: refused before anything is sent, naming what came.
    sent = pub.GetNumberOfMessagesSent()
    with pytest.raises(MessageValueError, match="expected 6 values for geometry_msgs/msg/"
                                                "Wrench, got 3"):
        pub.Publish([1.0, 2.0, 3.0])
    with pytest.raises(MessageValueError, match=r"expected numbers, got None at 1"):
        pub.Publish([1.0, None, 3.0, 4.0, 5.0, 6.0])
    assert pub.GetNumberOfMessagesSent() == pub.GetNumberOfMessages() == sent
    assert pub.GetNumberOfCalls() > sent  # the refused calls count as calls


def test_transform_publisher_sends_metres_and_the_subscriber_fills_a_target(
        rosLogic: Any, processes: Processes) -> None:
    rosNode = rosLogic.GetDefaultROS2Node()  # noqa: N806
    pub = rosNode.CreateAndAddPublisherNode("Transform", "/tt_transform")
    sub = rosNode.CreateAndAddSubscriberNode("Transform", "/tt_transform")
    matrix = vtk.vtkMatrix4x4()
    matrix.SetElement(0, 3, 25.0)
    matrix.SetElement(2, 3, -4.0)
    peer = echo(processes, "/tt_transform", "geometry_msgs/msg/Transform")
    received = until_received(lambda: pub.Publish(matrix), peer)
    assert received["translation"] == {"x": pytest.approx(0.025), "y": 0.0,
                                       "z": pytest.approx(-0.004)}
    assert received["rotation"]["w"] == pytest.approx(1.0)
    until_got(pub, matrix, sub, "the transform back")
    # GetLastMessage(target) fills a vtkMatrix4x4 the script owns, as Slicer's getters do.
    target = vtk.vtkMatrix4x4()
    assert sub.GetLastMessage(target) is target
    assert target.GetElement(0, 3) == pytest.approx(25.0)
    assert target.GetElement(2, 3) == pytest.approx(-4.0)
    # Into something that is no matrix: a TypeError naming both kinds.
    with pytest.raises(TypeError, match=r"cannot fill a \S*vtkIntArray with a vtkMatrix4x4"):
        sub.GetLastMessage(vtk.vtkIntArray())
    assert "translation:" in sub.GetLastMessageYAML()
    assert sub.GetName() == "ros2:sub:/tt_transform" and sub.GetTopic() == "/tt_transform"
    assert pub.GetName() == "ros2:pub:/tt_transform" and pub.GetTopic() == "/tt_transform"
    assert sub.IsAddedToROS2Node() and pub.IsAddedToROS2Node()
    assert rosNode.RemoveAndDeletePublisherNode("/tt_transform")
    assert not pub.IsAddedToROS2Node()


def _int_array(values: list[int]) -> Any:
    array = vtk.vtkIntArray()
    for value in values:
        array.InsertNextValue(value)
    return array


def test_tables_from_vtk_tables_and_a_1d_array_read_as_a_table(rosLogic: Any,
                                                               processes: Processes) -> None:
    rosNode = rosLogic.GetDefaultROS2Node()  # noqa: N806
    pub = rosNode.CreateAndAddPublisherNode("IntTable", "/tt_table")
    assert pub.GetBlankMessage().GetClassName() == "vtkTable"
    table = vtk.vtkTable()
    table.AddColumn(_int_array([1, 2, 3]))
    table.AddColumn(_int_array([10, 20, 30]))
    peer = echo(processes, "/tt_table", "std_msgs/msg/Int64MultiArray")
    received = until_received(lambda: pub.Publish(table), peer)
    assert [d["size"] for d in received["layout"]["dim"]] == [3, 2]
    assert received["data"] == [1, 10, 2, 20, 3, 30]  # row by row
    with pytest.raises(MessageValueError, match=r"expected integers, got 1.5 at 0"):
        pub.Publish([[1.5, 2.0]])
    # A table subscriber on a topic of 1-D arrays gets an empty table, as the reference
    # fills a table only from a 2-D array.
    flat_pub = rosNode.CreateAndAddPublisherNode("IntArray", "/tt_flat")
    flat_sub = rosNode.CreateAndAddSubscriberNode("IntTable", "/tt_flat")
    got = until_got(flat_pub, _int_array([4, 5, 6]), flat_sub, "the 1-D array")
    assert isinstance(got, vtk.vtkTable) and got.GetNumberOfColumns() == 0
    assert flat_sub.GetLastMessageYAML().startswith("layout:")


def test_uint8_image_both_ways(rosLogic: Any, processes: Processes) -> None:
    """The reference's UInt8Image: a vtkTypeUInt8Array of one tuple per row."""
    rosNode = rosLogic.GetDefaultROS2Node()  # noqa: N806
    pub = rosNode.CreateAndAddPublisherNode("UInt8Image", "/tt_uint8")
    sub = rosNode.CreateAndAddSubscriberNode("UInt8Image", "/tt_uint8")
    image = pub.GetBlankMessage()
    assert image.GetClassName() == "vtkTypeUInt8Array"
    image.SetNumberOfComponents(3)  # 3 columns
    image.SetNumberOfTuples(2)  # 2 rows
    for i, byte in enumerate((0, 1, 2, 250, 251, 255)):
        image.SetValue(i, byte)
    peer = echo(processes, "/tt_uint8", "sensor_msgs/msg/Image")
    received = until_received(lambda: pub.Publish(image), peer)
    assert (received["height"], received["width"], received["encoding"]) == (2, 3, "mono8")
    assert received["data"] == [0, 1, 2, 250, 251, 255]
    got = until_got(pub, image, sub, "the image back")
    assert isinstance(got, vtk.vtkTypeUInt8Array)
    assert (got.GetNumberOfTuples(), got.GetNumberOfComponents()) == (2, 3)
    assert [got.GetValue(i) for i in range(6)] == [0, 1, 2, 250, 251, 255]
    # Its YAML is the header, sizes and encoding, not megabytes of pixels.
    yaml = sub.GetLastMessageYAML()
    assert "height: 2" in yaml and "width: 3" in yaml and "encoding: mono8" in yaml
    assert "data" not in yaml
    # An image subscriber counts what its native stream brought.
    assert sub.GetNumberOfMessages() >= 1
    # GetLastMessage(target) deep-copies into an array of the same class.
    target = vtk.vtkTypeUInt8Array()
    assert sub.GetLastMessage(target) is target and target.GetValue(5) == 255
    variant = sub.GetLastMessageVariant()
    assert isinstance(variant, vtk.vtkVariant)


def test_image_by_its_ros_name_is_numpy_pixels(rosLogic: Any, processes: Processes) -> None:
    """A name the reference does not have (sensor_msgs/msg/Image): the subscriber (whose
    daemon streams images natively, not whole) gives the Pythonic API's pixels, a (rows,
    columns, channels) uint8 array, and the publisher of the same name takes them."""
    rosNode = rosLogic.GetDefaultROS2Node()  # noqa: N806
    pub = rosNode.CreateAndAddPublisherNode("sensor_msgs/msg/Image", "/tt_rgb", "camera")
    sub = rosNode.CreateAndAddSubscriberNode("sensor_msgs/msg/Image", "/tt_rgb")
    blank = pub.GetBlankMessage()
    assert isinstance(blank, np.ndarray) and blank.dtype == np.uint8
    pixels = np.arange(2 * 4 * 3, dtype=np.uint8).reshape(2, 4, 3)
    peer = echo(processes, "/tt_rgb", "sensor_msgs/msg/Image")
    received = until_received(lambda: pub.Publish(pixels), peer)
    assert (received["height"], received["width"], received["encoding"]) == (2, 4, "rgb8")
    assert received["header"]["frame_id"] == "camera"
    assert received["data"] == pixels.reshape(-1).tolist()
    got = until_got(pub, pixels, sub, "the pixels back")
    assert isinstance(got, np.ndarray)
    np.testing.assert_array_equal(got.reshape(2, 4, 3), pixels)
    # An image has no message stream: its native one is whole, and the node reads it.
    assert sub.resource.native is True and sub.resource.message_device == ""
    assert sub.resource.count >= 1
    yaml = sub.GetLastMessageYAML()
    assert "frame_id: camera" in yaml and "encoding: rgb8" in yaml
    with pytest.raises(ValueError, match=r"expected uint8 pixels .* got shape \(2, 4, 2\)"):
        pub.Publish(np.zeros((2, 4, 2), dtype=np.uint8))


def test_point_clouds_as_vtk_points(rosLogic: Any, processes: Processes) -> None:
    rosNode = rosLogic.GetDefaultROS2Node()  # noqa: N806
    pub = rosNode.CreateAndAddPublisherNode("PointCloud", "/tt_cloud")
    sub = rosNode.CreateAndAddSubscriberNode("PointCloud", "/tt_cloud")
    points = pub.GetBlankMessage()
    assert isinstance(points, vtk.vtkPoints)
    points.InsertNextPoint(1000.0, 0.0, 0.0)
    points.InsertNextPoint(0.0, 500.0, -250.0)
    peer = echo(processes, "/tt_cloud", "sensor_msgs/msg/PointCloud")
    received = until_received(lambda: pub.Publish(points), peer)
    assert [[p["x"], p["y"], p["z"]] for p in received["points"]] == [
        [1.0, 0.0, 0.0], [0.0, 0.5, -0.25]]
    got = until_got(pub, points, sub, "the cloud back")
    assert isinstance(got, vtk.vtkPoints) and got.GetNumberOfPoints() == 2
    np.testing.assert_allclose(got.GetPoint(1), (0.0, 500.0, -250.0), atol=1e-3)
    assert "points: 2" in sub.GetLastMessageYAML()
    # A PointCloud2 publisher takes an (N, 3) array in mm too; a subscriber by the ROS name
    # gives vtkPoints as well (its daemon streams clouds natively).
    pub2 = rosNode.CreateAndAddPublisherNode("PointCloud2", "/tt_cloud2")
    sub2 = rosNode.CreateAndAddSubscriberNode("sensor_msgs/msg/PointCloud2", "/tt_cloud2")
    got2 = until_got(pub2, np.array([[10.0, 20.0, 30.0]]), sub2, "the PointCloud2 back")
    assert got2.GetNumberOfPoints() == 1
    np.testing.assert_allclose(got2.GetPoint(0), (10.0, 20.0, 30.0), atol=1e-3)


def test_scalars_refuse_values_of_the_wrong_kind(rosLogic: Any) -> None:
    rosNode = rosLogic.GetDefaultROS2Node()  # noqa: N806
    for name, ros_type, bad, words in (
            ("Int", "std_msgs/msg/Int64", "7", "an integer in int64's range"),
            ("Int", "std_msgs/msg/Int64", 2**63, "an integer in int64's range"),
            ("Bool", "std_msgs/msg/Bool", "yes", "true or false"),
            ("Double", "std_msgs/msg/Float64", True, "a number"),
            ("String", "std_msgs/msg/String", 3, "a string")):
        pub = rosNode.CreateAndAddPublisherNode(name, f"/tt_bad_{name.lower()}")
        with pytest.raises(MessageValueError) as error:
            pub.Publish(bad)
        assert str(error.value) == f"Publish: expected {words} for {ros_type}, got {bad!r}"
    empty = rosNode.CreateAndAddPublisherNode("Empty", "/tt_empty")
    assert empty.GetBlankMessage() == ""
    assert empty.GetSlicerType() == "std::string"
    assert rosNode.CreateAndAddPublisherNode("Int", "/tt_bad_int").GetSlicerType() == "int"


def test_message_objects_of_another_type_or_as_plain_dicts(rosLogic: Any,
                                                           processes: Processes) -> None:
    rosNode = rosLogic.GetDefaultROS2Node()  # noqa: N806
    pub = rosNode.CreateAndAddPublisherNode("PoseStamped", "/tt_stamped")
    other = rosNode.CreateAndAddPublisherNode("PoseArray", "/tt_other").GetBlankMessage()
    with pytest.raises(MessageValueError, match="expected a geometry_msgs/msg/PoseStamped "
                                                "message, got a geometry_msgs/msg/PoseArray"):
        pub.Publish(other)
    with pytest.raises(MessageValueError, match="expected a geometry_msgs/msg/PoseStamped "
                                                "message object .*got int"):
        pub.Publish(5)
    with pytest.raises(MessageValueError, match="got list"):
        pub.Publish([[1, 2], [3]])  # not a 4x4 (np.shape cannot even tell a shape)
    # The generic JSON of the message (ROS units) is taken as it is.
    peer = echo(processes, "/tt_stamped", "geometry_msgs/msg/PoseStamped")
    received = until_received(lambda: pub.Publish(
        {"header": {"frame_id": "dict_frame"}, "pose": {"position": {"x": 1.5}}}), peer)
    assert received["header"]["frame_id"] == "dict_frame"
    assert received["pose"]["position"]["x"] == 1.5
    assert pub.GetSlicerType() == "vtkGeometryMsgsPoseStamped" or \
        pub.GetSlicerType().startswith("vtk")


def test_subscriber_observers_and_events(rosLogic: Any) -> None:
    rosNode = rosLogic.GetDefaultROS2Node()  # noqa: N806
    sub = rosNode.CreateAndAddSubscriberNode("String", "/tt_observed")
    with pytest.raises(ValueError, match="SubscriberNode.AddObserver: expected one of "
                                         "ModifiedEvent, got 'TransformModifiedEvent'"):
        sub.AddObserver("TransformModifiedEvent", lambda caller, event: None)
    assert not sub.HasObserver(33)
    tag = sub.AddObserver(33, lambda caller, event: None)
    assert sub.HasObserver("ModifiedEvent")
    sub.RemoveObserver(tag)
    assert not sub.HasObserver("ModifiedEvent")
    assert sub.GetBlankMessage() == "" and sub.GetLastMessageVariant() is None
    assert sub.GetLastMessageYAML() == ""
    assert sub.GetSlicerType() == "std::string"



def test_a_short_name_the_daemon_knows_makes_a_node(ros: slicer_client.Client) -> None:
    """Issue 43, item 10: the facade refused `Float32` before asking the daemon (it knew
    only the reference's short names); the daemon resolves it among installed types."""
    node = ros.GetDefaultROS2Node()
    subscriber = node.CreateAndAddSubscriberNode("Float32", "/short_float32")
    publisher = node.CreateAndAddPublisherNode("Float32", "/short_float32_out")
    assert subscriber.GetROSType() == publisher.GetROSType() == "std_msgs/msg/Float32"

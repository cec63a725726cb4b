"""The reference facade where vtk does not import: ``ROS2Logic(client, vtk=False)`` hands
out plain objects with VTK's methods (vtk_values.py, matrices.Matrix4x4) instead of VTK's,
and a script written for SlicerROS2 runs on them unchanged. Each value is filled the way
such a script fills a VTK one, published through a real daemon to an rclpy echo peer in
another process (the witness), and read back from a facade subscriber."""

from __future__ import annotations

from typing import Any, Iterator

import numpy as np
import pytest

import slicer_client
from slicer_client.matrices import Matrix4x4, MatrixError, as_numpy
from slicer_client.reference.logic import ROS2Logic
from slicer_client.reference.messages import MessageValueError
from slicer_client.reference.vtk_values import (DoubleArray, IntArray, Points, Table,
                                                TypeUInt8Array)
from ros_echo import echo, until_received, until_got
from support import Processes, RunningDaemon

pytestmark = pytest.mark.ros


@pytest.fixture
def rosNode(daemon: RunningDaemon) -> Iterator[Any]:  # noqa: N802 - the reference's name
    client = slicer_client.connect("127.0.0.1", daemon.port)
    try:
        yield ROS2Logic(client, vtk=False).GetDefaultROS2Node()
    finally:
        client.close()








def test_int_array_filled_as_a_vtk_array_is(rosNode: Any, processes: Processes) -> None:  # noqa: N803
    pub = rosNode.CreateAndAddPublisherNode("IntArray", "/pv_ints")
    sub = rosNode.CreateAndAddSubscriberNode("IntArray", "/pv_ints")
    array = pub.GetBlankMessage()
    assert type(array) is IntArray and array.GetClassName() == "vtkIntArray"
    assert array.IsA("vtkDataArray") and array.IsA("vtkIntArray") and not array.IsA("vtkTable")
    array.SetName("counts")
    assert array.GetName() == "counts"
    assert array.InsertNextValue(4.0) == 0 and array.InsertNextValue(5) == 1
    array.InsertValue(3, 7)  # past the end: grows, the gap is 0
    assert [array.GetValue(i) for i in range(array.GetNumberOfValues())] == [4, 5, 0, 7]
    array.SetNumberOfComponents(2)
    assert array.GetNumberOfTuples() == 2 and array.GetTuple(1) == (0.0, 7.0)
    assert repr(array) == "vtkIntArray([4, 5, 0, 7])"
    peer = echo(processes, "/pv_ints", "std_msgs/msg/Int64MultiArray")
    assert until_received(lambda: pub.Publish(array), peer)["data"] == [4, 5, 0, 7]
    got = until_got(pub, array, sub, "the ints back")
    assert type(got) is IntArray
    assert [got.GetValue(i) for i in range(got.GetNumberOfValues())] == [4, 5, 0, 7]
    # GetLastMessage(target): copied into an array of the script's.
    target = IntArray()
    assert sub.GetLastMessage(target) is target
    assert [target.GetValue(i) for i in range(target.GetNumberOfValues())] == [4, 5, 0, 7]
    # Without vtk there is no vtkVariant: the value itself.
    assert type(sub.GetLastMessageVariant()) is IntArray
    array.Initialize()
    assert array.GetNumberOfValues() == 0


def test_double_table_rows_and_columns(rosNode: Any, processes: Processes) -> None:  # noqa: N803
    pub = rosNode.CreateAndAddPublisherNode("DoubleTable", "/pv_table")
    sub = rosNode.CreateAndAddSubscriberNode("DoubleTable", "/pv_table")
    table = pub.GetBlankMessage()
    assert type(table) is Table and table.GetClassName() == "vtkTable"
    assert table.GetNumberOfRows() == 0
    table.AddColumn(DoubleArray())
    table.AddColumn(DoubleArray())
    table.SetNumberOfRows(2)
    for row in range(2):
        for col in range(2):
            table.SetValue(row, col, 10 * row + col + 0.5)
    assert table.GetValue(1, 0) == 10.5 and table.GetNumberOfRows() == 2
    assert repr(table) == "vtkTable([[0.5, 10.5], [1.5, 11.5]])"
    peer = echo(processes, "/pv_table", "std_msgs/msg/Float64MultiArray")
    received = until_received(lambda: pub.Publish(table), peer)
    assert received["data"] == [0.5, 1.5, 10.5, 11.5]
    got = until_got(pub, table, sub, "the table back")
    assert type(got) is Table and got.GetNumberOfColumns() == 2
    assert [[got.GetValue(r, c) for c in range(2)] for r in range(2)] == [[0.5, 1.5],
                                                                          [10.5, 11.5]]
    target = Table()
    assert sub.GetLastMessage(target) is target and target.GetValue(1, 1) == 11.5
    # Columns of different lengths are no table: refused, with both lengths.
    ragged = Table()
    ragged.AddColumn(DoubleArray())
    ragged.AddColumn(DoubleArray())
    ragged.GetColumn(0).InsertNextValue(1.0)
    with pytest.raises(MessageValueError, match=r"columns of one length, got \[1, 0\]"):
        pub.Publish(ragged)


def test_points_as_a_script_fills_vtk_points(rosNode: Any, processes: Processes) -> None:  # noqa: N803
    pub = rosNode.CreateAndAddPublisherNode("PointCloud", "/pv_cloud")
    sub = rosNode.CreateAndAddSubscriberNode("PointCloud", "/pv_cloud")
    points = pub.GetBlankMessage()
    assert type(points) is Points and points.GetClassName() == "vtkPoints"
    points.Allocate(3)
    points.InsertNextPoint((1.0, 2.0, 3.0))  # VTK's Python also takes one tuple
    points.Reset()
    assert points.GetNumberOfPoints() == 0
    points.SetNumberOfPoints(2)
    points.SetPoint(0, 1000.0, 0.0, 0.0)
    points.SetPoint(1, [0.0, 0.0, 250.0])
    peer = echo(processes, "/pv_cloud", "sensor_msgs/msg/PointCloud")
    received = until_received(lambda: pub.Publish(points), peer)
    assert [[p["x"], p["y"], p["z"]] for p in received["points"]] == [[1.0, 0.0, 0.0],
                                                                      [0.0, 0.0, 0.25]]
    got = until_got(pub, points, sub, "the points back")
    assert type(got) is Points and got.GetNumberOfPoints() == 2
    np.testing.assert_allclose(got.GetPoint(1), (0.0, 0.0, 250.0), atol=1e-3)
    target = Points()
    assert sub.GetLastMessage(target) is target and target.GetNumberOfPoints() == 2


def test_uint8_image_refuses_a_value_that_is_no_byte(rosNode: Any,  # noqa: N803
                                                     processes: Processes) -> None:
    pub = rosNode.CreateAndAddPublisherNode("UInt8Image", "/pv_image")
    sub = rosNode.CreateAndAddSubscriberNode("UInt8Image", "/pv_image")
    image = pub.GetBlankMessage()
    assert type(image) is TypeUInt8Array and image.GetClassName() == "vtkTypeUInt8Array"
    image.SetNumberOfComponents(2)
    image.SetNumberOfTuples(2)
    with pytest.raises(ValueError, match=r"expected a value in 0..255, got 300"):
        image.SetValue(0, 300)
    for i, byte in enumerate((1, 2, 3, 255)):
        image.SetValue(i, byte)
    peer = echo(processes, "/pv_image", "sensor_msgs/msg/Image")
    received = until_received(lambda: pub.Publish(image), peer)
    assert (received["height"], received["width"], received["data"]) == (2, 2, [1, 2, 3, 255])
    got = until_got(pub, image, sub, "the image back")
    assert type(got) is TypeUInt8Array
    assert (got.GetNumberOfTuples(), got.GetNumberOfComponents()) == (2, 2)
    assert [got.GetValue(i) for i in range(4)] == [1, 2, 3, 255]


def test_pose_matrices_without_vtk(rosNode: Any, processes: Processes) -> None:  # noqa: N803
    pub = rosNode.CreateAndAddPublisherNode("Pose", "/pv_pose")
    sub = rosNode.CreateAndAddSubscriberNode("Pose", "/pv_pose")
    matrix = pub.GetBlankMessage()
    assert type(matrix) is Matrix4x4
    matrix.SetElement(0, 3, 99.0)
    matrix.Identity()  # back to the identity, as vtkMatrix4x4.Identity
    assert matrix.GetElement(0, 3) == 0.0
    copy = Matrix4x4()
    source = np.eye(4)
    source[1, 3] = 42.0
    copy.DeepCopy(source)
    assert repr(copy).startswith("Matrix4x4([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 42.0]")
    assert np.asarray(copy, dtype=np.float32).dtype == np.float32
    peer = echo(processes, "/pv_pose", "geometry_msgs/msg/Pose")
    assert until_received(lambda: pub.Publish(copy), peer)["position"]["y"] == \
        pytest.approx(0.042)
    got = until_got(pub, copy, sub, "the pose back")
    assert type(got) is Matrix4x4
    np.testing.assert_allclose(np.asarray(got), source, atol=1e-9)
    target = Matrix4x4()
    assert sub.GetLastMessage(target) is target
    assert target.GetElement(1, 3) == pytest.approx(42.0)
    # Something that is not a matrix is refused naming what came.
    with pytest.raises(MatrixError, match=r"expected a 4x4 matrix .*got str"):
        as_numpy("not a matrix")
    with pytest.raises(MessageValueError):
        pub.Publish([[1.0, 2.0], [3.0]])


def test_int_array_out_of_int64_or_not_numbers_is_refused(rosNode: Any) -> None:  # noqa: N803
    pub = rosNode.CreateAndAddPublisherNode("IntArray", "/pv_refused")
    with pytest.raises(MessageValueError, match=r"expected numbers, got True at 0"):
        pub.Publish([True, False])
    with pytest.raises(MessageValueError, match=r"expected integers, got 2.5 at 1"):
        pub.Publish([1, 2.5])
    assert pub.GetNumberOfMessagesSent() == 0

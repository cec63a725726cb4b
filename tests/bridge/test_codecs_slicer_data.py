"""Slicer models and markups -> ROS codecs: POLYDATA -> shape_msgs/Mesh and Marker
TRIANGLE_LIST, POINT -> PoseArray / PointStamped per point, POINT or a polyline -> Path.
Values in metres are checked against numbers computed here (mm / 1000), bodies go through
their wire bytes (pack/unpack) as they would from Slicer."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bridge.codecs import CodecError, codec_for
from bridge.codecs.slicer_data import MAX_MESH_TRIANGLES, fan_triangles
from protocol.messages import Point, PointElement, PolyData, String, cells_from_array

pytestmark = pytest.mark.ros

SQUARE_MM = np.array([[0, 0, 0], [100, 0, 0], [100, 50, 0], [0, 50, 0]], dtype=np.float32)


def _wire(body):
    """As the daemon receives it: packed and unpacked again."""
    return type(body).unpack(body.pack())


def _flat(*cells: list[int]) -> np.ndarray:
    out: list[int] = []
    for cell in cells:
        out += [len(cell), *cell]
    return np.asarray(out, dtype=np.uint32)


def _xyz(points) -> list[tuple[float, float, float]]:
    return [(p.x, p.y, p.z) for p in points]


def test_a_quad_becomes_two_triangles_of_a_mesh_in_metres() -> None:
    body = _wire(PolyData(points=SQUARE_MM, polygons=_flat([0, 1, 2, 3])))
    mesh = codec_for("shape_msgs/msg/Mesh").from_igtl(body)
    assert _xyz(mesh.vertices) == [(0, 0, 0), (0.1, 0, 0), (0.1, 0.05, 0), (0, 0.05, 0)]
    assert [list(t.vertex_indices) for t in mesh.triangles] == [[0, 1, 2], [0, 2, 3]]


def test_mixed_polygons_fan_in_order() -> None:
    pts = np.zeros((7, 3), dtype=np.float32)
    body = PolyData(points=pts, polygons=_flat([0, 1, 2], [2, 3, 4, 5, 6]))
    assert fan_triangles(body, 10).tolist() == [[0, 1, 2], [2, 3, 4], [2, 4, 5], [2, 5, 6]]


def test_mesh_round_trip_is_lossless_at_float32() -> None:
    codec = codec_for("shape_msgs/msg/Mesh")
    body = _wire(PolyData(points=SQUARE_MM, polygons=cells_from_array(
        np.array([[0, 1, 2], [0, 2, 3]]))))
    mesh = codec.from_igtl(body)
    back = _wire(codec.to_igtl(mesh))
    np.testing.assert_array_equal(back.points, SQUARE_MM)
    np.testing.assert_array_equal(back.polygons, body.polygons)
    assert codec.encode(mesh).metadata["ros2.units"] == "mm"
    assert codec.from_value(codec.to_value(mesh)) == mesh


@pytest.mark.parametrize("body, field, words", [
    (PolyData(points=SQUARE_MM, triangle_strips=_flat([0, 1, 2, 3])),
     "body.triangle_strips", "strips are not converted"),
    (PolyData(points=SQUARE_MM, polygons=_flat([0, 1])), "body.polygons[0]", "3 or more"),
    (PolyData(points=SQUARE_MM, lines=_flat([0, 1, 2])), "body.polygons", "nav_msgs/Path"),
    (PolyData(points=np.array([[0, 0, 0], [1, 0, 0], [np.nan, 0, 0]], dtype=np.float32),
              polygons=_flat([0, 1, 2])), "body.points[2]", "finite"),
])
def test_bad_models_are_refused_naming_the_part(body, field, words) -> None:
    with pytest.raises(CodecError) as caught:
        codec_for("shape_msgs/msg/Mesh").from_igtl(_wire(body))
    assert caught.value.field == field
    assert words in str(caught.value)


def test_a_model_beyond_the_triangle_limit_is_refused() -> None:
    n = MAX_MESH_TRIANGLES + 1
    body = PolyData(points=np.zeros((3, 3), dtype=np.float32),
                    polygons=cells_from_array(np.tile([0, 1, 2], (n, 1))))
    with pytest.raises(CodecError, match=f"at most {MAX_MESH_TRIANGLES} triangles"):
        codec_for("shape_msgs/msg/Mesh").from_igtl(body)


def test_wrong_body_type_is_refused() -> None:
    with pytest.raises(CodecError, match="POLYDATA"):
        codec_for("shape_msgs/msg/Mesh").from_igtl(String("x"))


def test_marker_triangle_list_with_frame_ns_id_and_colour() -> None:
    codec = codec_for("visualization_msgs/msg/Marker")
    body = _wire(PolyData(points=SQUARE_MM, polygons=_flat([0, 1, 2, 3])))
    marker = codec.from_igtl(body, stamp=(7, 8), frame_id="patient", metadata={
        "ros2.ns": "liver", "ros2.id": "4", "ros2.color": "1 0.5 0 0.8"})
    assert marker.type == marker.TRIANGLE_LIST and marker.action == marker.ADD
    assert (marker.header.frame_id, marker.header.stamp.sec) == ("patient", 7)
    assert (marker.ns, marker.id) == ("liver", 4)
    assert (marker.scale.x, marker.scale.y, marker.scale.z) == (1, 1, 1)
    assert marker.pose.orientation.w == 1.0
    assert (marker.color.r, marker.color.g, marker.color.b) == (1.0, 0.5, 0.0)
    assert marker.color.a == pytest.approx(0.8)
    expected = SQUARE_MM.astype(np.float64)[[0, 1, 2, 0, 2, 3]] / 1000.0
    np.testing.assert_allclose(_xyz(marker.points), expected)
    # A STRING body still carries the generic JSON, both ways.
    assert codec.from_igtl(_wire(codec.to_igtl(marker))) == marker


@pytest.mark.parametrize("metadata, field", [
    ({"ros2.color": "1 0 0"}, "metadata.ros2.color"),
    ({"ros2.color": "2 0 0 1"}, "metadata.ros2.color"),
    ({"ros2.id": "x"}, "metadata.ros2.id"),
])
def test_marker_metadata_is_checked(metadata, field) -> None:
    body = PolyData(points=SQUARE_MM, polygons=_flat([0, 1, 2]))
    with pytest.raises(CodecError) as caught:
        codec_for("visualization_msgs/msg/Marker").from_igtl(body, metadata=metadata)
    assert caught.value.field == field


def _markups() -> Point:
    return _wire(Point([PointElement(name="entry", position=np.array([10.0, -20.0, 30.0])),
                        PointElement(name="target", position=np.array([1.5, 2.5, -3.5]))]))


def test_markups_become_a_pose_array_in_metres() -> None:
    poses = codec_for("PoseArray").from_igtl(_markups(), frame_id="ras")
    assert poses.header.frame_id == "ras"
    assert [(p.position.x, p.position.y, p.position.z) for p in poses.poses] == [
        (0.01, -0.02, 0.03), (0.0015, 0.0025, -0.0035)]
    assert all(p.orientation.w == 1.0 for p in poses.poses)


def test_markups_become_one_point_stamped_each() -> None:
    codec = codec_for("PointStamped")
    msgs = codec.from_igtl_all(_markups(), stamp=(3, 0), frame_id="ras")
    assert [(m.point.x, m.point.y, m.point.z) for m in msgs] == [
        (0.01, -0.02, 0.03), (0.0015, 0.0025, -0.0035)]
    assert {m.header.frame_id for m in msgs} == {"ras"}
    with pytest.raises(CodecError, match="one point"):
        codec.from_igtl(_markups())


def test_markups_with_nan_are_refused() -> None:
    body = Point([PointElement(name="a", position=np.array([0.0, math.inf, 0.0]))])
    with pytest.raises(CodecError) as caught:
        codec_for("PoseArray").from_igtl(_wire(body))
    assert caught.value.field == "body.points[0]"


def test_a_curve_polyline_becomes_a_path_in_line_order() -> None:
    pts = np.array([[0, 0, 0], [30, 0, 0], [10, 0, 0], [20, 0, 0]], dtype=np.float32)
    body = _wire(PolyData(points=pts, lines=_flat([0, 2, 3, 1])))
    path = codec_for("nav_msgs/msg/Path").from_igtl(body, stamp=(5, 6), frame_id="ras")
    assert [p.pose.position.x for p in path.poses] == [0.0, 0.01, 0.02, 0.03]
    assert {(p.header.frame_id, p.header.stamp.sec) for p in path.poses} == {("ras", 5)}
    with pytest.raises(CodecError, match="exactly one polyline"):
        codec_for("nav_msgs/msg/Path").from_igtl(PolyData(points=pts, lines=_flat([0, 1],
                                                                                 [2, 3])))


def test_a_line_of_markups_becomes_a_path() -> None:
    path = codec_for("nav_msgs/msg/Path").from_igtl(_markups(), frame_id="ras")
    assert [(p.pose.position.x, p.pose.position.z) for p in path.poses] == [
        (0.01, 0.03), (0.0015, -0.0035)]


@pytest.mark.parametrize("frame, ns", [("patient", "liver"), ("", "slicer"), ("p", "a"),
                                       ("bras_droit_é", "x" * 9)])
def test_the_serialized_path_gives_the_same_messages(frame: str, ns: str) -> None:
    """What the daemon publishes (CDR built with numpy) deserializes to the message the
    object path builds, whatever the string lengths before the bulk (alignment)."""
    from rclpy.serialization import deserialize_message

    rng = np.random.default_rng(1)
    points = rng.uniform(-100, 100, (50, 3)).astype(np.float32)
    body = _wire(PolyData(points=points, polygons=_flat(*[
        list(rng.choice(50, size=k, replace=False)) for k in (3, 4, 5, 3)])))
    metadata = {"ros2.ns": ns, "ros2.id": "-7", "ros2.color": "0 1 0 0.5"}
    for ros_type in ("shape_msgs/msg/Mesh", "visualization_msgs/msg/Marker"):
        codec = codec_for(ros_type)
        msg = codec.from_igtl(body, stamp=(11, 12), frame_id=frame, metadata=metadata)
        made = codec.from_igtl_raw(body, stamp=(11, 12), frame_id=frame, metadata=metadata)
        assert made is not None
        data, probe = made
        assert deserialize_message(data, type(msg)) == msg
        if hasattr(probe, "header"):  # what the guards judge
            assert probe.header.frame_id == frame and not probe.points


def test_the_serialized_path_refuses_as_the_object_path() -> None:
    body = PolyData(points=SQUARE_MM, triangle_strips=_flat([0, 1, 2, 3]))
    with pytest.raises(CodecError, match="strips"):
        codec_for("shape_msgs/msg/Mesh").from_igtl_raw(body)
    assert codec_for("nav_msgs/msg/Path").from_igtl_raw(body) is None  # no such path

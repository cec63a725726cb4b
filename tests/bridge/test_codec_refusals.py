"""Codec refusals a client or a ROS peer can provoke, each naming the bad part: the generic
JSON codec's field checks (bytes, times, integer and float32 ranges, nesting), a codec that
does not implement a direction, and the Slicer model / markups codecs' limits. Real rclpy
message classes and real numpy; bodies go through their wire bytes as from Slicer."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from bridge.codecs import CodecError, codec_for, dict_to_message, message_to_dict
from bridge.codecs.base import TypeCodec, make_header
from bridge.codecs.generic import check_float, describe_message, list_of, numeric_array
from bridge.codecs.slicer_data import MAX_MARKUP_POINTS, MAX_MESH_TRIANGLES, MAX_PATH_POINTS
from protocol.conversions import ConversionError
from protocol.messages import Point, PointElement, PolyData, String, Transform, unpack_body

pytestmark = pytest.mark.ros


def _wire(body: Any) -> Any:
    return unpack_body(body.TYPE, body.pack())


def _refusal(call: Any) -> CodecError:
    with pytest.raises(CodecError) as caught:
        call()
    return caught.value


# ------------------------------------------------------------------ generic JSON codec

def test_byte_fields_take_bytes_and_refuse_other_values() -> None:
    pv = dict_to_message("rcl_interfaces/msg/ParameterValue", {"byte_array_value": b"ab"})
    assert pv.byte_array_value == [b"a", b"b"]
    # rclpy keeps bytes assigned to a byte[] field as bytes: written as base64 all the same.
    from rcl_interfaces.msg import ParameterValue

    assert message_to_dict(ParameterValue(byte_array_value=b"abc"))["byte_array_value"] == "YWJj"
    assert message_to_dict(ParameterValue(byte_array_value=b"abc"),
                           bytes_as="list")["byte_array_value"] == [97, 98, 99]
    err = _refusal(lambda: dict_to_message(ParameterValue, {"byte_array_value": 5}))
    assert (err.field, err.got) == ("byte_array_value", "int 5")
    assert "base64" in err.expected
    status = dict_to_message("diagnostic_msgs/msg/DiagnosticStatus", {"level": b"\x02"})
    assert status.level == b"\x02"


def test_byte_constants_are_described_as_numbers() -> None:
    from diagnostic_msgs.msg import DiagnosticStatus

    described: dict[str, Any] = {}
    assert describe_message(DiagnosticStatus, described) == "diagnostic_msgs/msg/DiagnosticStatus"
    assert described["diagnostic_msgs/msg/DiagnosticStatus"].constants == {
        "OK": 0, "WARN": 1, "ERROR": 2, "STALE": 3}
    assert "diagnostic_msgs/msg/KeyValue" in described  # its nested type too


def test_times_in_seconds_round_up_and_refuse_nan() -> None:
    info = dict_to_message("action_msgs/msg/GoalInfo", {"stamp": 1.9999999999})
    assert (info.stamp.sec, info.stamp.nanosec) == (2, 0)
    err = _refusal(lambda: dict_to_message("action_msgs/msg/GoalInfo", {"stamp": float("nan")}))
    assert (err.field, err.expected) == ("stamp", "a finite number")
    err = _refusal(lambda: check_float(float("inf"), "value", finite=True))
    assert err.got == "inf"


@pytest.mark.parametrize("ros_type, value, field, words", [
    ("std_msgs/msg/UInt16MultiArray", {"data": np.array([1, 70000], dtype=np.uint32)},
     "data[1]", "[0, 65535]"),
    ("std_msgs/msg/Int16MultiArray", {"data": np.array([1.0, 70000.0])},
     "data[1]", "[-32768, 32767]"),
    ("sensor_msgs/msg/BatteryState", {"cell_voltage": [1.0, 1e39]},
     "cell_voltage[1]", "float32 range"),
    ("std_msgs/msg/Float64MultiArray", {"data": [[1.0]]}, "data", "1-D list"),
    ("std_msgs/msg/Float64MultiArray", {"data": [1.0, 2**70]}, "data[1]", "a number"),
    ("std_msgs/msg/Int64MultiArray", {"data": [2**70, 1]}, "data[0]", "(int64)"),
    ("std_msgs/msg/Float64", {"data": "a" * 200}, "data", "a number"),
])
def test_array_values_name_the_element(ros_type: str, value: dict[str, Any], field: str,
                                       words: str) -> None:
    err = _refusal(lambda: dict_to_message(ros_type, value))
    assert err.field == field
    assert words in err.expected
    assert len(err.got) <= 80  # long values are cut in the message a user sees


def test_huge_unsigned_integers_next_to_numpy_ones_are_kept_exactly() -> None:
    arr = numeric_array([np.int64(1), 2**63], "data", "uint64")
    assert arr.dtype == np.uint64 and arr.tolist() == [1, 2**63]


def test_a_non_message_and_a_non_list_are_refused() -> None:
    err = _refusal(lambda: message_to_dict({"data": 1}))
    assert (err.field, err.got) == ("message", "dict")
    err = _refusal(lambda: list_of(5, "value.points"))
    assert (err.field, err.expected, err.got) == ("value.points", "a list", "int 5")
    assert list_of((1, 2), "value.points") == [1, 2]


# ------------------------------------------------------------------ base codec

def test_a_codec_without_a_direction_answers_codec_errors() -> None:
    from std_msgs.msg import String as RosString

    bare = TypeCodec("std_msgs/msg/String", "STRING")
    for call, field in [(lambda: bare.to_value(RosString()), "message"),
                        (lambda: bare.from_value("x"), "value"),
                        (lambda: bare.encode(RosString()), "message"),
                        (lambda: bare.from_igtl(String("x")), "body")]:
        err = _refusal(call)
        assert err.field == field
        assert err.expected == "data convertible as std_msgs/msg/String"
        assert err.got.startswith("NotImplementedError")


def test_a_lower_layer_error_is_renamed_under_value() -> None:
    class Strict(TypeCodec):
        def _from_value(self, value: Any) -> Any:
            raise ConversionError("matrix", "a 4x4 matrix", repr(value))

    err = _refusal(lambda: Strict("std_msgs/msg/String", "STRING").from_value([1]))
    assert (err.field, err.expected, err.got) == ("value.matrix", "a 4x4 matrix", "[1]")


@pytest.mark.parametrize("stamp, frame, field, words", [
    ((1, 2), 7, "frame_id", "a string"),
    ((1.5, 2), "map", "stamp", "integers"),
    ((True, 2), "map", "stamp", "integers"),
    ((2**31, 0), "map", "stamp", "sec in int32"),
    ((0, 1_000_000_000), "map", "stamp", "nanosec in [0, 1e9)"),
    ("now", "map", "stamp", "builtin_interfaces/Time"),
])
def test_a_callers_stamp_and_frame_are_checked(stamp: Any, frame: Any, field: str,
                                               words: str) -> None:
    err = _refusal(lambda: make_header(stamp, frame))
    assert err.field == field
    assert words in err.expected
    err = _refusal(lambda: codec_for("PointStamped").from_value({}, stamp=stamp,
                                                                frame_id=frame))
    assert err.field == field


def test_a_header_from_time_and_from_a_pair() -> None:
    from builtin_interfaces.msg import Time

    assert make_header(Time(sec=3, nanosec=4), "map").stamp == Time(sec=3, nanosec=4)
    header = make_header((5, 6), "ras")
    assert (header.stamp.sec, header.stamp.nanosec, header.frame_id) == (5, 6, "ras")


# ------------------------------------------------------------------ Slicer models, markups

def _mesh(vertices: list[tuple[float, float, float]], triangles: list[list[int]]) -> Any:
    from geometry_msgs.msg import Point as RosPoint
    from shape_msgs.msg import Mesh, MeshTriangle

    return Mesh(vertices=[RosPoint(x=x, y=y, z=z) for x, y, z in vertices],
                triangles=[MeshTriangle(vertex_indices=t) for t in triangles])


def test_a_mesh_from_ros_with_nan_or_a_bad_index_is_refused() -> None:
    codec = codec_for("shape_msgs/msg/Mesh")
    for bad in (float("nan"), 1e36, -1e306):  # the last two: finite, not as float32 in mm
        mesh = _mesh([(0, 0, 0), (bad, 0, 0)], [])
        err = _refusal(lambda: codec.to_igtl(mesh))  # noqa: B023 - called at once
        assert (err.field, err.expected) == ("vertices[1]", "finite coordinates (within "
                                             "float32 once in mm)")
    err = _refusal(lambda: codec.to_value(_mesh([(0, 0, 0)] * 3, [[0, 1, 2], [0, 1, 3]])))
    assert (err.field, err.got) == ("triangles[1].vertex_indices", "[0, 1, 3]")
    assert "indices < 3" in err.expected


@pytest.mark.parametrize("value, field, words", [
    ([[0, 0, 0]], "value", "'vertices'"),
    ({"vertices": [], "faces": []}, "value", "'triangles'"),
    ({"vertices": [[0, 0]], "triangles": []}, "value.vertices", "[x, y, z] rows"),
    ({"vertices": [[0, 0, 0]] * 3, "triangles": [[0, 1]]}, "value.triangles", "[i, j, k]"),
    ({"vertices": [[0, 0, 0]] * 3, "triangles": [[0, 1, 5]]}, "value.triangles", "indices < 3"),
    ({"vertices": [[0, 0, float("inf")]], "triangles": []}, "value.vertices[0]", "finite"),
])
def test_a_mesh_value_from_a_client_is_checked(value: Any, field: str, words: str) -> None:
    err = _refusal(lambda: codec_for("shape_msgs/msg/Mesh").from_value(value))
    assert err.field == field
    assert words in err.expected


def test_a_mesh_value_beyond_the_triangle_limit_is_refused() -> None:
    triangles = np.zeros((MAX_MESH_TRIANGLES + 1, 3), dtype=np.uint32)
    err = _refusal(lambda: codec_for("shape_msgs/msg/Mesh").from_value(
        {"vertices": [[0, 0, 0]], "triangles": triangles}))
    assert err.field == "value.triangles"
    assert err.got == str(MAX_MESH_TRIANGLES + 1)


def test_marker_colour_that_is_not_numbers_is_refused() -> None:
    body = _wire(PolyData(points=np.zeros((3, 3), dtype=np.float32),
                          polygons=np.array([3, 0, 1, 2], dtype=np.uint32)))
    err = _refusal(lambda: codec_for("visualization_msgs/msg/Marker").from_igtl(
        body, metadata={"ros2.color": "red green blue alpha"}))
    assert (err.field, err.got) == ("metadata.ros2.color", "'red green blue alpha'")
    # A TRANSFORM has no serialized path for a Marker: None, the caller uses from_igtl.
    assert codec_for("visualization_msgs/msg/Marker").from_igtl_raw(
        Transform(np.eye(4))) is None


def _markups(n: int) -> Point:
    return _wire(Point([PointElement(name=f"F-{i}", position=np.array([float(i), 0.0, 0.0]))
                        for i in range(n)]))


def test_point_stamped_from_a_list_of_markups_wants_one() -> None:
    codec = codec_for("PointStamped")
    err = _refusal(lambda: codec.from_igtl(_markups(2)))
    assert (err.field, err.got) == ("body.points", "2 points")
    err = _refusal(lambda: codec.from_igtl(_wire(Point([]))))
    assert (err.field, err.expected) == ("body.points", "at least one point")
    # A STRING body is the generic JSON; a TRANSFORM is no markups list.
    assert codec.from_igtl(String('{"point": {"x": 1.5}}')).point.x == 1.5
    assert len(codec.from_igtl_all(String('{"point": {"y": 2.0}}'))) == 1
    err = _refusal(lambda: codec.from_igtl(Transform(np.eye(4))))
    assert err.field == "body"


def test_one_markup_is_one_point_stamped_in_metres() -> None:
    msg = codec_for("PointStamped").from_igtl(_markups(1), stamp=(3, 4), frame_id="ras")
    assert (msg.point.x, msg.point.y, msg.point.z) == (0.0, 0.0, 0.0)
    assert (msg.header.frame_id, msg.header.stamp.sec) == ("ras", 3)
    two = _wire(Point([PointElement(name="a", position=np.array([1500.0, -20.0, 3.0]))]))
    assert codec_for("PointStamped").from_igtl(two).point.x == 1.5


def test_too_many_markups_are_refused() -> None:
    err = _refusal(lambda: codec_for("PointStamped").from_igtl_all(
        _markups(MAX_MARKUP_POINTS + 1)))
    assert (err.field, err.got) == ("body.points", str(MAX_MARKUP_POINTS + 1))
    assert err.expected == f"at most {MAX_MARKUP_POINTS} points"


def test_a_path_longer_than_the_limit_or_from_a_transform_is_refused() -> None:
    n = MAX_PATH_POINTS + 1
    body = PolyData(points=np.zeros((n, 3), dtype=np.float32),
                    lines=np.concatenate([[n], np.arange(n)]).astype(np.uint32))
    err = _refusal(lambda: codec_for("nav_msgs/msg/Path").from_igtl(body))
    assert (err.field, err.got) == ("body.lines", str(n))
    err = _refusal(lambda: codec_for("nav_msgs/msg/Path").from_igtl(Transform(np.eye(4))))
    assert err.field == "body"
    assert "STRING" in err.expected

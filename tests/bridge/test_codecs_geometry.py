"""geometry_msgs: poses and transforms <-> TRANSFORM (mm), wrench and pose array <-> JSON."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Pose, PoseArray, PoseStamped, TransformStamped, WrenchStamped
from hypothesis import given, settings
from hypothesis import strategies as st

from bridge.codecs import CodecError, codec_for
from protocol.conversions import quaternion_to_rotation
from protocol.messages import String, Transform, unpack_body

# A rotation of 30 degrees about (1, 2, 3)/|.|, as a quaternion (x, y, z, w).
_AXIS = np.array([1.0, 2.0, 3.0]) / np.linalg.norm([1.0, 2.0, 3.0])
_Q = np.concatenate([_AXIS * np.sin(np.pi / 12), [np.cos(np.pi / 12)]])


def _wire(body: Any) -> Any:
    return unpack_body(body.TYPE, body.pack())


def _same_rotation(q1: list[float], q2: list[float], tol: float = 1e-6) -> bool:
    # q and -q are the same rotation
    return abs(abs(float(np.dot(q1, q2))) - 1.0) < tol


def _pose_stamped() -> PoseStamped:
    p = PoseStamped()
    p.header.stamp = Time(sec=1_700_000_000, nanosec=42)
    p.header.frame_id = "base"
    p.pose.position.x, p.pose.position.y, p.pose.position.z = 0.0031415, -0.25, 1.5
    o = p.pose.orientation
    o.x, o.y, o.z, o.w = (float(v) for v in _Q)
    return p


def test_pose_stamped_to_transform_in_mm_and_back() -> None:
    codec = codec_for("PoseStamped")
    msg = _pose_stamped()
    enc = codec.encode(msg)
    assert isinstance(enc.body, Transform)
    assert enc.stamp == (1_700_000_000, 42)
    assert enc.metadata["ros2.frame"] == "base"
    assert enc.metadata["ros2.units"] == "mm"
    on_wire = _wire(enc.body)
    # float32 on the wire: 3.1415 mm within float32 precision
    assert on_wire.matrix[0, 3] == pytest.approx(3.1415, abs=1e-5)
    assert on_wire.matrix[1, 3] == pytest.approx(-250.0, abs=1e-4)
    assert on_wire.matrix[2, 3] == pytest.approx(1500.0, abs=1e-3)
    np.testing.assert_allclose(on_wire.matrix[:3, :3], quaternion_to_rotation(_Q), atol=1e-6)

    back = codec.from_igtl(on_wire, stamp=Time(sec=7, nanosec=8), frame_id="world")
    assert isinstance(back, PoseStamped)
    assert back.header.frame_id == "world"
    assert (back.header.stamp.sec, back.header.stamp.nanosec) == (7, 8)
    assert back.pose.position.x == pytest.approx(0.0031415, abs=1e-8)
    assert back.pose.position.y == pytest.approx(-0.25, abs=1e-7)
    q = back.pose.orientation
    assert _same_rotation([q.x, q.y, q.z, q.w], list(_Q))


def test_pose_value_is_the_matrix_in_mm() -> None:
    codec = codec_for("Pose")
    pose = _pose_stamped().pose
    value = codec.to_value(pose)
    assert np.asarray(value).shape == (4, 4)
    assert value[0][3] == pytest.approx(3.1415, abs=1e-9)  # float64 here: no wire rounding
    back = codec.from_value(json.loads(json.dumps(value)))
    assert isinstance(back, Pose)
    assert back.position.x == pytest.approx(0.0031415, abs=1e-12)
    assert _same_rotation([back.orientation.x, back.orientation.y, back.orientation.z,
                           back.orientation.w], list(_Q), 1e-12)


def test_transform_stamped_carries_child_frame() -> None:
    codec = codec_for("TransformStamped")
    t = TransformStamped()
    t.header.frame_id, t.child_frame_id = "world", "tool"
    t.transform.translation.z = 0.1
    t.transform.rotation.w = 1.0
    enc = codec.encode(t)
    assert enc.metadata["ros2.parent"] == "world"
    assert enc.metadata["ros2.child"] == "tool"
    assert enc.body.matrix[2, 3] == pytest.approx(100.0)
    back = codec.from_igtl(_wire(enc.body), frame_id="world", metadata=enc.metadata)
    assert back.child_frame_id == "tool" and back.header.frame_id == "world"
    assert back.transform.translation.z == pytest.approx(0.1, abs=1e-7)
    by_value = codec.from_value({"matrix": codec.to_value(t), "child_frame_id": "tip"})
    assert by_value.child_frame_id == "tip"


@pytest.mark.parametrize("value, field", [
    ([[1, 0, 0, float("nan")], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "value"),
    ([[1, 0, 0, float("inf")], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "value"),
    ([[1, 0, 0], [0, 1, 0], [0, 0, 1]], "value"),
    ([[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "value rotation"),
    ([[1, 0.5, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "value rotation"),
    ([[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "value rotation"),
    ([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1]], "value[3]"),
    ([[1, 0, 0, "0"], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "value[0][3]"),
    ("eye", "value"),
])
def test_bad_matrices_from_a_client_name_the_field(value: Any, field: str) -> None:
    with pytest.raises(CodecError) as err:
        codec_for("PoseStamped").from_value(value)
    assert err.value.field == field
    assert err.value.expected


def test_bad_transform_body_from_slicer() -> None:
    m = np.eye(4)
    m[:3, :3] *= 2.0  # scaled: not a rigid transform
    with pytest.raises(CodecError) as err:
        codec_for("PoseStamped").from_igtl(_wire(Transform(m)))
    assert err.value.field == "matrix rotation"
    nan = np.eye(4)
    nan[0, 3] = np.nan
    with pytest.raises(CodecError) as err:
        codec_for("PoseStamped").from_igtl(Transform(nan))
    assert err.value.field == "matrix"
    with pytest.raises(CodecError) as err:
        codec_for("PoseStamped").from_igtl(String(text="eye"))
    assert err.value.field == "body"


def test_nan_pose_from_ros_is_a_codec_error() -> None:
    p = _pose_stamped()
    p.pose.position.y = float("nan")
    with pytest.raises(CodecError) as err:
        codec_for("PoseStamped").to_igtl(p)
    assert err.value.field == "pose.position"
    p = _pose_stamped()
    p.pose.orientation.x = p.pose.orientation.y = p.pose.orientation.z = 0.0
    p.pose.orientation.w = 0.0
    with pytest.raises(CodecError) as err:
        codec_for("PoseStamped").to_igtl(p)
    assert err.value.field == "pose.orientation"


def test_wrench_stamped_as_six_numbers() -> None:
    codec = codec_for("WrenchStamped")
    w = WrenchStamped()
    w.header.frame_id = "ft_sensor"
    w.wrench.force.x, w.wrench.force.y, w.wrench.force.z = 1.0, -2.0, 3.5
    w.wrench.torque.x, w.wrench.torque.y, w.wrench.torque.z = 0.1, 0.2, -0.3
    enc = codec.encode(w)
    assert json.loads(enc.body.text) == [1.0, -2.0, 3.5, 0.1, 0.2, -0.3]
    assert codec.from_igtl(_wire(enc.body), frame_id="ft_sensor") == w
    assert codec.from_value(codec.to_value(w), frame_id="ft_sensor") == w
    with pytest.raises(CodecError) as err:
        codec.from_value([1, 2, 3])
    assert err.value.field == "value" and "6" in err.value.expected
    with pytest.raises(CodecError) as err:
        codec.from_value([1, 2, 3, 4, 5, float("nan")])
    assert err.value.field == "value[5]"


def test_pose_array_as_matrices_in_mm() -> None:
    codec = codec_for("PoseArray")
    pa = PoseArray()
    pa.header.frame_id = "map"
    p2 = Pose()
    p2.position.x = -0.5
    p2.orientation.w = 1.0
    pa.poses = [_pose_stamped().pose, p2]
    enc = codec.encode(pa)
    mats = np.asarray(json.loads(enc.body.text))
    assert mats.shape == (2, 4, 4)
    assert mats[0, 0, 3] == pytest.approx(3.1415)
    assert mats[1, 0, 3] == pytest.approx(-500.0)
    np.testing.assert_allclose(mats[0, :3, :3], quaternion_to_rotation(_Q), atol=1e-12)
    back = codec.from_igtl(_wire(enc.body), frame_id="map")
    assert len(back.poses) == 2
    assert back.poses[0].position.x == pytest.approx(0.0031415, abs=1e-12)
    q = back.poses[0].orientation
    assert _same_rotation([q.x, q.y, q.z, q.w], list(_Q))
    assert codec.from_value([]) == PoseArray()
    bad = mats.tolist()
    bad[1][0][1] = 0.5
    with pytest.raises(CodecError) as err:
        codec.from_value(bad)
    assert err.value.field == "value[1] rotation"
    with pytest.raises(CodecError) as err:
        codec.from_value([[1, 2, 3]])
    assert err.value.field == "value"


_coord = st.floats(min_value=-10.0, max_value=10.0, allow_nan=False)
_unit = st.floats(min_value=-1.0, max_value=1.0, allow_nan=False)


@settings(max_examples=60, deadline=None)
@given(t=st.tuples(_coord, _coord, _coord), q=st.tuples(_unit, _unit, _unit, _unit))
def test_any_pose_round_trips_through_the_wire(t: tuple, q: tuple) -> None:
    norm = float(np.linalg.norm(q))
    if norm < 1e-3:
        return
    p = PoseStamped()
    p.pose.position.x, p.pose.position.y, p.pose.position.z = t
    o = p.pose.orientation
    o.x, o.y, o.z, o.w = (v / norm for v in q)
    codec = codec_for("PoseStamped")
    back = codec.from_igtl(_wire(codec.to_igtl(p)))
    got = back.pose.position
    # float32 mm on the wire: ~1e-7 relative of up to 10 m
    assert np.allclose([got.x, got.y, got.z], t, atol=2e-6)
    b = back.pose.orientation
    assert _same_rotation([b.x, b.y, b.z, b.w], [v / norm for v in q], 1e-6)

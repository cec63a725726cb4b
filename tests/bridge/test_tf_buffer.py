"""TfBuffer: composition, interpolation, latest common time, caches, tf2's errors. No ROS."""

from __future__ import annotations

import math
import pickle
import threading
from typing import Sequence

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from bridge.tf import (
    ConnectivityError,
    ExtrapolationError,
    InvalidArgumentError,
    RejectedTransformsError,
    StampedTransform,
    TfBuffer,
    TfError,
    TfErrorCode,
    TfLookupError,
)
from bridge.tf.math import quat_angle
from protocol.conversions import pose_to_matrix

S = 1_000_000_000  # ns per second
IDQ = (0.0, 0.0, 0.0, 1.0)

# Every test here runs on both tf stores (tests/bridge/conftest.py).
pytestmark = pytest.mark.usefixtures("tf_store")


def qaxis(axis: Sequence[float], angle: float) -> tuple[float, float, float, float]:
    n = math.sqrt(sum(a * a for a in axis))
    s = math.sin(angle / 2) / n
    return (axis[0] * s, axis[1] * s, axis[2] * s, math.cos(angle / 2))


def tf(parent: str, child: str, stamp: int, t: Sequence[float],
       q: Sequence[float] = IDQ) -> StampedTransform:
    return StampedTransform(parent, child, stamp, tuple(t), tuple(q))  # type: ignore[arg-type]


def mat(tr: StampedTransform) -> np.ndarray:
    return pose_to_matrix(tr.translation, tr.rotation)


# A robot: world -static-> base -> shoulder -> elbow -> tool, and base -> camera -> lens.
WORLD_BASE = tf("world", "base", 0, (0.5, 0.0, 0.1), qaxis((0, 0, 1), math.pi / 2))
BASE_SHOULDER = tf("base", "shoulder", 2 * S, (0.0, 0.0, 0.3), qaxis((0, 1, 0), 0.3))
SHOULDER_ELBOW = tf("shoulder", "elbow", 2 * S, (0.4, 0.0, 0.0), qaxis((1, 1, 0), -0.7))
ELBOW_TOOL = tf("elbow", "tool", 2 * S, (0.25, 0.05, -0.02), qaxis((0, 0, 1), 1.1))
BASE_CAMERA = tf("base", "camera", 2 * S, (-0.1, 0.2, 0.9), qaxis((1, 0, 0), math.pi))
CAMERA_LENS = tf("camera", "lens", 0, (0.0, 0.0, 0.05), qaxis((0, 1, 1), 0.2))


@pytest.fixture
def robot() -> TfBuffer:
    buf = TfBuffer()
    buf.set_transforms([WORLD_BASE, CAMERA_LENS], static=True)
    buf.set_transforms([BASE_SHOULDER, SHOULDER_ELBOW, ELBOW_TOOL, BASE_CAMERA], static=False)
    return buf


# ---------------------------------------------------------------------- composition


def test_chain_composes_to_the_expected_matrix_in_mm(robot: TfBuffer) -> None:
    result = robot.lookup("world", "tool")
    expected = mat(WORLD_BASE) @ mat(BASE_SHOULDER) @ mat(SHOULDER_ELBOW) @ mat(ELBOW_TOOL)
    assert (result.parent, result.child, result.stamp_ns) == ("world", "tool", 2 * S)
    np.testing.assert_allclose(result.matrix_mm(), expected, atol=1e-9)
    # and the translation really is in mm in the matrix, metres in the transform
    np.testing.assert_allclose(np.array(result.translation) * 1000.0, expected[:3, 3], atol=1e-9)


def test_lookup_between_leaves_of_two_branches_goes_through_common_ancestor(
        robot: TfBuffer) -> None:
    result = robot.lookup("lens", "tool")
    base_tool = mat(BASE_SHOULDER) @ mat(SHOULDER_ELBOW) @ mat(ELBOW_TOOL)
    base_lens = mat(BASE_CAMERA) @ mat(CAMERA_LENS)
    np.testing.assert_allclose(result.matrix_mm(), np.linalg.inv(base_lens) @ base_tool,
                               atol=1e-9)
    assert robot.chain_frames("lens", "tool") == {"lens", "camera", "shoulder", "elbow", "tool"}


def test_lookup_towards_a_descendant_is_the_inverse(robot: TfBuffer) -> None:
    down = robot.lookup("tool", "world").matrix_mm()
    up = robot.lookup("world", "tool").matrix_mm()
    np.testing.assert_allclose(down @ up, np.eye(4), atol=1e-9)


def test_same_frame_is_identity_like_tf2(robot: TfBuffer) -> None:
    same = robot.lookup("tool", "tool")
    assert same.translation == (0.0, 0.0, 0.0) and same.rotation == IDQ
    assert same.stamp_ns == 2 * S
    # tf2 short-circuits before checking that the frame exists
    assert robot.lookup("ghost", "ghost").stamp_ns == 0


def test_leading_slash_is_stripped(robot: TfBuffer) -> None:
    robot.set_transforms([tf("/tool", "/tip", 0, (0, 0, 0.1))], static=True)
    assert "tip" in robot.frames() and "/tip" not in robot.frames()
    np.testing.assert_allclose(robot.lookup("/tool", "tip").translation, (0, 0, 0.1))


# ---------------------------------------------------------------------- time


def test_interpolation_at_midpoint_is_half_translation_and_half_angle() -> None:
    buf = TfBuffer()
    axis = (1.0, 2.0, 2.0)
    buf.set_transforms([tf("map", "robot", 1 * S, (0, 0, 0), IDQ),
                        tf("map", "robot", 3 * S, (2.0, 4.0, -6.0), qaxis(axis, 1.2))],
                       static=False)
    mid = buf.lookup("map", "robot", 2 * S)
    assert mid.stamp_ns == 2 * S
    np.testing.assert_allclose(mid.translation, (1.0, 2.0, -3.0), atol=1e-12)
    assert quat_angle(IDQ, mid.rotation) == pytest.approx(0.6, abs=1e-12)
    np.testing.assert_allclose(mid.rotation, qaxis(axis, 0.6), atol=1e-12)
    quarter = buf.lookup("map", "robot", 1 * S + S // 2)
    np.testing.assert_allclose(quarter.translation, (0.5, 1.0, -1.5), atol=1e-12)
    assert quat_angle(IDQ, quarter.rotation) == pytest.approx(0.3, abs=1e-12)


def test_slerp_takes_the_short_way_round() -> None:
    buf = TfBuffer()
    q_end = qaxis((0, 0, 1), 3.0)
    buf.set_transforms([tf("a", "b", 0, (0, 0, 0), IDQ),
                        tf("a", "b", 2 * S, (0, 0, 0), tuple(-c for c in q_end))], static=False)
    assert quat_angle(IDQ, buf.lookup("a", "b", S).rotation) == pytest.approx(1.5, abs=1e-12)


def test_static_links_hold_at_any_time_and_mix_with_dynamic() -> None:
    buf = TfBuffer()
    buf.set_transforms([tf("world", "table", 0, (1, 0, 0))], static=True)
    buf.set_transforms([tf("table", "cup", 10 * S, (0, 0, 1)),
                        tf("table", "cup", 12 * S, (0, 0, 3))], static=False)
    # a static-only chain: any time is fine, latest gives stamp 0 like tf2
    assert buf.lookup("world", "table", 123 * S).translation == (1.0, 0.0, 0.0)
    assert buf.lookup("world", "table").stamp_ns == 0
    # mixed: the dynamic link sets the time
    r = buf.lookup("world", "cup")
    assert r.stamp_ns == 12 * S and r.translation == pytest.approx((1, 0, 3))
    assert buf.lookup("world", "cup", 11 * S).translation == pytest.approx((1, 0, 2))


def test_latest_common_time_is_newest_time_every_link_has() -> None:
    buf = TfBuffer()
    buf.set_transforms([tf("base", "a", k * S, (k, 0, 0)) for k in range(1, 6)], static=False)
    buf.set_transforms([tf("base", "b", k * S, (0, k, 0)) for k in range(1, 4)], static=False)
    buf.set_transforms([tf("b", "c", 0, (0, 0, 1))], static=True)  # static: no constraint
    r = buf.lookup("a", "c")
    assert r.stamp_ns == 3 * S
    # a at 3 s is (3, 0, 0); c in base at 3 s is (0, 3, 1)
    np.testing.assert_allclose(r.translation, (-3.0, 3.0, 1.0), atol=1e-12)
    assert buf.lookup("base", "a").stamp_ns == 5 * S
    assert buf.lookup("a", "base").stamp_ns == 5 * S


# ---------------------------------------------------------------------- errors


@pytest.fixture
def timed() -> TfBuffer:
    buf = TfBuffer()
    buf.set_transforms([tf("base", "arm", k * S, (k, 0, 0)) for k in (2, 3, 4)], static=False)
    buf.set_transforms([tf("base", "once", 3 * S, (0, 0, 0))], static=False)
    return buf


def test_extrapolation_into_the_future(timed: TfBuffer) -> None:
    with pytest.raises(ExtrapolationError) as info:
        timed.lookup("base", "arm", 5 * S + 250_000_000)
    assert str(info.value) == (
        "Lookup would require extrapolation into the future.  Requested time 5.250000000 but"
        " the latest data is at time 4.000000000, when looking up transform from frame [arm]"
        " to frame [base]")
    assert info.value.code == TfErrorCode.EXTRAPOLATION_ERROR == 3
    assert (info.value.direction, info.value.requested_ns, info.value.available_ns) == (
        "future", 5 * S + 250_000_000, 4 * S)


def test_extrapolation_into_the_past(timed: TfBuffer) -> None:
    with pytest.raises(ExtrapolationError) as info:
        timed.lookup("arm", "base", 1 * S)
    assert str(info.value) == (
        "Lookup would require extrapolation into the past.  Requested time 1.000000000 but"
        " the earliest data is at time 2.000000000, when looking up transform from frame"
        " [base] to frame [arm]")
    assert info.value.code == 3


def test_extrapolation_with_a_single_sample(timed: TfBuffer) -> None:
    with pytest.raises(ExtrapolationError, match=r"^Lookup would require extrapolation at time"
                       r" 2\.000000000, but only time 3\.000000000 is in the buffer, when"):
        timed.lookup("arm", "once", 2 * S)


def test_unknown_frames(timed: TfBuffer) -> None:
    with pytest.raises(TfLookupError) as info:
        timed.lookup("nowhere", "arm")
    assert str(info.value) == (
        '"nowhere" passed to lookupTransform argument target_frame does not exist.')
    assert info.value.code == TfErrorCode.LOOKUP_ERROR == 1 and info.value.frame == "nowhere"
    with pytest.raises(TfLookupError, match="argument source_frame does not exist"):
        timed.lookup("arm", "nowhere")
    assert not timed.can_transform("arm", "nowhere")


def test_disconnected_trees(timed: TfBuffer) -> None:
    timed.set_transforms([tf("map", "odom", 0, (0, 0, 0))], static=True)
    with pytest.raises(ConnectivityError) as info:
        timed.lookup("odom", "arm")
    assert str(info.value) == (
        "Could not find a connection between 'odom' and 'arm' because they are not part of"
        " the same tree.Tf has two or more unconnected trees.")
    assert info.value.code == TfErrorCode.CONNECTIVITY_ERROR == 2
    with pytest.raises(ConnectivityError):
        timed.lookup("odom", "arm", 3 * S)
    assert timed.can_transform("base", "arm", 3 * S)
    assert not timed.can_transform("odom", "arm")


def test_loop_is_reported_not_hung() -> None:
    buf = TfBuffer()
    buf.set_transforms([tf("a", "b", 0, (1, 0, 0)), tf("b", "c", 0, (1, 0, 0)),
                        tf("c", "a", 0, (1, 0, 0)), tf("x", "y", 0, (0, 0, 0))], static=True)
    # frames next to each other on the loop are still found (tf2 stops at the target too)
    assert buf.lookup("a", "c").translation == (2.0, 0.0, 0.0)
    for target, source, t in (("x", "a", 0), ("a", "y", 0), ("x", "b", 5), ("c", "y", 5)):
        with pytest.raises(TfLookupError, match="contains a loop") as info:
            buf.lookup(target, source, t)
        assert info.value.code == 1 and info.value.frame is None


@pytest.mark.parametrize("bad, what", [
    (tf("w", "b", 1, (0, 0, float("nan"))), "finite numbers"),
    (tf("w", "b", 1, (0, float("inf"), 0)), "finite numbers"),
    (tf("w", "b", 1, (0, 0, 0), (0, 0, 0, float("nan"))), "finite numbers"),
    (tf("w", "b", 1, (0, 0, 0), (0, 0, 0, 0)), "unit quaternion"),
    (tf("w", "b", 1, (0, 0, 0), (0, 0, 0, 2)), "unit quaternion"),
    (tf("", "b", 1, (0, 0, 0)), "non-empty frame id"),
    (tf("w", "/", 1, (0, 0, 0)), "non-empty frame id"),
    (tf("b", "b", 1, (0, 0, 0)), "different from the child"),
    (tf("w", "b", -1, (0, 0, 0)), "time >= 0"),
    (tf("w", "b", 1, (0, 0), IDQ), "3 numbers"),
])
def test_invalid_transforms_are_refused_and_never_stored(bad: StampedTransform,
                                                         what: str) -> None:
    buf = TfBuffer()
    good = tf("w", "ok", 1, (0, 0, 0))
    with pytest.raises(RejectedTransformsError) as info:
        buf.set_transforms([bad, good], static=False)
    err = info.value
    assert err.code == TfErrorCode.INVALID_ARGUMENT_ERROR == 4
    assert what in str(err) and err.field.startswith("transforms[0]")
    assert err.changed == {"ok"} and len(err.rejected) == 1
    assert buf.frames() == ["ok", "w"]


def test_slightly_denormalised_quaternion_is_accepted_and_normalised() -> None:
    buf = TfBuffer()
    buf.set_transforms([tf("w", "b", 1, (0, 0, 0), (0, 0, 0, 1.004))], static=False)
    assert buf.lookup("w", "b").rotation == (0.0, 0.0, 0.0, 1.0)


def test_invalid_lookup_arguments() -> None:
    buf = TfBuffer()
    buf.set_transforms([tf("w", "b", 1, (0, 0, 0))], static=False)
    for args in (("", "b", 0), ("w", "b", -5), ("w", "b", 1.5)):
        with pytest.raises(InvalidArgumentError) as info:
            buf.lookup(*args)  # type: ignore[arg-type]
        assert info.value.code == 4
    with pytest.raises(InvalidArgumentError):
        TfBuffer(cache_time_s=0)


# ---------------------------------------------------------------------- caches


def test_cache_is_pruned_to_cache_time_behind_newest() -> None:
    buf = TfBuffer(cache_time_s=1.0)
    changed = buf.set_transforms([tf("w", "b", k * S // 2, (k, 0, 0)) for k in range(8)],
                                 static=False)  # 0 .. 3.5 s
    assert changed == {"b"}
    (info,) = buf.frame_info()
    assert (info.oldest_ns, info.most_recent_ns, info.samples) == (5 * S // 2, 7 * S // 2, 3)
    assert buf.lookup("w", "b", 3 * S).translation == pytest.approx((6, 0, 0))
    with pytest.raises(ExtrapolationError, match="into the past"):
        buf.lookup("w", "b", 2 * S)
    # data older than the window is ignored, as tf2 does (TF_OLD_DATA)
    assert buf.set_transforms([tf("w", "b", 1 * S, (9, 9, 9))], static=False) == set()
    assert buf.frame_info()[0].samples == 3


def test_samples_dropped_in_chunks_are_gone_at_once() -> None:
    """The lists shed old samples a quarter window at a time; until then a sample older
    than the window is invisible to lookups and to frame_info, as tf2's pruned one is."""
    buf = TfBuffer(cache_time_s=1.0)
    for k in range(21):  # 0 .. 2.0 s, one sample each 0.1 s, one message each
        buf.set_transforms([tf("w", "b", k * S // 10, (k, 0, 0))], static=False)
    (info,) = buf.frame_info()
    assert (info.oldest_ns, info.most_recent_ns, info.samples) == (S, 2 * S, 11)
    assert buf.lookup("w", "b", S).translation == pytest.approx((10, 0, 0))
    assert buf.lookup("w", "b", 15 * S // 10).translation == pytest.approx((15, 0, 0))
    with pytest.raises(ExtrapolationError, match="into the past"):
        buf.lookup("w", "b", 95 * S // 100)  # 0.9 s is still held, not live


def test_out_of_order_samples_are_inserted_in_order() -> None:
    buf = TfBuffer()
    assert buf.set_transforms([tf("w", "b", 3 * S, (3, 0, 0)), tf("w", "b", 1 * S, (1, 0, 0))],
                              static=False) == {"b"}
    assert buf.set_transforms([tf("w", "b", 2 * S, (2, 0, 0))], static=False) == {"b"}
    assert buf.lookup("w", "b", S + S // 2).translation == pytest.approx((1.5, 0, 0))
    assert buf.lookup("w", "b", 2 * S + S // 2).translation == pytest.approx((2.5, 0, 0))
    assert buf.lookup("w", "b").stamp_ns == 3 * S
    assert buf.frame_info()[0].samples == 3


def test_repeats_do_not_count_as_changes_and_same_stamp_overwrites() -> None:
    buf = TfBuffer()
    static = [tf("w", "s", 0, (1, 0, 0))]
    assert buf.set_transforms(static, static=True) == {"s"}
    assert buf.set_transforms(static, static=True) == set()  # /tf_static re-delivered
    assert buf.set_transforms([tf("w", "d", S, (1, 0, 0))], static=False) == {"d"}
    assert buf.set_transforms([tf("w", "d", S, (1, 0, 0))], static=False) == set()
    assert buf.set_transforms([tf("w", "d", S, (2, 0, 0))], static=False) == {"d"}
    assert buf.lookup("w", "d").translation == (2.0, 0.0, 0.0)
    assert buf.frame_info()[1].samples == 1


def test_parent_change_newest_wins_for_later_times() -> None:
    buf = TfBuffer()
    buf.set_transforms([tf("world", "a", 0, (1, 0, 0)), tf("world", "b", 0, (0, 1, 0))],
                       static=True)
    buf.set_transforms([tf("a", "tool", 1 * S, (0, 0, 1)), tf("a", "tool", 2 * S, (0, 0, 2))],
                       static=False)
    version = buf.graph_version
    assert buf.lookup("world", "tool").translation == pytest.approx((1, 0, 2))
    buf.set_transforms([tf("b", "tool", 3 * S, (0, 0, 3)), tf("b", "tool", 4 * S, (0, 0, 4))],
                       static=False)
    assert buf.graph_version > version
    assert buf.lookup("world", "tool").translation == pytest.approx((0, 1, 4))
    assert buf.lookup("world", "tool", 3 * S + S // 2).translation == pytest.approx((0, 1, 3.5))
    assert buf.lookup("world", "tool", S + S // 2).translation == pytest.approx((1, 0, 1.5))
    # between samples with different parents tf2 keeps the older sample (no interpolation)
    assert buf.lookup("world", "tool", 2 * S + S // 2).translation == pytest.approx((1, 0, 2))
    assert buf.chain_frames("world", "tool") == {"tool", "b"}
    assert buf.lookup("a", "tool", 2 * S).translation == pytest.approx((0, 0, 2))


def test_latest_lookup_falls_back_when_parent_at_common_time_differs() -> None:
    buf = TfBuffer()
    buf.set_transforms([tf("world", "a", 0, (1, 0, 0))], static=True)
    buf.set_transforms([tf("world", "b", k * S, (0, k, 0)) for k in (1, 2)], static=False)
    buf.set_transforms([tf("a", "tool", 1 * S, (0, 0, 1)), tf("b", "tool", 5 * S, (0, 0, 5)),
                        tf("world", "probe", 2 * S, (0, 0, 0))], static=False)
    # newest parents give chain tool-b-world and common time 2 s; at 2 s tool's parent is a
    r = buf.lookup("probe", "tool")
    assert r.stamp_ns == 2 * S and r.translation == pytest.approx((1, 0, 1))


def test_static_and_dynamic_switch_replaces_the_cache() -> None:
    buf = TfBuffer()
    buf.set_transforms([tf("w", "x", k * S, (k, 0, 0)) for k in (1, 2)], static=False)
    buf.set_transforms([tf("w", "x", 0, (7, 0, 0))], static=True)
    info = buf.frame_info()[0]
    assert info.static and info.samples == 1
    assert buf.lookup("w", "x", 99 * S).translation == (7.0, 0.0, 0.0)


# ---------------------------------------------------------------------- listing


def test_frames_and_yaml(robot: TfBuffer) -> None:
    assert robot.frames() == ["base", "camera", "elbow", "lens", "shoulder", "tool", "world"]
    assert TfBuffer().all_frames_as_yaml().strip() == "[]"
    robot.set_transforms([tf("base", "camera", 3 * S, (0, 0, 1))], static=False)
    doc = yaml.safe_load(robot.all_frames_as_yaml(current_time_ns=4 * S))
    assert set(doc) == {"base", "camera", "elbow", "lens", "shoulder", "tool"}
    assert doc["camera"]["parent"] == "base" and doc["camera"]["static"] is False
    assert doc["camera"]["most_recent_transform"] == pytest.approx(3.0)
    assert doc["camera"]["oldest_transform"] == pytest.approx(2.0)
    assert doc["camera"]["buffer_length"] == pytest.approx(1.0)
    assert doc["camera"]["transform_delay"] == pytest.approx(1.0)
    assert doc["lens"]["static"] is True and doc["lens"]["parent"] == "camera"


def test_matrix_round_trip_and_errors_pickle(robot: TfBuffer) -> None:
    r = robot.lookup("lens", "tool")
    back = StampedTransform.from_matrix_mm("lens", "tool", r.stamp_ns, r.matrix_mm())
    np.testing.assert_allclose(back.matrix_mm(), r.matrix_mm(), atol=1e-9)
    errors = []
    for args in (("nowhere", "tool", 0), ("world", "tool", 9 * S), ("", "tool", 0)):
        with pytest.raises(Exception) as info:
            robot.lookup(*args)
        errors.append(info.value)
    robot.set_transforms([tf("m", "o", 0, (0, 0, 0))], static=True)
    with pytest.raises(ConnectivityError) as conn:
        robot.lookup("o", "tool")
    for err in [*errors, conn.value]:
        copy = pickle.loads(pickle.dumps(err))
        assert type(copy) is type(err) and str(copy) == str(err) and copy.code == err.code


# ---------------------------------------------------------------------- properties


@st.composite
def trees(draw: st.DrawFn) -> tuple[list[StampedTransform], int]:
    n = draw(st.integers(min_value=2, max_value=12))
    finite = st.floats(min_value=-5, max_value=5, allow_nan=False)
    unit = st.floats(min_value=-1, max_value=1, allow_nan=False)
    out = []
    for i in range(1, n):
        parent = draw(st.integers(min_value=0, max_value=i - 1))
        q = [draw(unit) for _ in range(4)]
        norm = math.sqrt(sum(c * c for c in q))
        if norm < 1e-3:
            q, norm = [0.0, 0.0, 0.0, 1.0], 1.0
        out.append(tf(f"f{parent}", f"f{i}", S, [draw(finite) for _ in range(3)],
                      [c / norm for c in q]))
    return out, n


@settings(max_examples=60, deadline=None)
@given(trees(), st.data())
def test_lookup_and_reverse_lookup_compose_to_identity(
        tree: tuple[list[StampedTransform], int], data: st.DataObject) -> None:
    transforms, n = tree
    buf = TfBuffer()
    buf.set_transforms(transforms, static=False)
    a = f"f{data.draw(st.integers(0, n - 1))}"
    b = f"f{data.draw(st.integers(0, n - 1))}"
    ab, ba = buf.lookup(a, b).matrix_mm(), buf.lookup(b, a).matrix_mm()
    np.testing.assert_allclose(ab @ ba, np.eye(4), atol=1e-7)
    # and both agree with plain 4x4 products along the paths to the root
    parent_of = {t.child: t for t in transforms}

    def to_root(frame: str) -> np.ndarray:
        m = np.eye(4)
        while frame in parent_of:
            m = mat(parent_of[frame]) @ m
            frame = parent_of[frame].parent
        return m

    np.testing.assert_allclose(ab, np.linalg.inv(to_root(a)) @ to_root(b), atol=1e-7)


def test_concurrent_writer_and_reader_see_whole_batches() -> None:
    # The writer moves two links in one batch so that world<-tool stays at x = 1 m; a reader
    # seeing half a batch would read another value.
    buf = TfBuffer()
    buf.set_transforms([tf("world", "mid", 1, (0, 0, 0)), tf("mid", "tool", 1, (1, 0, 0))],
                       static=False)
    stop = threading.Event()
    bad: list[object] = []

    def write() -> None:
        k = 2
        while not stop.is_set():
            x = (k % 100) / 100.0
            buf.set_transforms([tf("world", "mid", k, (x, 0, 0)),
                                tf("mid", "tool", k, (1 - x, 0, 0))], static=False)
            k += 1

    writer = threading.Thread(target=write)
    writer.start()
    try:
        for _ in range(3000):
            r = buf.lookup("world", "tool")
            if abs(r.translation[0] - 1.0) > 1e-9:
                bad.append(r)
    finally:
        stop.set()
        writer.join()
    assert not bad


# ---------------------------------------------------------------------------- batches


def test_a_batch_of_lookups_gives_what_each_lookup_gives() -> None:
    """`lookup_latest_many` shares composed links between lookups of one batch (a robot's
    links from its base): each result, value or error, is the one `lookup` gives alone."""
    buf = TfBuffer()
    rng = np.random.default_rng(11)

    def rand_q() -> tuple[float, float, float, float]:
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        return (float(q[0]), float(q[1]), float(q[2]), float(q[3]))

    buf.set_transforms([tf("world", "base", 0, (1, 2, 3), rand_q())], static=True)
    # Two arms sharing the base, samples at different times (interpolation and extrapolation
    # come from their stamps), and a frame of another tree.
    for stamp in (1 * S, 2 * S):
        batch = []
        for arm in ("a", "b"):
            parent = "base"
            for k in range(1, 5):
                child = f"{arm}{k}"
                if arm == "a" or stamp == 1 * S or k < 3:  # b3, b4 lag behind
                    batch.append(tf(parent, child, stamp + k * 1000,
                                    tuple(rng.uniform(-1, 1, 3)), rand_q()))
                parent = child
        buf.set_transforms(batch, static=False)
    buf.set_transforms([tf("elsewhere", "island", 1 * S, (0, 0, 1))], static=False)
    frames = ["world", "base", "a1", "a2", "a3", "a4", "b1", "b2", "b3", "b4", "island",
              "missing"]
    pairs = [(p, c) for p in frames for c in frames]
    batch_results = buf.lookup_latest_many(pairs)
    assert len(batch_results) == len(pairs)
    for (parent, child), got in zip(pairs, batch_results):
        try:
            alone = buf.lookup(parent, child)
        except TfError as error:
            assert isinstance(got, type(error)) and str(got) == str(error), (parent, child)
            continue
        assert isinstance(got, StampedTransform), (parent, child, got)
        assert (got.parent, got.child, got.stamp_ns) == (alone.parent, alone.child,
                                                         alone.stamp_ns)
        np.testing.assert_allclose(got.translation, alone.translation, atol=1e-12)
        np.testing.assert_allclose(got.rotation, alone.rotation, atol=1e-12)

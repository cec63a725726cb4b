"""LookupRegistry: only affected lookups, only changed results, rate caps, pending. No ROS."""

from __future__ import annotations

from typing import Sequence

import pytest

from bridge.tf import (
    ConnectivityError,
    ExtrapolationError,
    InvalidArgumentError,
    LookupKey,
    LookupRegistry,
    StampedTransform,
    TfBuffer,
    TfError,
)

S = 1_000_000_000
MS = 1_000_000
IDQ = (0.0, 0.0, 0.0, 1.0)

# Every test here runs on both tf stores (tests/bridge/conftest.py).
pytestmark = pytest.mark.usefixtures("tf_store")


def tf(parent: str, child: str, stamp: int, t: Sequence[float],
       q: Sequence[float] = IDQ) -> StampedTransform:
    return StampedTransform(parent, child, stamp, tuple(t), tuple(q))  # type: ignore[arg-type]


class CountingBuffer(TfBuffer):
    """A real TfBuffer that also counts the lookups asked of it (to prove 'no work')."""

    def __init__(self) -> None:
        super().__init__()
        self.asked: list[tuple[str, str]] = []

    def lookup(self, target_frame: str, source_frame: str, time_ns: int = 0) -> StampedTransform:
        self.asked.append((target_frame, source_frame))
        return super().lookup(target_frame, source_frame, time_ns)

    def lookup_latest_many(self, pairs: Sequence[tuple[str, str]],
                           ) -> list[StampedTransform | TfError]:
        self.asked.extend(pairs)
        return super().lookup_latest_many(pairs)


@pytest.fixture
def buf() -> CountingBuffer:
    b = CountingBuffer()
    b.set_transforms([tf("world", "base", 0, (1, 0, 0))], static=True)
    b.set_transforms([tf("base", "arm", S, (0, 1, 0)), tf("arm", "tool", S, (0, 0, 1)),
                      tf("base", "camera", S, (0, 0, 2))], static=False)
    return b


def arm_tool(stamp: int, t: Sequence[float],
             q: Sequence[float] = IDQ) -> list[StampedTransform]:
    """A robot update: every link of the arm at one stamp (a lone newer tool sample would not
    move a latest-time lookup: the latest common time stays at the arm link's newest)."""
    return [tf("base", "arm", stamp, (0, 1, 0)), tf("arm", "tool", stamp, t, q)]


def feed(buf: TfBuffer, reg: LookupRegistry, transforms: list[StampedTransform],
         now_ns: int) -> list[tuple[LookupKey, object]]:
    """What the daemon does after each /tf message."""
    return reg.updates(buf.set_transforms(transforms, static=False), now_ns)


def test_first_results_then_only_affected_lookups_are_evaluated(buf: CountingBuffer) -> None:
    reg = LookupRegistry(buf)
    tool = reg.add("world", "tool")
    cam = reg.add("world", "camera")
    first = dict(reg.updates(set(), 0))
    assert first[tool].translation == pytest.approx((1, 1, 1))  # type: ignore[union-attr]
    assert first[cam].translation == pytest.approx((1, 0, 2))  # type: ignore[union-attr]

    buf.asked.clear()
    out = feed(buf, reg, [tf("base", "camera", 2 * S, (0, 0, 3))], 10 * MS)
    assert [key for key, _ in out] == [cam]
    assert buf.asked == [("world", "camera")]  # the tool lookup was not even computed
    buf.asked.clear()
    assert reg.updates({"unrelated"}, 20 * MS) == [] and buf.asked == []


def test_unchanged_results_are_not_resent(buf: CountingBuffer) -> None:
    reg = LookupRegistry(buf, translation_tolerance_m=1e-6, rotation_tolerance_rad=1e-6)
    key = reg.add("world", "tool")
    assert len(reg.updates(set(), 0)) == 1
    # a new stamp with the same value, then a change below the tolerance: nothing to send
    assert feed(buf, reg, arm_tool(2 * S, (0, 0, 1)), 1) == []
    assert feed(buf, reg, arm_tool(3 * S, (0, 0, 1 + 1e-8)), 2) == []
    out = feed(buf, reg, arm_tool(4 * S, (0, 0, 1.001)), 3)
    assert [k for k, _ in out] == [key]
    assert reg.last_sent(key).translation == pytest.approx((1, 1, 1.001))  # type: ignore
    # a rotation above the tolerance counts as a change
    out = feed(buf, reg, arm_tool(5 * S, (0, 0, 1.001), (0, 0, 1e-5, 1)), 4)
    assert len(out) == 1


def test_rate_cap_holds_back_then_delivers_from_due(buf: CountingBuffer) -> None:
    reg = LookupRegistry(buf)
    key = reg.add("world", "tool", rate_hz=10.0)  # at most one result per 100 ms
    assert len(reg.due(0)) == 1  # first value comes from the timer too
    assert feed(buf, reg, arm_tool(2 * S, (0, 0, 5)), 50 * MS) == []
    assert feed(buf, reg, arm_tool(3 * S, (0, 0, 6)), 60 * MS) == []
    assert reg.next_due_ns() == 100 * MS
    assert reg.due(99 * MS) == []
    (out,) = reg.due(100 * MS)
    assert out[0] == key and out[1].translation == pytest.approx((1, 1, 6))  # type: ignore
    assert reg.next_due_ns() is None and reg.due(500 * MS) == []
    # after the interval a change goes out at once
    assert len(feed(buf, reg, arm_tool(4 * S, (0, 0, 7)), 250 * MS)) == 1


def test_held_value_is_dropped_when_the_value_returns(buf: CountingBuffer) -> None:
    reg = LookupRegistry(buf)
    reg.add("world", "tool", rate_hz=10.0)
    reg.due(0)
    assert feed(buf, reg, arm_tool(2 * S, (0, 0, 5)), 10 * MS) == []
    assert feed(buf, reg, arm_tool(3 * S, (0, 0, 1)), 20 * MS) == []
    assert reg.next_due_ns() is None and reg.due(200 * MS) == []


def test_pending_until_frames_appear(buf: CountingBuffer) -> None:
    reg = LookupRegistry(buf)
    key = reg.add("world", "/gripper")
    assert key == LookupKey("world", "gripper")
    assert reg.updates(set(), 0) == [] and reg.pending() == [key]
    out = feed(buf, reg, [tf("tool", "gripper", S, (0.1, 0, 0))], 1)
    assert [k for k, _ in out] == [key] and reg.pending() == []
    assert out[0][1].translation == pytest.approx((1.1, 1, 1))  # type: ignore[union-attr]


def test_reparenting_moves_the_chain(buf: CountingBuffer) -> None:
    reg = LookupRegistry(buf)
    key = reg.add("world", "tool")
    reg.updates(set(), 0)
    out = feed(buf, reg, [tf("base", "camera", 2 * S, (0, 0, 2)),
                          tf("camera", "tool", 2 * S, (0, 0, 1))], 1)
    assert [k for k, _ in out] == [key]
    assert out[0][1].translation == pytest.approx((1, 0, 3))  # type: ignore[union-attr]
    buf.asked.clear()
    assert feed(buf, reg, [tf("base", "arm", 2 * S, (5, 5, 5))], 2) == []
    assert buf.asked == []  # arm is no longer on the chain
    assert len(feed(buf, reg, [tf("base", "camera", 3 * S, (0, 0, 4)),
                               tf("camera", "tool", 3 * S, (0, 0, 1))], 3)) == 1


def test_errors_are_delivered_once_per_kind(buf: CountingBuffer) -> None:
    buf.set_transforms([tf("map", "odom", 0, (0, 0, 0))], static=True)
    reg = LookupRegistry(buf)
    key = reg.add("odom", "tool")
    (out,) = reg.updates(set(), 0)
    assert out[0] == key and isinstance(out[1], ConnectivityError)
    assert feed(buf, reg, arm_tool(2 * S, (0, 0, 1)), 1) == []
    # connecting the trees turns the error into a value
    buf.set_transforms([tf("world", "map", 0, (0, 0, 0))], static=True)
    (out,) = reg.updates({"map"}, 2)
    assert isinstance(out[1], StampedTransform)


def test_extrapolation_errors_are_not_repeated_for_every_sample() -> None:
    buf = TfBuffer(cache_time_s=1.0)
    reg = LookupRegistry(buf)
    # a's data moves on, b stopped long ago: the latest common time is before a's window
    buf.set_transforms([tf("w", "b", S, (0, 0, 0))], static=False)
    buf.set_transforms([tf("w", "a", k * S, (k, 0, 0)) for k in (5, 6)], static=False)
    key = reg.add("a", "b")
    (out,) = reg.updates(set(), 0)
    assert out[0] == key and isinstance(out[1], ExtrapolationError)
    assert feed(buf, reg, [tf("w", "a", 7 * S, (7, 0, 0))], 1) == []


def test_same_pair_for_two_clients_is_computed_once(buf: CountingBuffer) -> None:
    reg = LookupRegistry(buf)
    fast = reg.add("world", "tool", tag="client-1")
    slow = reg.add("world", "tool", tag="client-2", rate_hz=1.0)
    assert {k for k, _ in reg.updates(set(), 0)} == {fast, slow}
    buf.asked.clear()
    out = feed(buf, reg, arm_tool(2 * S, (0, 0, 9)), 10 * MS)
    assert [k for k, _ in out] == [fast] and len(buf.asked) == 1
    assert [k for k, _ in reg.due(S)] == [slow]


def test_remove_and_registration_checks(buf: CountingBuffer) -> None:
    reg = LookupRegistry(buf)
    key = reg.add("world", "tool")
    reg.updates(set(), 0)
    assert reg.remove(key) and not reg.remove(key)
    assert reg.keys() == []
    assert feed(buf, reg, arm_tool(2 * S, (0, 0, 9)), 1) == []
    for bad in ({"rate_hz": 0.0}, {"rate_hz": float("nan")}, {"rate_hz": True}):
        with pytest.raises(InvalidArgumentError):
            reg.add("world", "tool", **bad)  # type: ignore[arg-type]
    with pytest.raises(InvalidArgumentError):
        reg.add("", "tool")

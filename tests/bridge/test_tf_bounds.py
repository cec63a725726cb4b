"""The tf buffer keeps a bounded number of frames with bounded names (issue 22, item 8: a
peer's 1 MB frame ids and 100,000 new frames grew the daemon by hundreds of MB, for good).
On each store, through both ways in: transforms (`set_transforms`) and a TFMessage's CDR
bytes (`set_transforms_cdr`, as the daemon stores /tf)."""

from __future__ import annotations

from typing import Callable, Optional

import pytest

from bridge.tf import InvalidArgumentError, RejectedTransformsError, StampedTransform, TfBuffer
from bridge.tf.buffer import MAX_FRAME_ID, MAX_FRAMES

pytestmark = pytest.mark.usefixtures("tf_store")

IDQ = (0.0, 0.0, 0.0, 1.0)
Store = Callable[[TfBuffer, list[StampedTransform]], set[str]]


def tf(parent: str, child: str, stamp: int = 5) -> StampedTransform:
    return StampedTransform(parent, child, stamp, (0.0, 0.0, 1.0), IDQ)


def _cdr(batch: list[StampedTransform]) -> bytes:
    from geometry_msgs.msg import TransformStamped
    from rclpy.serialization import serialize_message
    from tf2_msgs.msg import TFMessage

    msg = TFMessage()
    for tr in batch:
        ts = TransformStamped()
        ts.header.stamp.nanosec = tr.stamp_ns
        ts.header.frame_id, ts.child_frame_id = tr.parent, tr.child
        t = ts.transform.translation
        t.x, t.y, t.z = tr.translation
        ts.transform.rotation.w = 1.0
        msg.transforms.append(ts)
    return serialize_message(msg)


def _as_transforms(buffer: TfBuffer, batch: list[StampedTransform]) -> set[str]:
    return buffer.set_transforms(batch, static=False)


def _as_cdr(buffer: TfBuffer, batch: list[StampedTransform]) -> set[str]:
    changed: Optional[set[str]] = buffer.set_transforms_cdr(_cdr(batch), static=False)
    if changed is None:  # the pure Python store does not read CDR: the daemon's fallback
        from bridge.tf.capability import tf_cdr_to_transforms

        return buffer.set_transforms(tf_cdr_to_transforms(_cdr(batch)), static=False)
    return changed


WAYS = pytest.mark.parametrize("store", [_as_transforms, _as_cdr], ids=["transforms", "cdr"])


def test_the_daemon_bounds_are_tf_names_and_ten_thousand_frames() -> None:
    assert (MAX_FRAME_ID, MAX_FRAMES) == (256, 10_000)


@WAYS
def test_a_frame_id_over_the_bound_is_refused_and_the_rest_kept(store: Store) -> None:
    buffer = TfBuffer(max_frame_id=8)
    long = "x" * 1_000_000
    with pytest.raises(RejectedTransformsError) as raised:
        store(buffer, [tf("world", long), tf("world", "ok"), tf(long, "other"),
                       tf("world", "eightchr")])
    assert raised.value.changed == {"ok", "eightchr"}
    first, second = raised.value.rejected
    assert isinstance(first, InvalidArgumentError)
    assert "transforms[0].child" in str(first) and "at most 8 characters" in str(first)
    # Cut in the error: whole from transforms, cut where it was read (a 1 MB id is not
    # even decoded whole from CDR).
    assert ("(1000000 characters)" in str(first) or str(first).endswith("\u2026"))
    assert len(str(first)) < 300
    assert "transforms[2].parent" in str(second)
    assert buffer.frames() == ["eightchr", "ok", "world"]


@WAYS
def test_new_frames_past_the_bound_are_refused_known_ones_still_update(store: Store) -> None:
    buffer = TfBuffer(max_frames=4)
    assert store(buffer, [tf("world", "a"), tf("a", "b")]) == {"a", "b"}
    with pytest.raises(RejectedTransformsError) as raised:
        store(buffer, [tf("b", "c"), tf("c", "d"), tf("world", "e"), tf("b", "a")])
    # c is the fourth frame; d and e would be a fifth; b -> a links two known frames.
    assert raised.value.changed == {"c", "a"}
    texts = [str(e) for e in raised.value.rejected]
    assert len(texts) == 2 and all("at most 4 frames are kept" in t for t in texts)
    assert "'c' -> 'd'" in texts[0] and "'world' -> 'e'" in texts[1]
    assert buffer.frames() == ["a", "b", "c", "world"]
    # Known frames keep updating once the bound is reached.
    assert store(buffer, [StampedTransform("c", "b", 9, (0.0, 0.0, 2.0), IDQ)]) == {"b"}
    assert buffer.lookup("c", "b").translation == (0.0, 0.0, 2.0)


def test_a_flood_of_refusals_is_counted_and_worded_a_few_at_a_time() -> None:
    """A peer's message of a thousand new frames past the bound: each refusal is counted,
    the first few are worded (wording each one again in Python cost 20 ms a message)."""
    buffer = TfBuffer(max_frames=3)
    store_cdr = _as_cdr
    with pytest.raises(RejectedTransformsError) as raised:
        store_cdr(buffer, [tf("world", f"f{i}") for i in range(1000)])
    assert raised.value.count == 998 and raised.value.changed == {"f0", "f1"}
    assert 1 <= len(raised.value.rejected) <= 998
    assert "(and 997 more)" in str(raised.value)


@WAYS
def test_a_full_buffer_forgets_stale_frames_to_make_room(store: Store) -> None:
    """A peer's once-sent frames must not keep new ones out for good: when the buffer is
    full, dynamic frames silent for longer than the cache time (judged by the newest
    sample of all) are forgotten; static frames, and frames still moving, stay."""
    second = 1_000_000_000
    buffer = TfBuffer(cache_time_s=1.0, max_frames=5)
    buffer.set_transforms([tf("world", "fixed")], static=True)
    flood = [StampedTransform("world", f"junk{i}", 1 * second, (0.0, 0.0, 1.0), IDQ)
             for i in range(3)]
    store(buffer, flood)
    assert len(buffer.frames()) == 5
    # Three seconds later, new frames only (the flood's stamps are all the buffer has).
    later = [StampedTransform("world", "arm", 4 * second, (1.0, 0.0, 0.0), IDQ),
             StampedTransform("arm", "hand", 4 * second, (1.0, 0.0, 0.0), IDQ)]
    assert store(buffer, later) == {"arm", "hand"}
    assert buffer.frames() == ["arm", "fixed", "hand", "world"]
    assert buffer.lookup("world", "hand").translation == (2.0, 0.0, 0.0)
    assert buffer.lookup("world", "fixed").translation == (0.0, 0.0, 1.0)


@WAYS
def test_a_full_buffer_keeps_room_for_the_looked_up_frames_and_their_chains(
        store: Store) -> None:
    """A peer's flood that fills the buffer and keeps its frames fresh must not keep a robot
    that starts later out of every lookup: the frames clients look up, and the chains that
    lead to them (sent root first, as robot_state_publisher does), use a bounded reserve."""
    buffer = TfBuffer(max_frames=5, looked_up_reserve=4)
    buffer.look_up(["base", "tip"])
    with pytest.raises(RejectedTransformsError):
        store(buffer, [tf("junk", f"j{i}") for i in range(6)])
    assert len(buffer.frames()) == 5
    assert store(buffer, [tf("base", "l1"), tf("l1", "tip")]) == {"l1", "tip"}
    assert buffer.lookup("base", "tip").translation == (0.0, 0.0, 2.0)
    # Other new frames are still refused; known ones (the flood's too) still update.
    with pytest.raises(RejectedTransformsError, match="at most 5 frames are kept"):
        store(buffer, [tf("junk", "j9")])
    assert store(buffer, [tf("junk", "j0", stamp=6)]) == {"j0"}
    # The reserve is bounded too: a ninth frame fits, a tenth does not.
    assert store(buffer, [tf("above", "base")]) == {"base"}
    with pytest.raises(RejectedTransformsError, match="at most 5 frames are kept"):
        store(buffer, [tf("higher", "above")])
    assert len(buffer.frames()) == 9
    # Once no client looks them up, they are frames like any other.
    buffer.look_up([])
    with pytest.raises(RejectedTransformsError):
        store(buffer, [tf("base", "other")])


def test_a_looked_up_chain_in_a_long_message_after_a_flood_gets_in() -> None:
    """Through the CDR path with more refusals than are worded: the transforms toward the
    looked-up frame are judged again and stored; the flood's are counted, not stored."""
    buffer = TfBuffer(max_frames=20, looked_up_reserve=20)
    buffer.look_up(["r0", "r12"])
    with pytest.raises(RejectedTransformsError):
        _as_cdr(buffer, [tf("junk", f"j{i}") for i in range(100)])
    chain = [tf(f"r{i}", f"r{i + 1}") for i in range(12)]
    for _ in range(12):  # a robot re-sends its chain at every tick
        try:
            _as_cdr(buffer, chain)
            break
        except RejectedTransformsError:
            continue
    assert buffer.lookup("r0", "r12").translation == (0.0, 0.0, 12.0)
    assert len(buffer.frames()) == 33

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
SECOND = 1_000_000_000
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
        ts.header.stamp.sec, ts.header.stamp.nanosec = divmod(tr.stamp_ns, SECOND)
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


class Clock:
    """The daemon's monotonic clock, set by hand (ns)."""

    def __init__(self) -> None:
        self.now = 1_000 * SECOND

    def __call__(self) -> int:
        return self.now


@pytest.mark.parametrize("flood_sec", [2**31 - 1, 1_000], ids=["future", "now"])
@WAYS
def test_a_flood_stamped_in_the_future_or_now_cannot_keep_a_new_frame_out(
        store: Store, flood_sec: int) -> None:
    """Issue 43, item 5: one message of frames that fills the buffer, stamped sec = 2**31-1
    (or now), then a new frame 50 ms later: before, the new one was refused until the
    flood's stamps were a cache time older than its own (never, for the future ones). Room
    is judged by when the daemon received each frame: the flood is the least recently
    received, a tenth of the bound of it goes, and the new frame is in from its first
    message."""
    clock = Clock()
    buffer = TfBuffer(max_frames=100, clock=clock)
    flood = [StampedTransform("world", f"junk{i:02}", flood_sec * SECOND, (0.0, 0.0, 1.0), IDQ)
             for i in range(99)]
    assert len(store(buffer, flood)) == 99 and len(buffer.frames()) == 100
    clock.now += SECOND // 20
    new = StampedTransform("world", "new", 1_000 * SECOND, (1.0, 0.0, 0.0), IDQ)
    assert store(buffer, [new]) == {"new"}
    assert buffer.lookup("world", "new").translation == (1.0, 0.0, 0.0)
    assert buffer.forgotten == 10  # a tenth of the bound, not one per new frame
    assert len(buffer.frames()) == 91
    assert buffer.has_frame("junk98") and buffer.lookup("world", "junk98").stamp_ns == \
        flood_sec * SECOND
    # The new frame is now among the most recently received: the next one takes room
    # left by the flood without forgetting anything.
    clock.now += SECOND // 20
    tip = StampedTransform("new", "tip", 1_000 * SECOND, (1.0, 0.0, 0.0), IDQ)
    assert store(buffer, [tip]) == {"tip"}
    assert buffer.forgotten == 10
    assert buffer.lookup("world", "tip").translation == (2.0, 0.0, 0.0)


@WAYS
def test_a_full_buffer_forgets_the_frames_received_least_recently(store: Store) -> None:
    """Whatever the stamps say: two floods, the older received first, then a new frame;
    the older flood goes first, the frames silent for longer than the cache time all go,
    and static frames stay."""
    clock = Clock()
    buffer = TfBuffer(cache_time_s=1.0, max_frames=10, clock=clock)
    buffer.set_transforms([tf("world", "fixed")], static=True)
    store(buffer, [tf("world", f"old{i}", stamp=9 * SECOND) for i in range(4)])
    clock.now += SECOND // 2
    store(buffer, [tf("world", f"young{i}", stamp=1) for i in range(4)])
    assert len(buffer.frames()) == 10
    clock.now += SECOND // 4  # none silent for longer than the cache time yet
    assert store(buffer, [tf("world", "a")]) == {"a"}
    assert buffer.frames() == ["a", "fixed", "old1", "old2", "old3", "world"] + [
        f"young{i}" for i in range(4)]
    clock.now += SECOND // 2  # the old ones are silent for longer than the cache time
    assert store(buffer, [tf("world", "b")]) == {"b"}
    assert buffer.frames() == ["a", "b", "fixed", "world"] + [f"young{i}" for i in range(4)]
    assert buffer.forgotten == 4
    assert buffer.lookup("world", "fixed").translation == (0.0, 0.0, 1.0)


@WAYS
def test_a_frame_goes_after_the_frames_below_it(store: Store) -> None:
    """A chain: a parent that a kept frame names stays known, so forgetting it would free
    no room. The tail goes first, up to the root."""
    clock = Clock()
    buffer = TfBuffer(max_frames=6, clock=clock)
    store(buffer, [tf("c4", "c5"), tf("c3", "c4"), tf("c2", "c3"), tf("c1", "c2"),
                   tf("c0", "c1")])
    clock.now += SECOND
    assert store(buffer, [tf("world", "robot")]) == {"robot"}
    assert buffer.frames() == ["c0", "c1", "c2", "c3", "robot", "world"]
    assert buffer.lookup("c0", "c3").translation == (0.0, 0.0, 3.0)


@WAYS
def test_a_message_of_new_names_forgets_once(store: Store) -> None:
    """A peer sending new names in every message, once the buffer is full: each message
    forgets once (a tenth of the bound; one rebuild of the store) and the new frames past
    that room are refused, however many it holds."""
    clock = Clock()
    buffer = TfBuffer(max_frames=20, clock=clock)
    store(buffer, [tf("world", f"old{i:02}") for i in range(19)])
    clock.now += SECOND
    with pytest.raises(RejectedTransformsError) as raised:
        store(buffer, [tf("world", f"new{i}") for i in range(10)])
    assert raised.value.changed == {"new0", "new1"} and raised.value.count == 8
    assert buffer.forgotten == 2 and len(buffer.frames()) == 20
    assert not buffer.has_frame("old00") and buffer.has_frame("old02")


@WAYS
def test_a_batch_never_forgets_its_own_frames(store: Store) -> None:
    """A message of more new frames than the bound: the first ones fill it, the others are
    refused; none of the message's frames makes room for another of it (no churn)."""
    clock = Clock()
    buffer = TfBuffer(max_frames=5, clock=clock)
    with pytest.raises(RejectedTransformsError) as raised:
        store(buffer, [tf("world", f"f{i}") for i in range(8)])
    assert raised.value.changed == {"f0", "f1", "f2", "f3"}
    assert buffer.forgotten == 0
    # Re-sent in the next message: the known ones are kept fresh, and the new ones take the
    # place of... nothing else: every frame the buffer holds is in this message.
    clock.now += SECOND
    with pytest.raises(RejectedTransformsError):
        store(buffer, [tf("world", f"f{i}", stamp=6) for i in range(8)])
    assert buffer.frames() == ["f0", "f1", "f2", "f3", "world"] and buffer.forgotten == 0


@WAYS
def test_a_full_buffer_keeps_room_for_the_looked_up_frames_and_their_chains(
        store: Store) -> None:
    """A peer's flood that fills the buffer in the same message as a robot's chain (so that
    no frame can be forgotten for it) must not keep the robot out of every lookup: the
    frames clients look up, and the chains that lead to them (sent root first, as
    robot_state_publisher does), use a bounded reserve; and they are never forgotten."""
    clock = Clock()
    buffer = TfBuffer(max_frames=5, looked_up_reserve=4, clock=clock)
    buffer.look_up(["base", "tip"])
    chain = [tf("base", "l1"), tf("l1", "tip"), tf("above", "base"), tf("higher", "above")]
    with pytest.raises(RejectedTransformsError, match="at most 5 frames are kept") as raised:
        store(buffer, [tf("junk", f"j{i}") for i in range(6)] + chain)
    # The reserve is bounded too: a ninth frame fits, a tenth does not.
    assert raised.value.changed == {"j0", "j1", "j2", "j3", "l1", "tip", "base"}
    assert len(buffer.frames()) == 9 and buffer.forgotten == 0
    assert buffer.lookup("above", "tip").translation == (0.0, 0.0, 3.0)
    # Later, a new frame takes the place of the flood's, received least recently; the
    # looked-up chain stays however long ago it came.
    clock.now += 100 * SECOND
    assert store(buffer, [tf("base", "j9")]) == {"j9"}
    assert buffer.frames() == ["above", "base", "j9", "l1", "tip"]
    assert buffer.forgotten == 4
    assert buffer.lookup("above", "tip").translation == (0.0, 0.0, 3.0)


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
    # The flood, received least recently, made some room (once per message); the reserve
    # took the rest of the chain.
    assert buffer.forgotten > 0 and len(buffer.frames()) <= 20 + 20

"""The native lane of streamed poses (bridge/core/_native_stream.pyx) against the Python path
it follows: the same bytes for the same messages, the same refusals, and real sockets for
what it writes."""

from __future__ import annotations

import math
import random
import select
import socket
import struct
from pathlib import Path
from typing import Any

import pytest
from geometry_msgs.msg import Pose, PoseStamped, TransformStamped
from rclpy.serialization import deserialize_message, serialize_message

from bridge.codecs import codec_for
from bridge.codecs.fast import NotFast, RawPoseStream
from bridge.core import native_stream
from protocol.conversions import (FLOAT32_BOUND, fits_float32, igtl_timestamp_from_ros,
                                  igtl_timestamp_now)
from protocol.crc64 import crc64
from protocol.freshness import CLOCK_MODULUS
from support import Processes, start_daemon

pytestmark = pytest.mark.skipif(
    not native_stream.available(),
    reason="the native lane is not built here (no Cython or C compiler)")

if native_stream.available():
    from bridge.core import _native_stream as ns

KINDS = [("geometry_msgs/msg/PoseStamped", PoseStamped),
         ("geometry_msgs/msg/TransformStamped", TransformStamped),
         ("geometry_msgs/msg/Pose", Pose)]
ODD = [float("nan"), float("inf"), -float("inf"), 1e300, 1e39, 0.0, -0.0, 5e-324]


def message(cls: type, rng: random.Random, odd: bool) -> Any:
    msg = cls()
    if cls is TransformStamped:
        pos, q = msg.transform.translation, msg.transform.rotation
        msg.child_frame_id = "tool"
    elif cls is PoseStamped:
        pos, q = msg.pose.position, msg.pose.orientation
    else:
        pos, q = msg.position, msg.orientation
    if cls is not Pose:
        msg.header.frame_id = "world"
        msg.header.stamp.sec = rng.choice([1, 1_700_000_000, 2**31 - 1])
        msg.header.stamp.nanosec = rng.choice([0, 1, 499_999_999, 500_000_000, 999_999_999])
    values = [rng.uniform(-10, 10) for _ in range(7)]
    if odd:
        values[rng.randrange(7)] = rng.choice(ODD)
    pos.x, pos.y, pos.z, q.x, q.y, q.z, q.w = values
    return msg


def lane_for(ros_type: str, fanout: Any = None) -> tuple[Any, RawPoseStream]:
    fanout = fanout if fanout is not None else native_stream.new_fanout()
    lane = native_stream.new_lane(fanout, ros_type, 1 << 16, 0.1)
    return lane, RawPoseStream(codec_for(ros_type), "dev", {"k": "v"})


def teach(lane: Any, stream: RawPoseStream, data: bytes) -> None:
    """Give the lane the template the Python path made for `data`'s frame ids."""
    template = stream.convert(data)[0]
    frame_id, child = stream.ids
    lane.set_template(frame_id.encode(), child.encode(), *template.wire_parts())


@pytest.mark.parametrize("ros_type, cls", KINDS)
def test_the_lane_writes_the_python_paths_bytes_and_leaves_it_the_same_messages(
        ros_type: str, cls: type) -> None:
    rng = random.Random(ros_type)
    lane, stream = lane_for(ros_type)
    teach(lane, stream, bytes(serialize_message(message(cls, rng, False))))
    compared = refused = 0
    for i in range(2000):
        data = bytes(serialize_message(message(cls, rng, odd=i % 7 == 0)))
        try:
            template, content, timestamp, _ = stream.convert(data)
        except NotFast:
            template = None
        for version in (1, 2):
            got = lane.encode(data, version, 77)
            if template is None:
                assert got is None
                refused += 1
                continue
            want = template.encode(content, timestamp, version, 77)
            if cls is Pose:  # no stamp: both take the time now, so all but it and the CRC
                assert (got[:34], got[42:50], got[58:]) == (want[:34], want[42:50], want[58:])
            else:
                assert got == want
            compared += 1
    assert compared > 3000 and refused > 50


def test_its_crc_is_protocols() -> None:
    rng = random.Random(1)
    for size in (0, 1, 9, 48, 160, 3000):
        data = bytes(rng.randrange(256) for _ in range(size))
        assert ns.crc64(data) == crc64(data)


def test_other_frame_ids_and_bad_bytes_go_to_python() -> None:
    lane, stream = lane_for("geometry_msgs/msg/PoseStamped")
    msg = message(PoseStamped, random.Random(2), False)
    data = bytes(serialize_message(msg))
    assert lane.encode(data, 2, 1) is None  # no template yet
    teach(lane, stream, data)
    assert lane.encode(data, 2, 1) is not None
    msg.header.frame_id = "base"
    assert lane.encode(bytes(serialize_message(msg)), 2, 1) is None
    assert lane.encode(data[:-1], 2, 1) is None  # cut short
    assert lane.encode(b"\x00\x00" + data[2:], 2, 1) is None  # big-endian CDR


@pytest.mark.parametrize("ros_type, cls", KINDS)
def test_a_message_cut_short_anywhere_or_with_other_ids_of_the_same_size_goes_to_python(
        ros_type: str, cls: type) -> None:
    lane, stream = lane_for(ros_type)
    data = posed(cls, (1.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0))
    teach(lane, stream, data)
    assert lane.encode(data, 2, 1) is not None
    for n in range(len(data)):  # every field's bound checked: none read past the end
        assert lane.encode(data[:n], 2, 1) is None, n
        with pytest.raises(NotFast):  # the Python path leaves it to rclpy too
            stream.convert(data[:n])
    if cls is Pose:
        return
    for ids in [("wOrld", "tool"), ("world", "tOol")]:
        msg = deserialize_message(data, cls)
        msg.header.frame_id = ids[0]
        if cls is TransformStamped:
            msg.child_frame_id = ids[1]
        elif ids[1] != "tool":
            continue
        assert lane.encode(bytes(serialize_message(msg)), 2, 1) is None, ids


def posed(cls: type, t: tuple[float, float, float], q: tuple[float, float, float, float],
          sec: int = 1_700_000_000, nanosec: int = 5) -> bytes:
    msg = message(cls, random.Random(0), False)
    if cls is TransformStamped:
        pos, rot = msg.transform.translation, msg.transform.rotation
    elif cls is PoseStamped:
        pos, rot = msg.pose.position, msg.pose.orientation
    else:
        pos, rot = msg.position, msg.orientation
    if cls is not Pose:
        msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
    pos.x, pos.y, pos.z = t
    rot.x, rot.y, rot.z, rot.w = q
    return bytes(serialize_message(msg))


# Around protocol.conversions.fits_float32's bound, once in mm (x1000): both sides of it.
EDGE = FLOAT32_BOUND / 1000
LENGTHS = [EDGE, -EDGE, math.nextafter(EDGE, 0.0), math.nextafter(EDGE, math.inf),
           math.nextafter(-EDGE, 0.0), 3.4e35, 3.41e35, 1e36, -1e36, 1e306, -1e306, 1.7e308,
           math.inf, -math.inf, math.nan, 1.5, -0.0]


@pytest.mark.parametrize("ros_type, cls", KINDS)
def test_the_lane_and_the_python_path_judge_lengths_by_the_one_float32_rule(
        ros_type: str, cls: type) -> None:
    """Every length in x, y and z: the lane writes exactly what fits_float32 lets through,
    with the Python path's bytes, and leaves the rest to it (which refuses it)."""
    lane, stream = lane_for(ros_type)
    teach(lane, stream, posed(cls, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)))
    written = left = 0
    for length in LENGTHS:
        for axis in range(3):
            t = [0.25, -0.5, 0.75]
            t[axis] = length
            data = posed(cls, (t[0], t[1], t[2]), (0.0, 0.0, 0.0, 1.0))
            fits = fits_float32(length * 1000)
            got = lane.encode(data, 2, 7)
            assert (got is not None) == fits, (length, axis)
            if not fits:
                with pytest.raises(NotFast):
                    stream.convert(data)
                left += 1
                continue
            template, content, timestamp, _ = stream.convert(data)
            want = template.encode(content, timestamp, 2, 7)
            if cls is Pose:  # the time now: all but it and the CRC
                assert (got[:34], got[42:50], got[58:]) == (want[:34], want[42:50], want[58:])
            else:
                assert got == want
            sent = struct.unpack(">12f", got[70:118])  # after the header and extended header
            assert all(math.isfinite(v) for v in sent) and sent[9 + axis] == \
                struct.unpack(">f", struct.pack(">f", length * 1000))[0]
            written += 1
    # Seven lengths fit (the bound over 1000 and its lower neighbour round below it in mm);
    # ten do not (from 3.41e35 m on, and inf, NaN).
    assert (written, left) == (3 * 7, 3 * 10)


def test_a_rotation_the_lane_cannot_normalise_goes_to_python() -> None:
    lane, stream = lane_for("geometry_msgs/msg/PoseStamped")
    teach(lane, stream, posed(PoseStamped, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)))
    for q in [(0.0, 0.0, 0.0, 0.0), (1e-13, 0.0, 0.0, 0.0), (1e200, 0.0, 0.0, 1.0),
              (0.0, math.nan, 0.0, 1.0), (0.0, 0.0, math.inf, 1.0)]:
        assert lane.encode(posed(PoseStamped, (1.0, 2.0, 3.0), q), 1, 0) is None, q
    assert lane.encode(posed(PoseStamped, (1.0, 2.0, 3.0), (0.0, 0.0, 2.0, 0.0)), 1, 0)


@pytest.mark.parametrize("ros_type, cls", KINDS[:2])
def test_a_stamp_out_of_range_is_the_time_now_in_the_lane_as_in_python(
        ros_type: str, cls: type) -> None:
    """igtl_stamp_or_now: an unset, negative or over-long stamp becomes the time now."""
    lane, stream = lane_for(ros_type)
    teach(lane, stream, posed(cls, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)))
    for sec, nanosec in [(-1, 0), (0, 0), (-(2**31), 5), (1, 1_000_000_000),
                         (1, 2**32 - 1)]:
        data = posed(cls, (1.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0), sec, nanosec)
        before = igtl_timestamp_now()
        got = lane.encode(data, 1, 0)
        python = stream.convert(data)[2]
        after = igtl_timestamp_now()
        assert got is not None
        stamp = struct.unpack(">Q", got[34:42])[0]
        assert before <= stamp <= after and before <= python <= after, (sec, nanosec)
    good = posed(cls, (1.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0), 1, 999_999_999)
    assert struct.unpack(">Q", lane.encode(good, 1, 0)[34:42])[0] == \
        igtl_timestamp_from_ros(1, 999_999_999) == stream.convert(good)[2]


def pair() -> tuple[socket.socket, socket.socket]:
    a, b = socket.socketpair()
    a.setblocking(False)
    return a, b


# A message's writes to every client in one io_uring call, or one sendmsg each (where
# io_uring is not allowed, or --send-batch off): the same results either way.
WRITES = pytest.mark.parametrize("batch", [True, False], ids=["one-call", "one-write-each"])


def taught(seed: int, batch: bool = True) -> tuple[Any, Any, RawPoseStream, bytes]:
    """(fanout, a PoseStamped lane on it that knows the message's frame ids, its Python
    path, the message)."""
    fanout = ns.Fanout(CLOCK_MODULUS, batch=batch)
    lane, stream = lane_for("geometry_msgs/msg/PoseStamped", fanout)
    data = bytes(serialize_message(message(PoseStamped, random.Random(seed), False)))
    teach(lane, stream, data)
    return fanout, lane, stream, data


def open_slot(sock: socket.socket, version: int = 2, owner: Any = None) -> Any:
    slot = native_stream.new_slot(owner)
    with slot:
        slot.connect(sock)
        slot.header_version = version
        slot.open = True
    return slot


def available_now(sock: socket.socket) -> bytes:
    """What ``sock`` has received so far, without waiting."""
    chunks = []
    while select.select([sock], [], [], 0)[0]:
        chunk = sock.recv(1 << 16)
        if not chunk:
            break
        chunks.append(chunk)
    return b"".join(chunks)


def read_exactly(sock: socket.socket, n: int) -> bytes:
    sock.settimeout(5)
    out = b""
    while len(out) < n:
        out += sock.recv(n - len(out))
    return out


@WRITES
def test_the_lane_writes_each_open_client_its_header_version_and_keeps_the_value(
        batch: bool) -> None:
    fanout, lane, stream, data = taught(3, batch)
    ends = [pair(), pair()]
    slots = [open_slot(ours, version) for version, (ours, _) in zip((1, 2), ends)]
    with fanout:
        fanout.set_slots(slots)
        lane.enabled = True
    assert lane.handle(data) == ns.HANDLED
    with fanout:
        content, timestamp, clock, values = lane.latest()
        assert lane.last() == data and lane.count == 1 and lane.arrivals()[2] == 1
    template, want_content, want_stamp, want_values = stream.convert(data)
    assert (content, timestamp, values) == (want_content, want_stamp, want_values)
    for version, (_, theirs) in zip((1, 2), ends):
        want = template.encode(content, timestamp, version, clock)
        assert read_exactly(theirs, len(want)) == want
    assert [s.sent for s in slots] == [1, 1]
    with fanout:
        lane.forget()
        assert lane.last() is None and lane.latest() is None
    for ours, theirs in ends:
        ours.close()
        theirs.close()


def test_a_held_fanout_a_disabled_lane_or_a_closed_client_leave_it_to_python() -> None:
    fanout, lane, _, data = taught(4)
    ours, theirs = pair()
    slot = open_slot(ours)
    with fanout:
        fanout.set_slots([slot])
    assert lane.handle(data) == ns.TO_PYTHON  # not enabled
    with fanout:
        lane.enabled = True
        fanout.hold = True
    assert lane.handle(data) == ns.TO_PYTHON
    with fanout:
        fanout.hold = False
    with slot:
        slot.open = False
    assert lane.handle(data) == ns.TO_PYTHON
    with slot:
        slot.open = True
    assert lane.handle(data) == ns.HANDLED
    with fanout:
        assert lane.count == 1
    ours.close()
    theirs.close()


class Owner:
    pass


def test_a_client_that_cannot_take_a_frame_whole_keeps_the_rest_or_is_handed_it() -> None:
    fanout, lane, _, data = taught(5)
    ours, theirs = pair()
    ours.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4096)
    owner = Owner()
    slot = open_slot(ours, owner=owner)
    with fanout:
        fanout.set_slots([slot])
        lane.enabled = True
    results = []
    while not results or results[-1] == ns.HANDLED:  # the peer reads nothing: it fills up
        results.append(lane.handle(data))
    assert results[-1] == ns.HANDLED_SETTLE
    assert lane.handle(data) == ns.TO_PYTHON  # until Python settles
    with fanout:
        missed, stashed = lane.settle()
    assert [r() for r in missed + stashed] == [owner]
    with slot:
        assert not slot.open
        rest = slot.take_stash()
    # Whatever the kernel took, then the stash (if any), is a whole number of frames.
    frame_size = len(lane.encode(data, 2, 1))
    taken = available_now(theirs)
    total = len(taken) + len(rest or b"")
    if missed:
        assert rest is None and total % frame_size == 0
    else:
        assert rest is not None and total % frame_size == 0
    ours.close()
    theirs.close()


def test_a_frame_of_parts_a_socket_takes_in_part_keeps_its_rest_in_order() -> None:
    """`Slot.send` of parts (a session's image: header, pixels where they lie, metadata),
    larger than the socket takes at once: what it took and the rest kept are the frame."""
    ours, theirs = pair()
    ours.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4096)
    slot = open_slot(ours)
    rng = random.Random(9)
    header = bytes(rng.randrange(256) for _ in range(58))
    pixels = bytes(rng.randrange(256) for _ in range(1 << 20))
    strided = memoryview(pixels)[::2]  # not contiguous: the lane copies it
    meta = b"metadata"
    with slot:
        assert slot.send((header, strided, meta)) == ns.STASHED
        assert not slot.open and slot.has_stash and slot.sent == 1
        # A slot holding a rest writes nothing more: that would pass it.
        assert slot.send(b"next") == ns.REFUSED
        rest = slot.take_stash()
        assert slot.take_stash() is None and not slot.has_stash
    frame = header + pixels[::2] + meta
    taken = available_now(theirs)
    assert 0 < len(taken) < len(frame) and taken + rest == frame
    with slot:
        with pytest.raises(ValueError, match="expected 1 to 8 parts, got 9"):
            slot.send((b"x",) * 9)
        with pytest.raises(ValueError, match="expected 1 to 8 parts, got 0"):
            slot.send(())
    ours.close()
    theirs.close()


def test_a_full_socket_refuses_a_gone_peer_breaks_and_a_disconnected_slot_refuses() -> None:
    ours, theirs = pair()
    slot = open_slot(ours)
    with slot:
        while (result := slot.send(b"x" * 4096)) == ns.SENT:  # the peer reads nothing
            pass
        assert result in (ns.REFUSED, ns.STASHED)
    ours.close()
    theirs.close()
    ours, theirs = pair()
    theirs.close()  # EPIPE: the loop's transport meets the same error
    slot = open_slot(ours)
    with slot:
        assert slot.send(b"frame") == ns.BROKEN
        slot.disconnect()
        assert slot.fd == -1 and not slot.open
        assert slot.send(b"frame") == ns.REFUSED
    ours.close()


def test_the_lane_refuses_what_it_cannot_be_made_of() -> None:
    fanout = ns.Fanout(CLOCK_MODULUS)
    with pytest.raises(ValueError, match="clock_modulus: expected 2 or more, got 1"):
        ns.Fanout(1)
    with pytest.raises(ValueError, match="kind: expected POSE, POSE_STAMPED or "
                                         "TRANSFORM_STAMPED, got 7"):
        ns.PoseLane(fanout, 7, 1 << 16, 0.1)
    lane = ns.PoseLane(fanout, ns.POSE, 1 << 16, 0.1)
    assert lane.frame_ids() is None
    with pytest.raises(ValueError, match="expected at most 12 and 20 bytes, got 13 and 3"):
        lane.set_template(b"", b"", b"T" * 13, b"dev", 0, 0, b"")
    with pytest.raises(ValueError, match=r"expected those of meta_tail \(2 bytes\), got 1 \+ 0"):
        lane.set_template(b"", b"", b"TRANSFORM", b"dev", 1, 0, b"ab")
    with pytest.raises(ValueError, match="header_version: expected 1 or 2, got 3"):
        lane.encode(b"", 3, 0)
    lane.set_template(b"w", b"", b"TRANSFORM", b"dev", 0, 0, b"")
    assert lane.frame_ids() == (b"w", b"")


@WRITES
def test_a_handle_that_may_not_wait_leaves_a_held_lock_and_writes_to_all_or_none(
        batch: bool) -> None:
    # What a middleware thread calls: it holds the middleware's locks, so it never waits
    # for one of ours, which a thread needing the interpreter may hold.
    fanout, lane, _, data = taught(6, batch)
    ends = [pair(), pair()]
    slots = [open_slot(ours) for ours, _ in ends]
    with fanout:
        fanout.set_slots(slots)
        lane.enabled = True
    with fanout:  # this thread's hold: a non-recursive lock, so a try fails as another's
        assert lane.handle(data, wait=False) == ns.BUSY
    with slots[1]:
        assert lane.handle(data, wait=False) == ns.BUSY
    assert [available_now(theirs) for _, theirs in ends] == [b"", b""]  # none, not one
    with fanout:
        assert lane.count == 0 and lane.last() is None
    assert lane.handle(data, wait=False) == ns.HANDLED
    want = lane.encode(data, 2, 0)
    assert [len(read_exactly(theirs, len(want))) for _, theirs in ends] == [len(want)] * 2
    assert [s.sent for s in slots] == [1, 1]
    for ours, theirs in ends:
        ours.close()
        theirs.close()


@WRITES
def test_a_full_client_and_a_gone_one_miss_the_value_and_the_others_get_every_frame(
        batch: bool) -> None:
    fanout, lane, _, data = taught(7, batch)
    healthy = [pair() for _ in range(3)]
    full_end, gone_end = pair(), pair()
    full_end[0].setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4096)
    gone_end[1].close()  # its peer has gone: a write fails with EPIPE
    owners = {name: Owner() for name in ("full", "gone")}
    slots = ([open_slot(ours) for ours, _ in healthy[:2]]
             + [open_slot(full_end[0], owner=owners["full"]),
                open_slot(gone_end[0], owner=owners["gone"]), open_slot(healthy[2][0])])
    with fanout:
        fanout.set_slots(slots)
        lane.enabled = True
    assert fanout.batched == batch
    frame = lane.encode(data, 2, 0)
    handled = 0
    settled: list[list[Any]] = []  # owners handed to Python, each time it settles
    while owners["full"] not in sum(settled, []):  # the full client's peer reads nothing
        assert lane.handle(data) in (ns.HANDLED, ns.HANDLED_SETTLE)
        handled += 1
        # The healthy ones get each frame whole, whatever the others' writes did.
        for _, theirs in healthy:
            got = read_exactly(theirs, len(frame))
            assert got[:2] == b"\x00\x02" and got[2:14] == b"TRANSFORM\0\0\0"
        with fanout:
            missed, stashed = lane.settle()
            if missed or stashed:
                settled.append([r() for r in missed + stashed])
                # As a session does: a client handed to Python leaves the native lane.
                fanout.set_slots([s for s in fanout.slots
                                  if s.owner is None or s.owner() not in settled[-1]])
    assert owners["gone"] in settled[0]  # at once, on the first frame
    assert len(fanout.slots) == 3
    with slots[2]:
        rest = slots[2].take_stash()
    taken = available_now(full_end[1])
    assert len(taken) + len(rest or b"") == (handled - 1) * len(frame) + (
        len(frame) if rest else 0)  # whole frames, the last one's rest kept or none of it
    assert [s.sent for s in slots[:2]] == [handled] * 2 and slots[4].sent == handled
    assert slots[3].sent == 0
    for ours, theirs in healthy + [full_end]:
        ours.close()
        theirs.close()
    gone_end[0].close()


@WRITES
def test_more_clients_than_one_call_takes_each_get_the_frame_once(batch: bool) -> None:
    fanout, lane, _, data = taught(8, batch)
    ends = [pair() for _ in range(70)]  # over the ring's 64 writes per call
    slots = [open_slot(ours) for ours, _ in ends]
    with fanout:
        fanout.set_slots(slots)
        lane.enabled = True
    frame = lane.encode(data, 2, 0)
    for _ in range(3):
        assert lane.handle(data) == ns.HANDLED
    got = [read_exactly(theirs, 3 * len(frame)) for _, theirs in ends]
    assert got[0][:14] == b"\x00\x02TRANSFORM\0\0\0" and got == [got[0]] * len(ends)
    assert [available_now(theirs) for _, theirs in ends] == [b""] * len(ends)
    assert {s.sent for s in slots} == {3}
    for ours, theirs in ends:
        ours.close()
        theirs.close()


@WRITES
def test_a_lane_with_its_own_clients_writes_to_them_only_and_settles_only_them(
        batch: bool) -> None:
    """A device limited to an audience (docs/security.md, "Who owns a bridge") keeps its
    lane: the lane writes to its own subset of the fanout's clients, judges only their
    slots, and hands back only theirs; without a subset it writes to every client."""
    fanout, lane, _, data = taught(9, batch)
    ends = [pair() for _ in range(3)]
    owners = [Owner() for _ in ends]
    slots = [open_slot(ours, owner=owner) for (ours, _), owner in zip(ends, owners)]
    frame = lane.encode(data, 2, 0)
    with fanout:
        fanout.set_slots(slots)
        lane.set_slots([slots[0], slots[2]])
        lane.enabled = True
        assert lane.slots == [slots[0], slots[2]]
    with slots[1]:
        slots[1].open = False  # not the lane's: it does not send the lane to Python
    assert lane.handle(data) == ns.HANDLED
    assert [len(available_now(theirs)) for _, theirs in ends] == [len(frame), 0, len(frame)]
    assert [s.sent for s in slots] == [1, 0, 1]
    with slots[2]:
        slots[2].open = False  # one of its own is closed: the Python path's
    assert lane.handle(data) == ns.TO_PYTHON
    with slots[2]:
        slots[2].open = True
    ends[2][1].close()  # its peer has gone: only its owner is handed back
    assert lane.handle(data) == ns.HANDLED_SETTLE
    with fanout:
        missed, stashed = lane.settle()
    assert [r() for r in missed] == [owners[2]] and stashed == []
    with fanout:
        lane.set_slots([])  # nobody's: written to no one, kept for a later client
    assert lane.handle(data) == ns.HANDLED
    with fanout:
        assert lane.count == 3 and lane.latest() is not None
        lane.set_slots(None)  # every client of the fanout again
        assert lane.slots is None
    with slots[1]:
        slots[1].open = True
    with slots[2]:
        slots[2].disconnect()
    with fanout:
        fanout.set_slots(slots[:2])
    assert lane.handle(data) == ns.HANDLED
    assert [len(available_now(theirs)) for _, theirs in ends[:2]] == [2 * len(frame),
                                                                      len(frame)]
    for ours, theirs in ends:
        ours.close()
        theirs.close()


def test_a_lanes_clients_are_slots() -> None:
    fanout, lane, _, _ = taught(10)
    with fanout, pytest.raises(TypeError):
        lane.set_slots([object()])


def _io_uring_allowed() -> tuple[bool, str]:
    """Whether this process may set up an io_uring, as the system says (not as the lane
    says: that is what is tested)."""
    sysctl = Path("/proc/sys/kernel/io_uring_disabled")
    disabled = sysctl.read_text().strip() if sysctl.exists() else "0"
    if disabled != "0":
        return False, f"io_uring is disabled here (kernel.io_uring_disabled={disabled})"
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("Seccomp:") and line.split()[1] != "0":
            return False, "a seccomp filter may forbid io_uring here (a container's profile)"
    return True, ""


@pytest.mark.ros
def test_the_daemons_fanout_writes_in_one_call_where_allowed_unless_told_not_to(
        processes: Processes) -> None:
    """`--send-batch on` (the default) and `off`, from the daemon's command line."""
    allowed, why = _io_uring_allowed()
    if not allowed:
        pytest.skip(why)
    assert native_stream.new_fanout().batched
    assert not native_stream.new_fanout(batch=False).batched
    for args, mode in (((), "one io_uring call for all clients at a time (--send-batch on)"),
                       (("--send-batch", "off"), "one sendmsg per client")):
        daemon = start_daemon(processes, *args)
        daemon.child.wait_for_output("streams written to clients", timeout=30)
        assert f"streams written to clients {mode}" in daemon.child.output()
        daemon.child.stop()

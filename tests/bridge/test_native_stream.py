"""The native lane of streamed poses (bridge/core/_native_stream.pyx) against the Python path
it follows: the same bytes for the same messages, the same refusals, and real sockets for
what it writes."""

from __future__ import annotations

import random
import select
import socket
from typing import Any

import pytest
from geometry_msgs.msg import Pose, PoseStamped, TransformStamped
from rclpy.serialization import serialize_message

from bridge.codecs import codec_for
from bridge.codecs.fast import NotFast, RawPoseStream
from bridge.core import native_stream
from protocol.crc64 import crc64

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


def test_other_frame_ids_a_stamp_out_of_range_and_bad_bytes_go_to_python() -> None:
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


def pair() -> tuple[socket.socket, socket.socket]:
    a, b = socket.socketpair()
    a.setblocking(False)
    return a, b


def taught(seed: int) -> tuple[Any, Any, RawPoseStream, bytes]:
    """(fanout, a PoseStamped lane on it that knows the message's frame ids, its Python
    path, the message)."""
    fanout = native_stream.new_fanout()
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


def test_the_lane_writes_each_open_client_its_header_version_and_keeps_the_value() -> None:
    fanout, lane, stream, data = taught(3)
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


def test_a_handle_that_may_not_wait_leaves_a_held_lock_and_writes_to_all_or_none() -> None:
    # What a middleware thread calls: it holds the middleware's locks, so it never waits
    # for one of ours, which a thread needing the interpreter may hold.
    fanout, lane, _, data = taught(6)
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

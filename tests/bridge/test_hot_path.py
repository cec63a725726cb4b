"""The streaming hot path: CDR bytes read without rclpy, frames made without a `Message`,
direct writes from the executor thread, and the hub's guarantees around them (order,
nothing lost for a client that keeps up, newest-wins for one that does not, a removed
device staying gone). Real sockets, real rclpy serialization; no timing assertions."""

from __future__ import annotations

import asyncio
import math
import socket
import struct
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any, Iterator

import pytest
from geometry_msgs.msg import Pose, PoseStamped, TransformStamped
from hypothesis import given, settings
from hypothesis import strategies as st
from rclpy.serialization import deserialize_message, serialize_message

from bridge.codecs import CodecError, codec_for
from bridge.codecs.cdr import CdrError, read_pose, read_pose_stamped, read_transform_stamped
from bridge.codecs.fast import (NotFast, RawPoseStream, pose_document, read_raw_pose,
                                transform_body)
from bridge.codecs.generic import document_to_json, message_to_json
from bridge.core.hub import Hub
from bridge.core.outbox import Frame, TemplateFrame
from bridge.core.session import ClientSession, SessionLimits
from protocol.conversions import igtl_timestamp_from_ros
from protocol.framing import Decoder, encode
from protocol.messages import Message, String

REPO = Path(__file__).resolve().parents[2]

finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False)
unit = st.floats(min_value=-1.0, max_value=1.0, allow_nan=False)
names = st.text(min_size=0, max_size=23)  # every alignment of what follows a string
stamps = st.tuples(st.integers(0, 2**31 - 1), st.integers(0, 999_999_999))


def _quaternion(q: tuple[float, float, float, float]) -> tuple[float, float, float, float]:
    return q if sum(v * v for v in q) > 1e-6 else (0.0, 0.0, 0.0, 1.0)


def _pose_stamped(stamp: tuple[int, int], frame: str, t: tuple[float, ...],
                  q: tuple[float, ...]) -> PoseStamped:
    msg = PoseStamped()
    msg.header.stamp.sec, msg.header.stamp.nanosec = stamp
    msg.header.frame_id = frame
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = t
    o = msg.pose.orientation
    o.x, o.y, o.z, o.w = q
    return msg


def _transform_stamped(stamp: tuple[int, int], frame: str, child: str, t: tuple[float, ...],
                       q: tuple[float, ...]) -> TransformStamped:
    msg = TransformStamped()
    msg.header.stamp.sec, msg.header.stamp.nanosec = stamp
    msg.header.frame_id, msg.child_frame_id = frame, child
    tr = msg.transform.translation
    tr.x, tr.y, tr.z = t
    r = msg.transform.rotation
    r.x, r.y, r.z, r.w = q
    return msg


# --------------------------------------------------------------------- CDR -> numbers


@settings(max_examples=200, deadline=None)
@given(stamps, names, st.tuples(finite, finite, finite), st.tuples(unit, unit, unit, unit))
def test_pose_stamped_bytes_read_as_rclpy_deserializes_them(stamp, frame, t, q) -> None:
    data = serialize_message(_pose_stamped(stamp, frame, t, q))
    ours = read_pose_stamped(data)
    theirs = deserialize_message(data, PoseStamped)
    p, o = theirs.pose.position, theirs.pose.orientation
    assert ours == (theirs.header.stamp.sec, theirs.header.stamp.nanosec,
                    theirs.header.frame_id, "", p.x, p.y, p.z, o.x, o.y, o.z, o.w)


@settings(max_examples=200, deadline=None)
@given(stamps, names, names, st.tuples(finite, finite, finite),
       st.tuples(unit, unit, unit, unit))
def test_transform_stamped_bytes_read_as_rclpy_deserializes_them(stamp, frame, child, t,
                                                                  q) -> None:
    data = serialize_message(_transform_stamped(stamp, frame, child, t, q))
    ours = read_transform_stamped(data)
    theirs = deserialize_message(data, TransformStamped)
    tr, r = theirs.transform.translation, theirs.transform.rotation
    assert ours == (theirs.header.stamp.sec, theirs.header.stamp.nanosec,
                    theirs.header.frame_id, theirs.child_frame_id,
                    tr.x, tr.y, tr.z, r.x, r.y, r.z, r.w)


@given(st.tuples(finite, finite, finite), st.tuples(unit, unit, unit, unit))
def test_pose_bytes_read_as_rclpy_deserializes_them(t, q) -> None:
    msg = Pose()
    msg.position.x, msg.position.y, msg.position.z = t
    msg.orientation.x, msg.orientation.y, msg.orientation.z, msg.orientation.w = q
    assert read_pose(serialize_message(msg))[4:] == (*t, *q)


any_float = st.floats(allow_nan=True, allow_infinity=True)


@settings(max_examples=200, deadline=None)
@given(st.sampled_from(["geometry_msgs/msg/Pose", "geometry_msgs/msg/PoseStamped",
                        "geometry_msgs/msg/TransformStamped"]), stamps, names, names,
       st.tuples(any_float, any_float, any_float), st.tuples(unit, unit, unit, any_float))
def test_a_hot_pose_s_whole_message_is_the_generic_json_of_the_message(
        ros_type, stamp, frame, child, t, q) -> None:
    """The message stream reads a hot pose from its bytes (`pose_document`): the same
    JSON text as the generic way from the rclpy message, NaN and infinities included."""
    if ros_type == "geometry_msgs/msg/Pose":
        msg: Any = _pose_stamped(stamp, frame, t, q).pose
    elif ros_type == "geometry_msgs/msg/PoseStamped":
        msg = _pose_stamped(stamp, frame, t, q)
    else:
        msg = _transform_stamped(stamp, frame, child, t, q)
    data = serialize_message(msg)
    ours = document_to_json(pose_document(ros_type, read_raw_pose(ros_type, data)))
    assert ours == message_to_json(deserialize_message(data, type(msg)))


def test_bytes_it_does_not_read_are_refused_not_misread() -> None:
    data = serialize_message(_pose_stamped((1, 2), "world", (1, 2, 3), (0, 0, 0, 1)))
    with pytest.raises(CdrError, match="little-endian"):
        read_pose_stamped(b"\x00\x00" + data[2:])  # big-endian CDR
    with pytest.raises(CdrError):
        read_pose_stamped(data[:40])  # cut short
    with pytest.raises(CdrError):
        read_transform_stamped(data[:14])


# --------------------------------------------------------------- bytes on the wire


def _ordinary_bytes(codec_name: str, msg: Any, device: str, metadata: dict[str, str],
                    version: int) -> bytes:
    """What the ordinary path (rclpy message -> codec -> Message -> encode) sends, for the
    message as the daemon receives it: a string ends at its first NUL on the wire."""
    msg = deserialize_message(serialize_message(msg), type(msg))
    encoded = codec_for(codec_name).encode(msg)
    meta = dict(metadata)
    meta.update(encoded.metadata)
    assert encoded.stamp is not None
    message = Message(device_name=device, body=encoded.body,
                      timestamp=igtl_timestamp_from_ros(*encoded.stamp), metadata=meta)
    return encode(message, header_version=version)


def _fast_frame(codec_name: str, msg: Any, device: str,
                metadata: dict[str, str]) -> TemplateFrame:
    stream = RawPoseStream(codec_for(codec_name), device, metadata)
    template, content, timestamp, values = stream.convert(serialize_message(msg))
    return TemplateFrame(template, content, timestamp, values, transform_body)


@settings(max_examples=150, deadline=None)
@given(st.tuples(st.integers(1, 2**31 - 1), st.integers(0, 999_999_999)), names, names,
       st.tuples(finite, finite, finite), st.tuples(unit, unit, unit, unit))
def test_fast_frames_are_the_bytes_of_the_ordinary_path(stamp, frame, child, t, q) -> None:
    q = _quaternion(q)
    metadata = {"ros2.topic": "/tool"}
    for name, msg in (("PoseStamped", _pose_stamped(stamp, frame, t, q)),
                      ("TransformStamped", _transform_stamped(stamp, frame, child, t, q))):
        fast = _fast_frame(name, msg, "tool", metadata)
        for version in (1, 2):
            assert fast.encoded(version) == _ordinary_bytes(name, msg, "tool", metadata,
                                                            version), (name, version)
        # The Message made on demand (GET_TRANSFORM, a late v1 client) says the same.
        assert encode(fast.message, header_version=2) == fast.encoded(2)


def test_what_the_fast_path_cannot_convert_goes_the_ordinary_way() -> None:
    stream = RawPoseStream(codec_for("PoseStamped"), "tool", {})
    nan = _pose_stamped((1, 0), "w", (math.nan, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))
    zero = _pose_stamped((1, 0), "w", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0))
    huge = _pose_stamped((1, 0), "w", (1e300, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))
    for msg in (nan, zero, huge):
        with pytest.raises(NotFast):
            stream.convert(serialize_message(msg))


@pytest.mark.parametrize("x_m", [1e306, 1e36])
def test_a_finite_length_beyond_float32_in_mm_is_refused_by_both_ways(x_m: float) -> None:
    """Finite in metres, so ROS takes it; infinite as the float32 a TRANSFORM carries."""
    msg = _pose_stamped((1, 0), "w", (0.0, x_m, 0.0), (0.0, 0.0, 0.0, 1.0))
    with pytest.raises(NotFast):
        RawPoseStream(codec_for("PoseStamped"), "tool", {}).convert(serialize_message(msg))
    with pytest.raises(CodecError) as info:
        codec_for("PoseStamped").encode(msg)
    assert info.value.field == "pose.position"
    assert info.value.got == f"{[0.0, x_m, 0.0]} m"


# ------------------------------------------------------------- hub + real sockets


class _Peer:
    """A real TCP client of a `ClientSession` served by a loop in a thread."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        self.decoder = Decoder()

    def read_until(self, count: int, timeout: float = 30.0) -> list[Message]:
        self.sock.settimeout(timeout)
        out: list[Message] = []
        while len(out) < count:
            data = self.sock.recv(1 << 16)
            assert data, f"closed after {len(out)} of {count} messages"
            self.decoder.feed(data)
            out.extend(self.decoder.messages())
        return out


class _Served:
    """A hub and its sessions on a loop in a thread: the daemon's wiring without ROS."""

    def __init__(self, direct_writes: bool) -> None:
        self.loop = asyncio.new_event_loop()
        self.hub = Hub(self.loop, direct_writes=direct_writes)
        self.sessions: list[ClientSession] = []
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()
        self.server = self.call(self._serve())

    async def _serve(self) -> asyncio.AbstractServer:
        limits = SessionLimits(write_high_water=64 * 1024, negotiation_grace_s=0.0)

        def session() -> ClientSession:
            s = ClientSession(self.hub, lambda m, c: None, limits, lambda c: None)
            self.sessions.append(s)
            return s

        return await self.loop.create_server(session, "127.0.0.1", 0)

    @property
    def port(self) -> int:
        return int(self.server.sockets[0].getsockname()[1])

    def call(self, coroutine: Any) -> Any:
        return asyncio.run_coroutine_threadsafe(coroutine, self.loop).result(30)

    def connect(self, rcvbuf: int = 0) -> _Peer:
        count = len(self.hub.clients) + 1
        sock = socket.socket()
        if rcvbuf:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        sock.connect(self.server.sockets[0].getsockname())
        for _ in range(3000):  # attached once the (zero) negotiation grace has passed
            if len(self.hub.clients) >= count:
                break
            threading.Event().wait(0.01)
        assert len(self.hub.clients) >= count
        return _Peer(sock)

    def close(self) -> None:
        async def stop() -> None:
            self.server.close()
            for s in self.sessions:
                s.close()

        self.call(stop())
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(10)
        self.loop.close()


@pytest.fixture(params=[True, False], ids=["direct", "loop-only"])
def served(request: pytest.FixtureRequest) -> Iterator[_Served]:
    s = _Served(direct_writes=request.param)
    try:
        yield s
    finally:
        s.close()


def _numbered(device: str, n: int) -> Frame:
    return Frame(Message(device_name=device, body=String(text=str(n)), timestamp=n))


def _post_from_another_thread(hub: Hub, channel: Any, frames: list[Frame]) -> None:
    poster = threading.Thread(target=lambda: [hub.post_frame(channel, f) for f in frames])
    poster.start()
    poster.join()


_READER = """
import socket, sys
from protocol.framing import Decoder
sock = socket.create_connection(("127.0.0.1", int(sys.argv[1])))
print("CONNECTED", flush=True)
decoder, texts = Decoder(), []
sock.settimeout(30)
while len(texts) < int(sys.argv[2]):
    data = sock.recv(1 << 16)
    if not data:
        break
    decoder.feed(data)
    texts.extend(m.body.text for m in decoder.messages())
print(" ".join(texts) or "nothing", flush=True)
"""


@pytest.mark.integration
def test_bursts_reach_a_client_that_keeps_up_whole_and_in_order(served: _Served) -> None:
    # The client reads in a process of its own, as a real one does, and keeps up: bursts
    # of 300 (a driver's batch), 10 ms apart, reach it whole and in order. (A client whose
    # kernel cannot take a burst is behind, and gets the newest value of each device.)
    count, burst = 3000, 300
    reader = subprocess.Popen([sys.executable, "-c", _READER, str(served.port), str(count)],
                              cwd=REPO, stdout=subprocess.PIPE, text=True)
    try:
        assert reader.stdout is not None
        assert reader.stdout.readline().strip() == "CONNECTED"
        for _ in range(3000):  # attached once the (zero) negotiation grace has passed
            if served.hub.clients:
                break
            threading.Event().wait(0.01)
        channel = served.hub.open_channel("burst")
        for first in range(1, count + 1, burst):
            _post_from_another_thread(served.hub, channel, [
                _numbered("burst", n) for n in range(first, first + burst)])
            threading.Event().wait(0.01)
        received = reader.stdout.readline().split()
    finally:
        reader.kill()
        reader.wait()
    assert [int(text) for text in received] == list(range(1, count + 1))


def test_a_stalled_client_gets_the_newest_value_and_the_others_everything(
        served: _Served) -> None:
    fast = served.connect()
    stalled = served.connect(rcvbuf=4096)  # never reads until the end
    channels = {d: served.hub.open_channel(d) for d in ("a", "b")}
    count = 4000
    pad = "x" * 400  # fills the stalled client's socket buffers quickly
    frames = [(d, Frame(Message(device_name=d, body=String(text=f"{n}:{pad}"))))
              for n in range(1, count + 1) for d in ("a", "b")]
    got: list[Message] = []

    def read() -> None:
        fast.sock.settimeout(30)
        while len(got) < 2 * count:
            data = fast.sock.recv(1 << 16)
            assert data
            fast.decoder.feed(data)
            got.extend(fast.decoder.messages())

    reader = threading.Thread(target=read)
    reader.start()

    def post() -> None:
        # As fast as the fast client reads (it keeps up: never 100 values, 40 KB, behind;
        # further behind, it too would get the newest of each device), and never so far
        # ahead that the hub's own bound (MAX_PENDING) drops values.
        for n, (d, f) in enumerate(frames):
            while served.hub.pending > 1000 or n - len(got) > 100:
                threading.Event().wait(0.001)
            served.hub.post_frame(channels[d], f)

    poster = threading.Thread(target=post)
    poster.start()
    poster.join()
    reader.join(60)
    assert [(m.device_name, m.body.text.split(":")[0]) for m in got] == \
        [(d, str(n)) for n in range(1, count + 1) for d in ("a", "b")]
    # The stalled client's buffer holds one value per device, however many were posted.
    waiting = served.call(_describe_all(served))
    assert max(w["waiting"] for w in waiting) <= 2
    assert any(w["coalesced"] > 0 for w in waiting)
    # Once it reads, the last value of each device arrives, after only what the kernels
    # held (its small socket buffer as loopback sizes it, the daemon's 16 KB of unsent
    # bytes: about 200 values here), not a queue of the 8,000 posted (6,000 of them read
    # first when the daemon let the kernel and the transport queue them).
    stalled.sock.settimeout(30)
    last: dict[str, str] = {}
    read_before = 0
    while last != {"a": str(count), "b": str(count)}:
        data = stalled.sock.recv(1 << 16)
        assert data
        stalled.decoder.feed(data)
        for m in stalled.decoder.messages():
            last[m.device_name] = m.body.text.split(":")[0]
            read_before += 1
    assert read_before <= 500, read_before


async def _describe_all(served: _Served) -> list[dict[str, Any]]:
    return [s.describe() for s in served.sessions]


def test_a_value_posted_after_its_channel_closed_never_reaches_a_client(
        served: _Served) -> None:
    hub = served.hub
    channel = hub.open_channel("removed")
    _post_from_another_thread(hub, channel, [_numbered("removed", 1)])
    served.call(asyncio.sleep(0.05))
    assert "removed" in served.call(_devices(hub))

    async def close() -> None:
        hub.close_channel(channel)

    served.call(close())
    # A callback that checked before the close posts after it (the race of issue 11).
    _post_from_another_thread(hub, channel, [_numbered("removed", 2)])
    served.call(asyncio.sleep(0.05))
    assert "removed" not in served.call(_devices(hub))
    # A client connecting later gets nothing of it.
    late = served.connect()
    other = hub.open_channel("other")
    _post_from_another_thread(hub, other, [_numbered("other", 7)])
    first = late.read_until(1)
    assert [(m.device_name, m.body.text) for m in first] == [("other", "7")]


async def _devices(hub: Hub) -> list[str]:
    return hub.devices()


def test_a_partial_direct_write_is_finished_before_anything_else(served: _Served) -> None:
    """Frames larger than a socket buffer: direct writes stop half-way and the loop writes
    the rest first; the client still reads whole frames, in order."""
    peer = served.connect(rcvbuf=8192)
    channel = served.hub.open_channel("big")
    body = "y" * 60_000  # under the hub's large-message bound: posted as a small value
    count = 60
    frames = [Frame(Message(device_name="big", body=String(text=f"{n}:{body}")))
              for n in range(1, count + 1)]
    _post_from_another_thread(served.hub, channel, frames)
    # Newest-wins may coalesce some (the client fell behind); the last one always comes,
    # whole, and nothing is reordered.
    numbers: list[int] = []
    while not numbers or numbers[-1] != count:
        numbers.extend(int(m.body.text.split(":")[0]) for m in peer.read_until(1))
    assert numbers == sorted(set(numbers))


def test_resuming_writes_nothing_within_the_transports_handler(served: _Served) -> None:
    """asyncio calls `resume_writing` from within its write handler, which goes on after
    it: a write from there that fails ends the connection twice (CPython gh-156512; an
    error and a traceback in the daemon's log, ci70). What waited is written from the
    next loop turn, and arrives whole and in order."""
    peer = served.connect()
    session = served.sessions[-1]

    async def pause_queue_resume() -> tuple[int, int]:
        session.pause_writing()
        for n in range(1, 4):
            session.send_once(_numbered("queued", n))
        before = session.sent
        session.resume_writing()
        return before, session.sent  # what resume_writing itself wrote

    before, within = served.call(pause_queue_resume())
    assert within == before
    assert [m.body.text for m in peer.read_until(3)] == ["1", "2", "3"]


def test_the_stamp_of_a_frame_survives_the_direct_path() -> None:
    msg = _pose_stamped((1_700_000_000, 5), "w", (0.1, 0.2, 0.3), (0.0, 0.0, 0.0, 1.0))
    frame = _fast_frame("PoseStamped", msg, "tool", {})
    header = struct.unpack(">H12s20sQQQ", frame.encoded(2)[:58])
    assert header[3] == igtl_timestamp_from_ros(1_700_000_000, 5)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.tuples(stamps, names, names, st.tuples(finite, finite, finite),
                          st.tuples(unit, unit, unit, unit)), max_size=9))
def test_tf_bytes_give_the_transforms_the_ordinary_path_gives(transforms) -> None:
    from tf2_msgs.msg import TFMessage

    from bridge.tf.capability import tf_cdr_to_transforms, tf_message_to_transforms

    msg = TFMessage(transforms=[_transform_stamped(*t) for t in transforms])
    data = serialize_message(msg)
    assert tf_cdr_to_transforms(data) == tf_message_to_transforms(
        deserialize_message(data, TFMessage))


class _HeldStringCodec:
    """std_msgs/String's codec, whose conversion waits for a signal: a callback held just
    after its closed-check, as the executor thread can be when close() runs."""

    def __init__(self) -> None:
        from bridge.codecs.scalars import StringCodec

        self.inner = StringCodec("std_msgs/msg/String", "STRING")
        self.entered = threading.Event()
        self.release = threading.Event()

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)

    def encode(self, msg: Any) -> Any:
        self.entered.set()
        assert self.release.wait(30)
        return self.inner.encode(msg)


@pytest.mark.ros
def test_a_subscriber_callback_running_when_its_bridge_closes_does_not_bring_it_back() -> None:
    """Issue 11's race, with a real node: the callback passed its check, close() ran, then
    the callback posted. No client, now or later, may see the removed device."""
    from std_msgs.msg import String as RosString

    from protocol.commands import QoS
    from bridge.ros.ros_node import RosNode, RosOptions
    from bridge.topics.capability import SubscriberBridge

    served = _Served(direct_writes=True)
    ros = RosNode(RosOptions(node_name="hot_path_race"))
    try:
        codec = _HeldStringCodec()
        bridge = SubscriberBridge(ros, served.hub, topic="/hot_path_race",
                                  codec=codec,  # type: ignore[arg-type]
                                  qos=QoS(), device="raced", metadata={})
        callback = threading.Thread(target=bridge._on_raw,
                                    args=(serialize_message(RosString(data="late")),))
        callback.start()
        assert codec.entered.wait(30)

        async def close() -> None:
            bridge.close()

        served.call(close())
        codec.release.set()
        callback.join(30)
        served.call(asyncio.sleep(0.05))  # a drain the late post may have scheduled runs
        assert "raced" not in served.call(_devices(served.hub))
        late = served.connect()
        other = served.hub.open_channel("other")
        _post_from_another_thread(served.hub, other, [_numbered("other", 1)])
        assert [m.device_name for m in late.read_until(1)] == ["other"]
    finally:
        ros.stop()
        served.close()


@settings(max_examples=150, deadline=None)
@given(st.integers(1, (2**32 - 1) * 10**9), st.tuples(finite, finite, finite),
       st.tuples(unit, unit, unit, unit))
def test_a_tf_lookups_template_frame_is_the_bytes_of_the_ordinary_path(stamp_ns, t, q) -> None:
    from bridge.tf.buffer import StampedTransform
    from bridge.tf.capability import _Lookup, _igtl_timestamp
    from protocol.messages import Transform
    from protocol.naming import UNITS_MM, NameKey, metadata_for

    q = _quaternion(q)
    result = StampedTransform("world", "tool", stamp_ns, t, q)
    metadata = metadata_for(NameKey.tf_lookup("world", "tool"), frame="world", units=UNITS_MM)
    lookup = _Lookup(("world", "tool"), "tf:world>tool", metadata, ("world", "tool"), None)
    frame = lookup.frame_of(result)
    assert frame is not None
    ordinary = Message(device_name="tf:world>tool", body=Transform(matrix=result.matrix_mm()),
                       timestamp=_igtl_timestamp(stamp_ns), metadata=metadata)
    for version in (1, 2):
        assert frame.encoded(version) == encode(ordinary, header_version=version)


# ---------------------------------------------------------------------------- tf updates


def test_a_tf_update_reaches_each_client_whole_in_one_write() -> None:
    """`Hub.post_frames`: the lookups one /tf message changed go to every client that keeps
    up as one socket write from the posting thread, in order."""
    served = _Served(direct_writes=True)
    try:
        peers = [served.connect() for _ in range(3)]
        devices = [f"link{i}" for i in range(1, 8)]
        update = [(d, _numbered(d, i)) for i, d in enumerate(devices, 1)]
        poster = threading.Thread(target=served.hub.post_frames, args=(update,))
        poster.start()
        poster.join()
        for peer in peers:
            got = peer.read_until(len(devices))
            assert [(m.device_name, m.body.text) for m in got] == \
                [(d, str(i)) for i, d in enumerate(devices, 1)]
        assert [s.slot.sent for s in served.sessions] == [1, 1, 1]
        assert served.hub.direct == len(devices)
    finally:
        served.close()


def test_a_removed_lookup_never_comes_back_while_tf_keeps_arriving() -> None:
    """tf lookups are evaluated and written on the thread /tf arrives on: removing one on
    the loop while that thread delivers must leave its device gone for good."""
    from bridge.ros.ros_node import RosNode, RosOptions
    from bridge.tf.buffer import StampedTransform
    from bridge.tf.capability import TfBridges
    from protocol.commands import CreateTfLookup, RemoveTfLookup
    from protocol.naming import DeviceNameRegistry

    served = _Served(direct_writes=True)
    ros = RosNode(RosOptions(node_name="tf_race_test"))
    stop = threading.Event()
    try:
        tf = TfBridges(ros, served.hub, DeviceNameRegistry())

        async def create() -> str:
            return tf.create_lookup(CreateTfLookup(parent="base", child="tool")).reply.device

        device = served.call(create())

        def publish() -> None:  # what the streams thread does with each /tf message
            n = 0
            while not stop.is_set():
                n += 1
                tf._store([StampedTransform("base", "tool", n, (n * 1e-3, 0.0, 0.0),
                                            (0.0, 0.0, 0.0, 1.0))], static=False)

        publisher = threading.Thread(target=publish)
        publisher.start()
        for _ in range(3000):
            if device in served.call(_devices(served.hub)):
                break
            threading.Event().wait(0.01)
        assert device in served.call(_devices(served.hub))

        async def remove() -> None:
            tf.remove_lookup(RemoveTfLookup(parent="base", child="tool"))

        served.call(remove())
        delivered = tf.updates
        for _ in range(3):  # more /tf after the removal: delivered nowhere
            served.call(asyncio.sleep(0.05))
            assert device not in served.call(_devices(served.hub))
        stop.set()
        publisher.join(30)
        assert tf.updates == delivered
        tf.close()
    finally:
        stop.set()
        served.close()
        ros.stop()


@pytest.mark.ros
def test_bytes_rclpy_cannot_read_are_dropped_with_a_warning(
        caplog: pytest.LogCaptureFixture) -> None:
    """A subscriber takes every type serialized: bytes that do not deserialize must cost
    one warning, not an exception in the streams thread (which would pause every stream)."""
    from bridge.codecs import codec_for
    from bridge.ros.ros_node import RosNode, RosOptions
    from bridge.topics.capability import SubscriberBridge
    from protocol.commands import QoS

    served = _Served(direct_writes=True)
    ros = RosNode(RosOptions(node_name="hot_path_bad_bytes"))
    try:
        bridge = SubscriberBridge(ros, served.hub, topic="/hot_path_bad_bytes",
                                  codec=codec_for("sensor_msgs/msg/Image"), qos=QoS(),
                                  device="bad", metadata={})
        with caplog.at_level("WARNING", logger="bridge.topics.capability"):
            bridge._on_raw(b"\x00\x01\x00\x00\xff")  # a CDR header, then nothing usable
        assert bridge.count == 0 and bridge.last_message is None
        assert "bad" not in served.call(_devices(served.hub))
        assert any("cannot read a sensor_msgs/msg/Image from /hot_path_bad_bytes" in r.message
                   for r in caplog.records)
        bridge.close()
    finally:
        ros.stop()
        served.close()


# ---------------------------------------------------------------------------- pose bursts


def _pose_bytes(n: int, frame: str = "world") -> bytes:
    from geometry_msgs.msg import PoseStamped

    msg = PoseStamped()
    msg.header.frame_id = frame
    msg.header.stamp.sec = 1_700_000_000
    msg.pose.position.x = n * 1e-3
    msg.pose.orientation.w = 1.0
    return bytes(serialize_message(msg))


@pytest.mark.ros
def test_a_burst_of_poses_taken_together_reaches_each_client_in_one_write_in_order() -> None:
    """A pose subscriber's raw reader hands on the messages waiting together: each client
    that keeps up gets the whole burst in one socket write from that thread, in order; a
    message the fast path cannot convert takes the ordinary way in its place in the order."""
    from bridge.codecs import codec_for
    from bridge.ros.ros_node import RosNode, RosOptions
    from bridge.topics.capability import SubscriberBridge
    from protocol.commands import QoS

    served = _Served(direct_writes=True)
    ros = RosNode(RosOptions(node_name="hot_path_pose_burst"))
    try:
        peers = [served.connect() for _ in range(2)]
        bridge = SubscriberBridge(ros, served.hub, topic="/hot_path_pose_burst",
                                  codec=codec_for("geometry_msgs/msg/PoseStamped"),
                                  qos=QoS(), device="pose", metadata={})
        burst = [_pose_bytes(n) for n in range(1, 11)]
        poster = threading.Thread(target=bridge._on_batch, args=(burst,))
        poster.start()
        poster.join()
        for peer in peers:
            got = peer.read_until(10)
            assert [round(m.body.matrix[0][3]) for m in got] == list(range(1, 11))  # mm
        assert [s.slot.sent for s in served.sessions] == [1, 1]
        assert bridge.count == 10
        assert bridge.last_message.pose.position.x == pytest.approx(0.010)

        # A zero quaternion is not the fast path's: the ordinary codec sends it (no rotation,
        # at the origin here), in its place in the order.
        from geometry_msgs.msg import PoseStamped

        bad = PoseStamped()
        bad.header.frame_id = "world"
        with_bad = [_pose_bytes(11), bytes(serialize_message(bad)), _pose_bytes(12)]
        poster = threading.Thread(target=bridge._on_batch, args=(with_bad,))
        poster.start()
        poster.join()
        for peer in peers:
            got = peer.read_until(3)
            assert [round(m.body.matrix[0][3]) for m in got] == [11, 0, 12]
        assert bridge.count == 13
        bridge.close()
        poster = threading.Thread(target=bridge._on_batch, args=([_pose_bytes(13)],))
        poster.start()
        poster.join()
        assert "pose" not in served.call(_devices(served.hub))
    finally:
        ros.stop()
        served.close()


@pytest.mark.ros
def test_pose_streams_past_the_stream_readers_bound_go_through_rclpy_and_arrive_alike(
        processes: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    from bridge.ros import ros_node
    from bridge.ros.ros_node import RosNode, RosOptions
    from bridge.topics.capability import SubscriberBridge
    from protocol.commands import QoS

    monkeypatch.setattr(ros_node, "MAX_READ_STREAMS", 1)
    served = _Served(direct_writes=True)
    ros = RosNode(RosOptions(node_name="hot_path_reader_bound"))
    ros.start()
    try:
        peer = served.connect()
        codec = codec_for("geometry_msgs/msg/PoseStamped")
        read, spun = (SubscriberBridge(ros, served.hub, topic=f"/hot_path_bound_{name}",
                                       codec=codec, qos=QoS(), device=name, metadata={})
                      for name in ("read", "spun"))
        assert read._reader is not None and read._subscription is None
        assert spun._reader is None and spun._subscription is not None
        for name in ("read", "spun"):
            processes.python(name, "stream_publisher.py", f"/hot_path_bound_{name}", "200",
                             "--count", "100000")
        seen: dict[str, list[float]] = {"read": [], "spun": []}
        while min(len(v) for v in seen.values()) < 20:
            for message in peer.read_until(1):
                seen[message.device_name].append(message.body.matrix[0][3])
        for values in seen.values():  # stream_publisher.py: x = n µm, in order
            assert values == sorted(values) and len(set(values)) == len(values)
        read.close()
        spun.close()
    finally:
        ros.stop()
        served.close()


@pytest.mark.ros
def test_pose_bytes_nobody_can_read_in_a_burst_cost_a_warning_and_the_rest_goes_on(
        caplog: pytest.LogCaptureFixture) -> None:
    """A malformed PoseStamped among good ones (a hostile peer's bytes): the fast path
    refuses it, the ordinary way cannot read it either and says so once; the good ones
    before and after it reach the client, in order."""
    from bridge.ros.ros_node import RosNode, RosOptions
    from bridge.topics.capability import SubscriberBridge
    from protocol.commands import QoS

    served = _Served(direct_writes=True)
    ros = RosNode(RosOptions(node_name="hot_path_bad_pose"))
    try:
        peer = served.connect()
        bridge = SubscriberBridge(ros, served.hub, topic="/hot_path_bad_pose",
                                  codec=codec_for("geometry_msgs/msg/PoseStamped"),
                                  qos=QoS(), device="pose", metadata={})
        garbage = b"\x00\x01\x00\x00" + b"\xff" * 7  # a CDR header, then a broken stamp
        with caplog.at_level("WARNING", logger="bridge.topics.capability"):
            bridge._on_batch([_pose_bytes(1), garbage, _pose_bytes(2)])
        got = peer.read_until(2)
        assert [round(m.body.matrix[0][3]) for m in got] == [1, 2]
        assert any("cannot read a geometry_msgs/msg/PoseStamped from /hot_path_bad_pose"
                   in r.getMessage() for r in caplog.records)
        assert bridge.count == 2
        # Ending a burst, it is not kept as the last message: the one before it is.
        bridge._on_batch([_pose_bytes(3), garbage])
        assert [round(m.body.matrix[0][3]) for m in peer.read_until(1)] == [3]
        assert bridge.last_message.pose.position.x == pytest.approx(0.003)
        bridge.close()
    finally:
        ros.stop()
        served.close()

"""A client's bridges stream only to the clients that hold them (issue 43, item 7;
docs/security.md, "Who owns a bridge"), with the real daemon, real TCP and rclpy
publishers in processes of their own.

What the issue saw: every stream went to every connected client, so a plain OpenIGTLink
client (3D Slicer's connector) that asked for nothing received the pose and force streams
another live client had made. Now a client's bridge goes to its live holders only (its
pose still by the native lane), a client that asks for it too gets its newest value at
once and then the stream, keeping it opens it to everyone, and the operator's reach all.
"""

from __future__ import annotations

import socket
import threading
from collections import Counter
from typing import Any, Iterator

import pytest

from protocol.framing import Decoder
from protocol.messages import Message, Status
from slicer_client.connection import CommandRefusedError, Connection
from support import (Child, Processes, RunningDaemon, assert_clean_exit, operator_daemon, scaled,
                     wait_until)

pytestmark = pytest.mark.ros

# The operator's pose topic, a client's pose and Float64 streams, a value published once.
OPERATOR_TOPIC, POSE_TOPIC, FORCE_TOPIC, ONCE_TOPIC = ("/aud_op", "/aud_pose", "/aud_force",
                                                      "/aud_once")
FLOAT64 = "std_msgs/msg/Float64"


@pytest.fixture(scope="module")
def daemon(module_processes: Processes,
           tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningDaemon]:
    """Poses at 200 Hz on the operator's topic and a client's, forces at 20 Hz."""
    running = operator_daemon(module_processes, tmp_path_factory.mktemp("audience"),
                              OPERATOR_TOPIC, POSE_TOPIC, rate_hz="200")
    module_processes.python("publisher_force", "publish_json.py", FORCE_TOPIC, FLOAT64,
                            '{"data": 2.5}')
    yield running
    assert_clean_exit(running)


class Tally:
    """How many values of each device reached a client (any thread); a device's STATUS
    (a stale stream's, a heartbeat) is not one."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._counts: Counter[str] = Counter()

    def __call__(self, message: Message) -> None:
        if isinstance(message.body, Status):
            return
        with self._lock:
            self._counts[message.device_name] += 1

    def __getitem__(self, device: str) -> int:
        with self._lock:
            return self._counts[device]

    def devices(self) -> set[str]:
        with self._lock:
            return set(self._counts)


class PlainClient:
    """A plain OpenIGTLink client (3D Slicer's connector before anyone asks for anything):
    it connects, never sends, and reads."""

    def __init__(self, port: int) -> None:
        self.tally = Tally()
        self._sock = socket.create_connection(("127.0.0.1", port), timeout=scaled(20))
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        decoder = Decoder()
        try:
            while data := self._sock.recv(1 << 16):
                decoder.feed(data)
                for message in decoder.messages():
                    self.tally(message)
        except OSError:
            pass  # closed by close()

    def close(self) -> None:
        self._sock.shutdown(socket.SHUT_RDWR)
        self._sock.close()
        self._thread.join(scaled(10))


def connect(daemon: RunningDaemon, tally: Tally) -> Connection:
    return Connection("127.0.0.1", daemon.port, on_message=tally)


def subscribe(client: Connection, topic: str, ros_type: str) -> dict[str, Any]:
    return client.command("create_subscriber", {"topic": topic, "type": ros_type})


def listed(client: Connection, topic: str) -> dict[str, Any]:
    return next(b for b in client.command("list_bridges")["bridges"]
                if b["kind"] == "subscriber" and b["topic"] == topic)


def more(tally: Tally, device: str, count: int, what: str) -> None:
    """Until `count` more messages of `device` reached `tally`."""
    start = tally[device]
    wait_until(lambda: tally[device] >= start + count, timeout=20, what=what)


def test_a_clients_streams_reach_only_its_holders_on_every_route(
        daemon: RunningDaemon, processes: Processes) -> None:
    plain = PlainClient(daemon.port)
    mine, theirs, paced_seen = Tally(), Tally(), Tally()
    maker = connect(daemon, mine)
    paced = connect(daemon, paced_seen)
    joiner = None
    try:
        assert paced.command("hello", {"display_hz": 30.0})["display_hz"] == 30.0
        operator = listed(maker, OPERATOR_TOPIC)["device"]
        pose = subscribe(maker, POSE_TOPIC, "PoseStamped")["device"]
        force = subscribe(maker, FORCE_TOPIC, FLOAT64)["device"]
        more(mine, pose, 50, "the maker's pose stream")
        more(mine, force, 3, "the maker's force stream")
        # The operator's bridge reaches every client: while 100 of its values came, the
        # plain client and the paced display got none of the maker's streams.
        more(plain.tally, operator, 100, "the operator's stream at the plain client")
        more(paced_seen, operator, 3, "the operator's stream at the paced display")
        assert plain.tally[pose] == plain.tally[force] == 0, plain.tally.devices()
        assert paced_seen[pose] == paced_seen[force] == 0, paced_seen.devices()
        # The maker's pose still takes the native lane (its route's counter moves with it).
        written = listed(maker, POSE_TOPIC)["lane_written"]
        more(mine, pose, 50, "more of the maker's pose stream")
        assert listed(maker, POSE_TOPIC)["lane_written"] > written + 10

        # A value published a while ago and no more: a client that asks for the bridge
        # gets it at once, as a client that connects gets the others'.
        once = subscribe(maker, ONCE_TOPIC, FLOAT64)["device"]
        publisher: Child = processes.python("publisher_once", "publish_json.py", ONCE_TOPIC,
                                            FLOAT64, '{"data": 7.0}')
        wait_until(lambda: mine[once] > 0, timeout=20, what="the maker's value")
        publisher.stop()  # no more of it
        joiner = connect(daemon, theirs)
        assert theirs[once] == theirs[pose] == 0
        assert subscribe(joiner, ONCE_TOPIC, FLOAT64)["existed"] is True
        wait_until(lambda: theirs[once] == 1, timeout=20,
                   what="the newest value at the client that asked again")
        # ... and then the stream, by the lane, which writes to both holders now.
        assert subscribe(joiner, POSE_TOPIC, "PoseStamped")["existed"] is True
        more(theirs, pose, 50, "the pose stream at the client that asked again")
        written = listed(maker, POSE_TOPIC)["lane_written"]
        more(theirs, pose, 50, "more of it")
        assert listed(maker, POSE_TOPIC)["lane_written"] > written + 10
        assert plain.tally[pose] == plain.tally[once] == 0

        # Kept, it goes to every client at once: the plain client and the paced display.
        maker.command("keep_bridge", {"kind": "subscriber", "topic": POSE_TOPIC})
        more(plain.tally, pose, 50, "the kept pose stream at the plain client")
        more(paced_seen, pose, 3, "the kept pose stream at the paced display")
        assert plain.tally[force] == paced_seen[force] == 0
        written = listed(maker, POSE_TOPIC)["lane_written"]
        more(plain.tally, pose, 50, "more of it")
        assert listed(maker, POSE_TOPIC)["lane_written"] > written + 10
    finally:
        for client in (maker, paced, joiner):
            if client is not None:
                client.close()
        plain.close()
    with daemon.connect() as cleaner:
        cleaner.command("remove_subscriber", {"topic": POSE_TOPIC})


def test_a_paced_display_that_asks_gets_the_stream_a_frame_at_a_time(
        daemon: RunningDaemon) -> None:
    """The paced display takes the lanes' news only of what it may see: once it holds the
    bridge too, it gets the maker's pose, fewer than the maker's, which the lane writes."""
    mine, shown = Tally(), Tally()
    maker = connect(daemon, mine)
    paced = connect(daemon, shown)
    try:
        assert paced.command("hello", {"display_hz": 20.0})["display_hz"] == 20.0
        pose = subscribe(maker, POSE_TOPIC, "PoseStamped")["device"]
        more(mine, pose, 50, "the maker's pose stream")
        assert shown[pose] == 0
        assert subscribe(paced, POSE_TOPIC, "PoseStamped")["existed"] is True
        more(shown, pose, 5, "the pose at the paced holder")
        start_mine, start_shown = mine[pose], shown[pose]
        more(mine, pose, 400, "two seconds of the maker's stream")
        assert shown[pose] - start_shown < (mine[pose] - start_mine) / 3
    finally:
        maker.close()
        paced.close()


def test_a_client_that_reads_messages_whole_gets_no_native_values(
        daemon: RunningDaemon) -> None:
    """`native: false` with `messages` (what the reference facade asks): the client gets
    the whole messages and none of the pose's TRANSFORMs, while another holder still gets
    them by the lane; kept (every client), it still gets none; asked again with `native`,
    it gets the newest value at once and then the stream. Declining alone is refused."""
    whole_seen, raw_seen = Tally(), Tally()
    reader = connect(daemon, whole_seen)
    raw = connect(daemon, raw_seen)
    try:
        with pytest.raises(CommandRefusedError) as refused:
            reader.command("create_subscriber", {"topic": POSE_TOPIC, "type": "PoseStamped",
                                                 "native": False})
        assert (refused.value.error.field, refused.value.error.code.name) == \
            ("native", "OUT_OF_RANGE")
        reply = reader.command("create_subscriber", {"topic": POSE_TOPIC,
                                                     "type": "PoseStamped",
                                                     "messages": True, "native": False})
        pose, whole = reply["device"], reply["message_device"]
        subscribe(raw, POSE_TOPIC, "PoseStamped")
        more(raw_seen, pose, 200, "the pose stream at the raw holder")
        more(whole_seen, whole, 20, "the whole messages at the reader")
        assert whole_seen[pose] == 0, whole_seen.devices()
        written = listed(raw, POSE_TOPIC)["lane_written"]
        more(raw_seen, pose, 100, "more of it, by the lane")
        assert listed(raw, POSE_TOPIC)["lane_written"] > written + 10

        raw.command("keep_bridge", {"kind": "subscriber", "topic": POSE_TOPIC})
        more(raw_seen, pose, 200, "the kept stream at the raw holder")
        more(whole_seen, whole, 10, "the whole messages, kept")
        assert whole_seen[pose] == 0, whole_seen.devices()

        assert subscribe(reader, POSE_TOPIC, "PoseStamped")["existed"] is True
        more(whole_seen, pose, 100, "the native values, asked for again")
    finally:
        reader.close()
        raw.close()
    with daemon.connect() as cleaner:
        cleaner.command("remove_subscriber", {"topic": POSE_TOPIC})


def test_a_client_that_joins_a_message_stream_after_the_last_left_gets_it(
        daemon: RunningDaemon) -> None:
    """Seen in bench_slicer_main_thread's second module pass: the message stream of a pose
    the native lane takes stopped once its last reader left (its pacer stops looking while
    nobody listens, and the lane pokes nothing), so a reader that came after (a module that
    reconnected, a second script) got the newest once and nothing more."""
    holder_seen, first_seen, second_seen = Tally(), Tally(), Tally()
    holder = connect(daemon, holder_seen)  # keeps the bridge alive between the readers
    try:
        subscribe(holder, POSE_TOPIC, "PoseStamped")
        whole = {"topic": POSE_TOPIC, "type": "PoseStamped", "messages": True,
                 "native": False}
        first = connect(daemon, first_seen)
        device = first.command("create_subscriber", whole)["message_device"]
        more(first_seen, device, 20, "the whole messages at the first reader")
        first.close()
        wait_until(lambda: listed(holder, POSE_TOPIC)["clients"] == 1, timeout=20,
                   what="the first reader gone")
        written = listed(holder, POSE_TOPIC)["lane_written"]
        more(holder_seen, listed(holder, POSE_TOPIC)["device"], 200, "the lane writing on")
        assert listed(holder, POSE_TOPIC)["lane_written"] > written + 100
        second = connect(daemon, second_seen)
        try:
            assert second.command("create_subscriber", whole)["message_device"] == device
            more(second_seen, device, 20, "the whole messages at the second reader")
        finally:
            second.close()
    finally:
        holder.close()
    with daemon.connect() as looker:  # no holder left, nothing kept: the bridge ended
        wait_until(lambda: not any(b["kind"] == "subscriber" and b["topic"] == POSE_TOPIC
                                   for b in looker.command("list_bridges")["bridges"]),
                   timeout=20, what="the bridge ended with its last holder")

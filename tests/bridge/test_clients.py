"""Many clients at once: daemon-wide streams, a stalled client, a late joiner."""

from __future__ import annotations

import socket
import time
from pathlib import Path


from protocol.messages import Transform
from support import Processes, RunningDaemon, scaled, wait_until


def rss_bytes(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024
    raise AssertionError("no VmRSS")


def sequence_of(message) -> int:
    assert isinstance(message.body, Transform)
    return round(message.body.matrix[0, 3] * 1000)  # the peer sends n * 1e-6 m = n/1000 mm


def test_eight_clients_all_receive_every_streamed_device(daemon: RunningDaemon,
                                                         processes: Processes) -> None:
    clients = [daemon.connect() for _ in range(8)]
    try:
        device = clients[0].command("create_subscriber", {"topic": "/clients_eight",
                                                          "type": "PoseStamped"})["device"]
        # Another client's command changed the shared state: all see the same device.
        assert clients[5].command("create_subscriber", {"topic": "/clients_eight",
                                                        "type": "PoseStamped"})["existed"]
        # Kept, it goes to every client (a client's own goes to its holders only:
        # test_stream_audience.py).
        clients[0].command("keep_bridge", {"kind": "subscriber", "topic": "/clients_eight"})
        processes.python("stream", "stream_publisher.py", "/clients_eight", "200",
                         "--count", "400")
        for client in clients:
            client.wait_for(device, lambda m: sequence_of(m) == 400, timeout=30)
        listed = clients[3].command("list_bridges")
        assert len(listed["clients"]) >= 8
        assert all(c["header_version"] == 2 for c in listed["clients"])
    finally:
        clients[0].command("remove_subscriber", {"topic": "/clients_eight"})
        for client in clients:
            client.close()


def test_a_client_that_never_reads_does_not_slow_others_and_memory_stays_bounded(
        daemon: RunningDaemon, processes: Processes) -> None:
    fast = daemon.connect()
    # A client that connects, asks for nothing and never reads a byte.
    stalled = socket.socket()
    stalled.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    stalled.connect(("127.0.0.1", daemon.port))
    try:
        device = fast.command("create_subscriber", {"topic": "/clients_camera",
                                                    "type": "Image"})["device"]
        # Kept, it goes to the client that asked for nothing too.
        fast.command("keep_bridge", {"kind": "subscriber", "topic": "/clients_camera"})
        received: list[int] = []
        fast_latest = [0]

        def count(message) -> None:
            if message.device_name == device:
                received.append(1)
                fast_latest[0] = int(message.metadata["ros2.frame"].split(":")[1])

        fast._on_message = count
        # 640x480 rgb8 at 30 Hz: 27 MB/s that the stalled client never takes.
        camera = processes.python("camera", "stream_publisher.py", "/clients_camera", "30",
                                  "--image", "640x480", "--count", "300")
        camera.wait_for_output("SENT 100", timeout=30)
        rss_start = rss_bytes(daemon.child.pid)
        camera.wait_for_output("DONE", timeout=60)
        # The fast client keeps up and ends with the very last frame.
        wait_until(lambda: fast_latest[0] == 300, timeout=20, what="the last frame (seq:300)")
        rss_growth = rss_bytes(daemon.child.pid) - rss_start
        # 200 frames of 0.9 MB went by: an unbounded buffer would have grown by ~180 MB.
        assert rss_growth < 80 * 1024 * 1024, f"daemon RSS grew by {rss_growth / 1e6:.0f} MB"
        assert len(received) >= 250, f"the fast client got only {len(received)} of 300 frames"
        stats = [c for c in fast.command("list_bridges")["clients"] if c["received"] == 0]
        assert stats and stats[0]["coalesced"] > 200, stats  # the stalled one skipped them
        assert stats[0]["waiting"] <= 1  # one camera device: at most one frame waits
    finally:
        fast.command("remove_subscriber", {"topic": "/clients_camera"})
        stalled.close()
        fast.close()


def test_a_late_client_gets_the_current_state_at_once(daemon: RunningDaemon,
                                                      processes: Processes) -> None:
    with daemon.connect() as first:
        device = first.command("create_subscriber", {"topic": "/clients_late",
                                                     "type": "PoseStamped"})["device"]
        publisher = processes.python("once", "stream_publisher.py", "/clients_late", "50",
                                     "--count", "7")
        first.wait_for(device, lambda m: sequence_of(m) == 7, timeout=20)
        publisher.wait_for_output("DONE")
        # Nothing is published any more; a new client that asks for the same bridge gets
        # the latest value at once (while the bridge lives: its first client is still here).
        with daemon.connect() as late:
            assert late.command("create_subscriber", {"topic": "/clients_late",
                                                      "type": "PoseStamped"})["existed"]
            message = late.wait_for(device, timeout=scaled(5))
            assert sequence_of(message) == 7
            assert message.metadata["ros2.topic"] == "/clients_late"


def test_rate_cap_limits_a_stream_but_delivers_the_last_value(daemon: RunningDaemon,
                                                              processes: Processes) -> None:
    with daemon.connect() as client:
        seen: list[int] = []
        device = client.command("create_subscriber", {"topic": "/clients_capped",
                                                      "type": "PoseStamped",
                                                      "rate_hz": 10})["device"]
        client._on_message = lambda m: seen.append(sequence_of(m)) \
            if m.device_name == device else None
        started = time.monotonic()
        processes.python("fast", "stream_publisher.py", "/clients_capped", "200",
                         "--count", "200")
        client.wait_for(device, lambda m: sequence_of(m) == 200, timeout=30)
        elapsed = time.monotonic() - started
        # 10 Hz over the stream's ~1 s (+ start-up), far below the 200 messages sent.
        assert len(seen) <= 10 * elapsed + 2, (len(seen), elapsed)
        assert seen[-1] == 200

"""Display pacing (hello's ``display_hz``), over real TCP against a real daemon: a client
that shows streams on a display (3D Slicer) gets each stream's newest value once a frame;
a client beside it that did not ask still gets every value, by the native lane. Each gets
only what it may: the streams of the bridges it holds (docs/security.md, "Who owns a
bridge"), so a paced display that asked for nothing gets nothing of them."""

from __future__ import annotations

import threading
import time

import pytest

from protocol.commands import ErrorCode
from protocol.messages import Message, Transform
from slicer_client.connection import CommandRefusedError, Connection
from support import RunningDaemon, wait_until

pytestmark = pytest.mark.ros

PUBLISHED = 300
HZ = 20.0  # slow enough that a frame's worth is plain to see


class _Arrivals:
    """When each TRANSFORM of one device reached a connection, and its x (mm)."""

    def __init__(self, device: str) -> None:
        self.device = device
        self.lock = threading.Lock()
        self.values: list[tuple[float, float]] = []

    def __call__(self, message: Message) -> None:
        if message.device_name == self.device and isinstance(message.body, Transform):
            with self.lock:
                self.values.append((time.monotonic(), message.body.matrix[0][3]))

    def snapshot(self) -> list[tuple[float, float]]:
        with self.lock:
            return list(self.values)


def test_a_display_gets_the_newest_value_once_a_frame_and_the_others_every_one(
        daemon: RunningDaemon) -> None:
    setup = daemon.connect()
    try:
        device = setup.command("create_subscriber", {"topic": "/paced_pose",
                                                     "type": "PoseStamped"})["device"]
        setup.command("create_publisher", {"topic": "/paced_pose", "type": "PoseStamped"})
        shown, every, stranger = _Arrivals(device), _Arrivals(device), _Arrivals(device)
        display = Connection("127.0.0.1", daemon.port, on_message=shown)
        plain = Connection("127.0.0.1", daemon.port, on_message=every)
        other = Connection("127.0.0.1", daemon.port, on_message=stranger)
        try:
            assert display.command("hello", {"display_hz": HZ})["display_hz"] == HZ
            assert other.command("hello", {"display_hz": HZ})["display_hz"] == HZ
            for holder in (display, plain):  # they share the setup's bridge
                assert holder.command("create_subscriber", {
                    "topic": "/paced_pose", "type": "PoseStamped"})["existed"] is True
            matrix = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]
            def both_see_it() -> bool:
                setup.command("publish", {"topic": "/paced_pose", "value": matrix})
                return bool(shown.snapshot()) and bool(every.snapshot())
            wait_until(both_see_it, timeout=20, what="the stream at both clients")
            start = time.monotonic()
            for i in range(1, PUBLISHED + 1):
                matrix[0][3] = float(i)
                setup.command("publish", {"topic": "/paced_pose", "value": matrix})
            for arrivals in (shown, every):  # the newest reaches both
                wait_until(lambda a=arrivals: bool(a.snapshot())  # type: ignore[misc]
                           and a.snapshot()[-1][1] == PUBLISHED, timeout=20,
                           what="the last value")
            paced = [t for t, x in shown.snapshot() if t >= start]
            span = paced[-1] - start
            # One value a frame at most, each frame after the one before.
            assert len(paced) <= span * HZ + 2, (len(paced), span)
            assert len([x for t, x in every.snapshot() if t >= start]) > len(paced)
            # The lane wrote the plain holder's values; the paced one that holds nothing got
            # none of them, by the lane's news or otherwise.
            listed = setup.command("list_bridges")["bridges"]
            assert [b["lane_written"] for b in listed if b.get("device") == device][0] > 0
            assert stranger.snapshot() == []
        finally:
            display.close()
            plain.close()
            other.close()
    finally:
        setup.close()


def test_a_display_rate_out_of_range_is_refused_naming_it(client: Connection) -> None:
    with pytest.raises(CommandRefusedError) as refused:
        client.command("hello", {"display_hz": 0})
    assert refused.value.field == "display_hz"
    assert refused.value.code == ErrorCode.OUT_OF_RANGE

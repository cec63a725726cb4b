"""Stale streams (issue 23): the rule, and a running daemon telling its clients when a
real publisher in another process crashes, stops, and comes back."""

from __future__ import annotations

import signal
import time
from typing import Iterator

import pytest

import slicer_client
from bridge.core.stream_health import SILENCE_FLOOR_S, STALE_PERIODS, Arrivals, stale_reason
from protocol.liveness import stream_condition
from slicer_client.scene_plan import describe_bridges, stale_lines
from protocol.messages import Status, StatusCode
from support import Processes, RunningDaemon, assert_clean_exit, start_daemon, wait_until


def arrivals_every(period: float, count: int, start: float = 100.0) -> Arrivals:
    arrivals = Arrivals()
    for n in range(count):
        arrivals.note(start + n * period)
    return arrivals


def test_a_stream_is_stale_after_a_few_of_its_own_periods() -> None:
    fast = arrivals_every(0.01, 50)  # 100 Hz: the floor decides
    last = fast.last
    assert last is not None and fast.period == pytest.approx(0.01)
    assert stale_reason(fast, last + SILENCE_FLOOR_S * 0.9, 1, "/p") is None
    reason = stale_reason(fast, last + SILENCE_FLOOR_S * 1.1, 1, "/p")
    assert reason is not None and reason.startswith("no message on /p for ")
    assert "expected one every 10 ms" in reason
    slow = arrivals_every(1.0, 5)  # 1 Hz: its own period decides
    assert slow.last is not None
    assert stale_reason(slow, slow.last + STALE_PERIODS * 0.9, 1, "/s") is None
    assert stale_reason(slow, slow.last + STALE_PERIODS * 1.1, 1, "/s") is not None


def test_a_publisher_gone_from_the_graph_is_stale_at_once_and_never_live_is_never_stale() \
        -> None:
    slow = arrivals_every(1.0, 5)
    assert slow.last is not None
    assert stale_reason(slow, slow.last + 0.2, 0, "/s") == "no publisher of /s in the ROS graph"
    assert stale_reason(slow, slow.last + 0.05, 0, "/s") is None  # the graph may lag
    assert stale_reason(Arrivals(), 1e9, 0, "/never") is None
    one = arrivals_every(1.0, 1)
    assert one.last is not None and stale_reason(one, one.last + 100, 1, "/one") is None


@pytest.fixture(scope="module")
def daemon(module_processes: Processes) -> Iterator[RunningDaemon]:
    running = start_daemon(module_processes)
    yield running
    assert_clean_exit(running)


@pytest.mark.ros
def test_a_crashed_publisher_is_stale_at_the_client_and_live_again_when_back(
        daemon: RunningDaemon, processes: Processes) -> None:
    ros = slicer_client.connect("127.0.0.1", daemon.port)
    said: list[str] = []
    try:
        pose = ros.subscribe("/health_pose", "PoseStamped")
        pose.add_stale_callback(said.append)
        driver = processes.python("driver", "stream_publisher.py", "/health_pose", "50")
        driver.wait_for_output("READY", timeout=60)
        wait_until(lambda: pose.count >= 20, 30, "20 poses")
        assert pose.stale == ""
        driver.popen.send_signal(signal.SIGKILL)  # a crashed driver: no goodbye to the graph
        killed = time.monotonic()
        wait_until(lambda: pose.stale != "", 30, "the stream marked stale")
        noticed = time.monotonic() - killed
        print(f"\nstale at the client {noticed:.2f} s after the publisher was killed")
        assert pose.stale.startswith(("no message on /health_pose", "no publisher of"))
        # What the ROS2Bridge module shows: its client's stale streams; and the listing.
        assert stale_lines(ros.resources()) == [f"/health_pose is stale: {pose.stale}"]
        assert any("(STALE: " in line for line in describe_bridges(ros.list_bridges()))
        # A client that asks for it now is told at once, beside the last value.
        raw = daemon.connect()
        try:
            assert raw.command("create_subscriber", {"topic": "/health_pose",
                                                     "type": "PoseStamped"})["existed"] is True
            status = raw.wait_for(pose.device, lambda m: stream_condition(m) is not None,
                                  timeout=30)
            assert isinstance(status.body, Status)
            assert status.body.code == StatusCode.NOT_READY and status.body.error_name == \
                "stale"
        finally:
            raw.close()
        counted = pose.count
        again = processes.python("driver-again", "stream_publisher.py", "/health_pose", "50")
        again.wait_for_output("READY", timeout=60)
        wait_until(lambda: pose.stale == "" and pose.count > counted, 30, "the stream live")
        wait_until(lambda: not stale_lines(ros.list_bridges()), 10, "the module's line gone")
        wait_until(lambda: said[-1:] == [""], 10, "the live callback")
        assert said[0] == pose.stale or said[0].startswith(("no message", "no publisher"))
        # A publisher that stops cleanly leaves the graph: stale for that reason.
        again.stop()
        wait_until(lambda: pose.stale != "", 30, "stale after a clean stop")
        assert not ros.errors, ros.errors  # stale/live are not errors
    finally:
        ros.close()

"""`slicer-ros2-bridge topics | services | echo`: the `ros2 topic list/echo` checks of
SlicerROS2's documentation, for a ROS installed from wheels (no `ros2` command)."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from support import REPO, Processes, scaled, wait_until

pytestmark = pytest.mark.ros


@pytest.fixture
def pose_peer(processes: Processes) -> None:
    peer = processes.python("pose", "pose_publisher.py", "/gi_pose", "1", "2", "3",
                            "0", "0", "0", "1", "gi_world")
    peer.wait_for_output("READY", timeout=30)


def _finished(child: object, timeout: float = 60.0) -> int:
    popen = child.popen  # type: ignore[attr-defined]
    popen.wait(timeout)
    return int(popen.returncode)


def test_topics_lists_names_and_types_as_ros2_topic_list_t(processes: Processes,
                                                           pose_peer: None) -> None:
    def listed() -> bool:
        child = processes.bridge("topics", "--wait", "1")
        assert _finished(child) == 0, child.output()
        return "/gi_pose [geometry_msgs/msg/PoseStamped]" in child.lines()
    wait_until(listed, timeout=60, what="/gi_pose in the topic list")


def test_echo_prints_yaml_messages_separated_as_ros2_topic_echo(processes: Processes,
                                                               pose_peer: None) -> None:
    child = processes.bridge("echo", "/gi_pose", "--count", "2", "--wait", "30")
    assert _finished(child) == 0, child.output()
    messages = [m for m in child.output().split("---\n") if m.strip()]
    assert len(messages) == 2
    first = messages[0]
    assert "frame_id: gi_world" in first
    assert "position:\n    x: 1.0\n    y: 2.0\n    z: 3.0" in first
    assert "orientation:\n    x: 0.0\n    y: 0.0\n    z: 0.0\n    w: 1.0" in first


def test_echo_of_an_unknown_topic_says_what_to_check(processes: Processes) -> None:
    child = processes.bridge("echo", "/gi_nobody_publishes", "--wait", "0.5")
    assert _finished(child) == 1
    output = child.output()
    assert "expected a topic the ROS graph knows, got /gi_nobody_publishes" in output
    assert "ROS_DOMAIN_ID" in output and "Traceback" not in output


def test_echo_finds_a_topic_whose_publisher_starts_with_it(processes: Processes) -> None:
    """Issue 25, item 9: echo waits for discovery until the topic appears (10 s at most by
    default, not 2), so a publisher started at the same moment is found on a busy machine."""
    child = processes.bridge("echo", "/gi_together", "--count", "1")
    processes.python("together", "pose_publisher.py", "/gi_together", "4", "5", "6",
                     "0", "0", "0", "1", "gi_world")
    assert _finished(child) == 0, child.output()
    assert "position:\n    x: 4.0\n    y: 5.0\n    z: 6.0" in child.output()


def test_echo_with_a_type_and_no_publisher_yet_matches_a_volatile_one(
        processes: Processes) -> None:
    """With no publisher discovered, the subscription asks for the least (best effort,
    volatile): asking for the most, as BEST_AVAILABLE then does, never matches the volatile
    publisher that comes later (rclpy warns of an incompatible durability)."""
    child = processes.bridge("echo", "/gi_later", "geometry_msgs/msg/PoseStamped", "--wait",
                             "0", "--count", "1")
    processes.python("later", "pose_publisher.py", "/gi_later", "7", "8", "9",
                     "0", "0", "0", "1", "gi_world")
    assert _finished(child) == 0, child.output()
    assert "position:\n    x: 7.0\n    y: 8.0\n    z: 9.0" in child.output()
    assert "incompatible QoS" not in child.output()


def test_echo_of_a_misspelt_topic_names_what_the_graph_has(processes: Processes,
                                                           pose_peer: None) -> None:
    child = processes.bridge("echo", "/gi_pos", "--wait", "5")
    assert _finished(child) == 1
    output = child.output()
    line = next(x for x in output.splitlines() if "expected a topic the ROS graph knows" in x)
    # The count of topics seen, the closest name first.
    assert re.search(r"got /gi_pos: it is not among the \d+ topics \(/gi_pose, ", line), line
    assert "Traceback" not in output


def test_services_lists_no_inspector_s_services(processes: Processes) -> None:
    """Issue 25, item 11: another inspector (an echo still running) and this one are the
    CLI's own nodes: their parameter services are not listed; a peer's service is."""
    processes.python("server", "service_server.py", "--namespace", "gi").wait_for_output(
        "READY", timeout=30)
    echo = processes.bridge("echo", "/gi_nothing_here", "std_msgs/msg/String")

    def listed() -> list[str]:
        child = processes.bridge("services")
        assert _finished(child) == 0, child.output()
        return child.lines()
    lines: list[str] = []

    def both_seen() -> bool:
        lines[:] = listed()
        return "/gi/trigger [std_srvs/srv/Trigger]" in lines and echo.popen.poll() is None
    wait_until(both_seen, timeout=60, what="the peer's service in the list")
    assert not [line for line in lines if "slicer_bridge_inspect_" in line], lines
    assert "/gi/set_enabled [std_srvs/srv/SetBool]" in lines


def test_echo_with_a_type_that_is_not_installed(processes: Processes) -> None:
    child = processes.bridge("echo", "/gi_x", "no_such_pkg/msg/Thing", "--timeout", "1")
    assert _finished(child) == 1
    output = child.output()
    assert "expected a message type installed here, got 'no_such_pkg/msg/Thing'" in output
    assert "Traceback" not in output


def test_echo_into_a_reader_that_stops_ends_quietly(processes: Processes, tmp_path: Path,
                                                    pose_peer: None) -> None:
    """Issue 43, item 8: `echo /topic | head -3` printed a BrokenPipeError traceback (from
    the executor thread that wrote the message) and then hung. A closed stdout now ends the
    command at once, with no traceback and status 1 (Python's status for EPIPE)."""
    errors = tmp_path / "echo-stderr.log"
    with errors.open("wb") as stderr:
        popen = subprocess.Popen(
            [sys.executable, "-m", "bridge.console", "echo", "/gi_pose", "--wait", "30"],
            stdout=subprocess.PIPE, stderr=stderr, stdin=subprocess.DEVNULL,
            cwd=str(REPO), start_new_session=True)
    try:
        assert popen.stdout is not None
        head = [popen.stdout.readline() for _ in range(3)]  # as `head -3` reads
        popen.stdout.close()  # ... and exits
        try:
            status = popen.wait(scaled(30))
        except subprocess.TimeoutExpired:
            raise AssertionError(f"echo hung after its reader closed; stderr:\n"
                                 f"{errors.read_text()}") from None
    finally:
        if popen.poll() is None:
            os.killpg(popen.pid, signal.SIGKILL)
            popen.wait(5)
    assert head[0] == b"header:\n", head
    assert status == 1
    assert errors.read_text() == ""  # no traceback, no "Exception ignored" at exit

"""`slicer-ros2-bridge topics | services | echo`: the `ros2 topic list/echo` checks of
SlicerROS2's documentation, for a ROS installed from wheels (no `ros2` command)."""

from __future__ import annotations

import pytest

from support import Processes, wait_until

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
        return "/gi_pose [geometry_msgs/msg/PoseStamped]" in child.output().splitlines()
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


def test_echo_with_a_type_that_is_not_installed(processes: Processes) -> None:
    child = processes.bridge("echo", "/gi_x", "no_such_pkg/msg/Thing", "--timeout", "1")
    assert _finished(child) == 1
    output = child.output()
    assert "expected a message type installed here, got 'no_such_pkg/msg/Thing'" in output
    assert "Traceback" not in output

"""The demo's joint motion node (`python -m bridge.robots.demo.joint_motion`) as a real
process: options it refuses (exit 2, saying which), and a trajectory goal preempted by a
newer one, sent through the daemon (the first ends aborted, saying why; after the second
the arm holds still, then moves on by itself)."""

from __future__ import annotations

import json
import sys

import pytest

import slicer_client
from bridge.robots.demo.trajectory import DEFAULT_ACTION
from support import Child, Processes, scaled, start_daemon, wait_until

FJT = "control_msgs/action/FollowJointTrajectory"


def moving_states(echo: Child) -> list[bool]:
    """For each joint state the echo printed: whether the idle motion sent it (it carries
    velocities; a held or trajectory state has none)."""
    return [bool(json.loads(line[4:])["velocity"]) for line in echo.lines()
            if line.startswith("MSG ")]


def joint_motion(processes: Processes, *args: str):  # type: ignore[no-untyped-def]
    return processes.start("joint_motion", [sys.executable, "-u", "-m",
                                            "bridge.robots.demo.joint_motion", *args])


@pytest.mark.parametrize("args, said", [
    (["--rate", "0"], "--rate must be positive"),
    (["--yield-s", "-1"], "--yield-s must be >= 0"),
    (["--period", "0"], "joint_motion: period_s > 0 and 0 < fraction <= 1 expected, got 0.0"),
], ids=["rate", "yield", "period"])
def test_options_it_refuses(processes: Processes, args: list[str], said: str) -> None:
    child = joint_motion(processes, *args)
    assert child.popen.wait(scaled(30)) == 2
    output = child.output()
    assert said in output and "Traceback" not in output, output[-2000:]


@pytest.mark.ros
def test_a_trajectory_preempted_by_a_newer_goal(processes: Processes) -> None:
    motion = joint_motion(processes)  # no URDF: the built-in demo robot
    motion.wait_for_output("joint motion ready")
    echo = processes.python("echo", "echo_subscriber.py", "/joint_states",
                            "sensor_msgs/msg/JointState")
    echo.wait_for_output("READY")
    daemon = start_daemon(processes)
    ros = slicer_client.connect("127.0.0.1", daemon.port, reconnect=False)
    try:
        controller = ros.action(DEFAULT_ACTION, FJT)
        slow = controller.send_goal({"trajectory": {"joint_names": ["joint_1"], "points": [
            {"positions": [-1.5], "time_from_start": {"sec": 20}}]}}, timeout=scaled(10))
        wait_until(lambda: len(slow.feedback) >= 3, 10, "feedback of the first goal")
        newer = controller.send_goal({"trajectory": {"joint_names": ["joint_1"], "points": [
            {"positions": [0.5], "time_from_start": {"sec": 1}}]}}, timeout=scaled(10))
        result = slow.result(timeout=scaled(10))
        assert slow.status == "aborted"
        assert result["error_string"] == "preempted by a newer goal"
        assert newer.result(timeout=scaled(20))["error_code"] == 0
        assert newer.status == "succeeded"
        motion.wait_for_output("trajectory done")
        # The arm holds the goal's end for 10 s, then the idle motion takes over again.
        held = len(moving_states(echo))
        wait_until(lambda: not any(moving_states(echo)[held:held + 50]) and
                   len(moving_states(echo)) > held + 50, 10, "50 held joint states")
        wait_until(lambda: any(moving_states(echo)[held:]), scaled(30),
                   "the idle motion back after the hold")
    finally:
        ros.close()

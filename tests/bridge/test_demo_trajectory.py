"""The demo arm's FollowJointTrajectory controller: the pure interpolation and hold logic,
and the real thing: the demo's joint motion process moved by a goal sent through the daemon,
its joint states observed by an independent rclpy subscriber."""

from __future__ import annotations

import json
import re
import sys
from typing import Any

import pytest

import slicer_client
from bridge.robots.demo.motion_hold import MotionHold
from bridge.robots.demo.trajectory import DEFAULT_ACTION, InvalidTrajectory, TrajectoryRun
from protocol.commands import ErrorCode
from slicer_client.connection import CommandRefusedError
from support import Child, Processes, scaled, start_daemon, wait_until

ACTUATED = ("joint_1", "joint_2", "finger_left_joint")
FJT = "control_msgs/action/FollowJointTrajectory"


def test_positions_are_interpolated_from_where_the_arm_is() -> None:
    run = TrajectoryRun(["joint_1", "joint_2"], [(1.0, [1.0, -1.0]), (3.0, [0.0, 1.0])],
                        {"joint_1": 0.0, "joint_2": 0.5, "finger_left_joint": 0.01}, ACTUATED)
    assert run.positions_at(0.0) == {"joint_1": 0.0, "joint_2": 0.5}
    assert run.positions_at(0.5) == pytest.approx({"joint_1": 0.5, "joint_2": -0.25})
    assert run.positions_at(2.0) == pytest.approx({"joint_1": 0.5, "joint_2": 0.0})
    assert run.positions_at(9.0) == {"joint_1": 0.0, "joint_2": 1.0}
    assert run.duration == 3.0 and run.finished(3.0) and not run.finished(2.9)


@pytest.mark.parametrize("joints,points,expected", [
    (["elbow"], [(1.0, [0.0])], "joint names of the robot"),
    ([], [(1.0, [])], "joint_names"),
    (["joint_1", "joint_1"], [(1.0, [0.0, 0.0])], "each joint once"),
    (["joint_1"], [], "at least one trajectory point"),
    (["joint_1"], [(1.0, [0.0, 1.0])], "1 positions (one per joint), got 2"),
    (["joint_1"], [(1.0, [0.0]), (1.0, [1.0])], "point 1: a time_from_start after 1 s"),
])
def test_invalid_trajectories_say_what_was_expected(joints: list[str], points: list[Any],
                                                    expected: str) -> None:
    with pytest.raises(InvalidTrajectory, match=re.escape(expected)):
        TrajectoryRun(joints, points, {j: 0.0 for j in ACTUATED}, ACTUATED)


def test_the_hold_pauses_the_idle_motion_and_blends_back() -> None:
    hold = MotionHold()
    idle = {"a": 1.0, "b": 2.0}
    assert hold.apply(0.0, idle) == idle and hold.idle
    hold.hold({"a": 0.0})
    assert hold.apply(1.0, idle) == {"a": 0.0, "b": 2.0} and hold.holding
    hold.release(10.0)
    assert hold.apply(11.0, idle) == pytest.approx({"a": 0.5, "b": 2.0})  # half-way back
    assert hold.apply(12.0, idle) == idle and hold.idle


# ---------------------------------------------------------------------------- with ROS


def joint_states(echo: Child) -> list[dict[str, float]]:
    out = []
    for line in echo.output().splitlines():
        if line.startswith("MSG "):
            msg = json.loads(line[4:])
            out.append(dict(zip(msg["name"], msg["position"])))
    return out


@pytest.mark.ros
def test_the_demo_arm_follows_a_trajectory_sent_through_the_daemon(processes: Processes
                                                                   ) -> None:
    motion = processes.start("joint_motion", [sys.executable, "-u", "-m",
                                              "bridge.robots.demo.joint_motion"])
    motion.wait_for_output("joint motion ready")
    assert DEFAULT_ACTION in motion.output()
    echo = processes.python("echo", "echo_subscriber.py", "/joint_states",
                            "sensor_msgs/msg/JointState")
    echo.wait_for_output("READY")
    daemon = start_daemon(processes)
    ros = slicer_client.connect("127.0.0.1", daemon.port, reconnect=False)
    try:
        controller = ros.action(DEFAULT_ACTION, FJT)
        goal = {"trajectory": {"joint_names": ["joint_1", "joint_2"], "points": [
            {"positions": [1.0, -0.5], "time_from_start": {"sec": 1, "nanosec": 0}},
            {"positions": [1.5, 0.5], "time_from_start": {"sec": 1, "nanosec": 500_000_000}},
        ]}}
        handle = controller.send_goal(goal, timeout=scaled(10))
        result = handle.result(timeout=scaled(20))
        assert handle.status == "succeeded" and result["error_code"] == 0
        # Feedback came all along: desired vs actual, for the goal's joints.
        assert len(handle.feedback) >= 10
        assert handle.feedback[-1]["joint_names"] == ["joint_1", "joint_2"]
        assert handle.feedback[-1]["desired"]["positions"] == pytest.approx([1.5, 0.5])
        # The joint states reached the goal and stay there (the idle motion is paused).
        wait_until(lambda: len(joint_states(echo)) > 0 and
                   joint_states(echo)[-1]["joint_1"] == pytest.approx(1.5, abs=1e-6), 10,
                   "joint_1 at 1.5 rad")
        seen = len(joint_states(echo))
        wait_until(lambda: len(joint_states(echo)) >= seen + 25, 10, "25 more joint states")
        held = joint_states(echo)[seen:]
        assert all(s["joint_1"] == pytest.approx(1.5, abs=1e-6) and
                   s["joint_2"] == pytest.approx(0.5, abs=1e-6) for s in held)
        # The other joints kept where they were when the goal began.
        assert len({round(s["joint_3"], 9) for s in held}) == 1
        # On the way, joint_1 passed through the interpolated values.
        path = [s["joint_1"] for s in joint_states(echo)]
        assert any(0.2 < p < 0.9 for p in path) and any(1.05 < p < 1.45 for p in path)

        # Bad joints: rejected, as joint_trajectory_controller does.
        with pytest.raises(CommandRefusedError) as refused:
            controller.send_goal({"trajectory": {"joint_names": ["elbow"], "points": [
                {"positions": [1.0], "time_from_start": {"sec": 1}}]}}, timeout=scaled(10))
        assert refused.value.code == ErrorCode.REJECTED
        motion.wait_for_output("trajectory rejected: expected joint names of the robot")

        # A cancel mid-goal stops the arm where it is.
        slow = controller.send_goal({"trajectory": {"joint_names": ["joint_1"], "points": [
            {"positions": [-1.5], "time_from_start": {"sec": 20}}]}}, timeout=scaled(10))
        wait_until(lambda: len(slow.feedback) >= 5, 10, "feedback of the slow goal")
        assert slow.cancel(timeout=scaled(5))
        slow.result(timeout=scaled(10))
        assert slow.status == "canceled"
        motion.wait_for_output("trajectory canceled")
        stopped = joint_states(echo)[-1]["joint_1"]
        assert -1.5 < stopped < 1.5
        seen = len(joint_states(echo))
        wait_until(lambda: len(joint_states(echo)) >= seen + 10, 10, "10 more joint states")
        assert all(s["joint_1"] == pytest.approx(stopped, abs=1e-6)
                   for s in joint_states(echo)[seen:])
    finally:
        ros.close()

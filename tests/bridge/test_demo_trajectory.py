"""The demo arm's FollowJointTrajectory controller: the pure interpolation and hold logic,
and the real thing: the demo's joint motion process moved by a goal sent through the daemon,
its joint states observed by an independent rclpy subscriber."""

from __future__ import annotations

import json
import re
import sys
from typing import Any, Optional

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


def joint_states(echo: Child, *, idle: Optional[bool] = None) -> list[dict[str, float]]:
    """The positions of each joint state the echo printed; ``idle`` True: only the idle
    motion's (they carry velocities), False: only held or moved ones (no velocities)."""
    out = []
    for line in echo.lines():
        if line.startswith("MSG "):
            msg = json.loads(line[4:])
            if idle is None or bool(msg["velocity"]) == idle:
                out.append(dict(zip(msg["name"], msg["position"])))
    return out


def share_along(state: dict[str, float], a: dict[str, float], b: dict[str, float]
                ) -> Optional[float]:
    """u in [0, 1] if ``state`` is ``a + u (b - a)`` in every joint of ``a`` (1e-6), else
    None."""
    span = {j: b[j] - a[j] for j in a}
    norm = sum(d * d for d in span.values())
    if norm == 0.0:
        return 0.0 if all(abs(state[j] - a[j]) < 1e-6 for j in a) else None
    u = sum((state[j] - a[j]) * span[j] for j in a) / norm
    if not -1e-6 <= u <= 1 + 1e-6:
        return None
    return u if all(abs(state[j] - (a[j] + u * span[j])) < 1e-6 for j in a) else None


def started_from(line: str) -> dict[str, float]:
    """The positions a "trajectory started: ..., from joint_1=..., joint_2=..." line gives."""
    return {name: float(value) for name, value in
            (pair.split("=") for pair in line.split(" from ", 1)[1].split(", "))}


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
    # READY: its subscription exists; the motion's states reach it once discovery matched
    # the two, and only then can it see the whole trajectory.
    wait_until(lambda: len(joint_states(echo)) > 0, 20, "the echo's first joint state")
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
        # On the way, the joints went along the interpolation: from where the arm was
        # (the motion says where) to the first point, then to the second, both joints at
        # the same share of each segment, never back.
        start = started_from(motion.wait_for_output("trajectory started"))
        assert set(start) == {"joint_1", "joint_2"}
        first, second = {"joint_1": 1.0, "joint_2": -0.5}, {"joint_1": 1.5, "joint_2": 0.5}
        moved = joint_states(echo, idle=False)
        end = next(i for i, s in enumerate(moved)
                   if s["joint_1"] == pytest.approx(1.5, abs=1e-9) and
                   s["joint_2"] == pytest.approx(0.5, abs=1e-9))
        progress: list[tuple[int, float]] = []
        for state in moved[:end + 1]:
            u, v = share_along(state, start, first), share_along(state, first, second)
            if u is not None and (v is None or u < 1):
                progress.append((0, u))
            else:
                assert v is not None, (state, start)
                progress.append((1, v))
        assert progress == sorted(progress), progress
        if abs(start["joint_1"] - 1.0) + abs(start["joint_2"] + 0.5) > 0.01:
            assert any(0.05 < u < 0.95 for segment, u in progress if segment == 0), progress
        assert any(0.05 < v < 0.95 for segment, v in progress if segment == 1), progress

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

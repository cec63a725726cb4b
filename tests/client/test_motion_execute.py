"""Plan and execute (issue 46), end to end: a real daemon, the client over real TCP, the
demo's joint motion process serving FollowJointTrajectory for a one-joint arm, a Slicer
model (published to ROS, placed by a tf frame the client broadcasts) in the arm's way.
Executing to a goal behind it is refused naming the link and the obstacle, and nothing
moves; with the model moved away the arm reaches the goal, as an rclpy subscriber in
another process reads it on the arm's joint states."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pytest

import slicer_client
from protocol.commands import ErrorCode
from support import (Child, Processes, RunningDaemon, assert_clean_exit, scaled, start_daemon,
                     wait_until)
from motion_robots import ARM_URDF, box_mm, wait_loaded as _loaded

pytestmark = pytest.mark.ros
pytest.importorskip("pinocchio", reason="motion needs pin (pyproject's dependencies)")

ACTION = "/swing/follow_joint_trajectory"
BOX_MM = box_mm()
GOAL = 1.5  # rad; the arm is first sent to -1.0


@pytest.fixture(scope="module")
def robot_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("motion_execute")
    (folder / "swing.urdf").write_text(ARM_URDF)
    return folder


@pytest.fixture(scope="module")
def daemon(module_processes: Processes, robot_dir: Path) -> Iterator[RunningDaemon]:
    running = start_daemon(module_processes, "--robot-dir", str(robot_dir))
    yield running
    assert_clean_exit(running)


def _swing_states(echo: Child) -> list[float]:
    out = []
    for line in echo.lines():
        if line.startswith("MSG "):
            msg = json.loads(line[4:])
            out.append(dict(zip(msg["name"], msg["position"]))["swing"])
    return out


def _at(angle: float) -> np.ndarray:
    """The block's frame: on the tool's circle (0.5 m) at ``angle``, in mm."""
    placed = np.eye(4)
    placed[:3, 3] = (500.0 * math.cos(angle), 500.0 * math.sin(angle), 0.0)
    return placed


def test_execute_is_refused_through_an_obstacle_and_reaches_the_goal_without_it(
        daemon: RunningDaemon, robot_dir: Path, processes: Processes) -> None:
    motion = processes.start("swing-motion", [
        sys.executable, "-u", "-m", "bridge.robots.demo.joint_motion",
        str(robot_dir / "swing.urdf"), "--namespace", "swing", "--rate", "20",
        "--trajectory-action", ACTION, "--yield-s", "0"])
    motion.wait_for_output("joint motion ready", timeout=30)
    echo = processes.python("echo_swing", "echo_subscriber.py", "/swing/joint_states",
                            "sensor_msgs/msg/JointState")
    echo.wait_for_output("READY", timeout=30)
    ros = slicer_client.connect("127.0.0.1", daemon.port, reconnect=False)
    try:
        robot = ros.robot("swing", source={"kind": "file", "path": str(robot_dir / "swing.urdf")},
                          namespace="swing")
        _loaded(robot)
        # First to -1.0, no obstacle yet: the controller then holds it there.
        first = robot.execute({"swing": -1.0}, action=ACTION, duration_s=1.0)
        assert first.result(timeout=scaled(30))["error_code"] == 0
        wait_until(lambda: _swing_states(echo)[-1] == pytest.approx(-1.0, abs=1e-6),
                   timeout=30, what="the arm held at -1.0")

        # A block on the way from -1.0 to 1.5 (at 0.3 rad), placed by a tf frame.
        frame = ros.tf_broadcaster("base", "block_frame")
        placed = _at(0.3)
        robot.set_obstacle("block", "/obstacles/block")
        model = ros.publish_model("/obstacles/block", (BOX_MM.vertices, BOX_MM.faces),
                                  frame="block_frame", type="visualization_msgs/msg/Marker")
        plans: list[dict[str, Any]] = []

        def planned(clear: bool) -> bool:
            frame.broadcast(placed)
            model.send_model((BOX_MM.vertices, BOX_MM.faces))
            plans.append(robot.plan({"swing": GOAL}, resolution=0.01))
            return plans[-1]["clear"] is clear and not plans[-1]["unplaced"] and \
                plans[-1]["start"]["swing"] == pytest.approx(-1.0, abs=1e-6)
        wait_until(lambda: planned(False), timeout=30, what="a plan through the block")
        blocked = plans[-1]
        assert blocked["joints"] == ["swing"] and blocked["resolution"] == 0.01
        assert blocked["checked"] == 251  # 2.5 rad at 0.01 rad: 250 steps, both ends
        assert (blocked["collision"]["link"], blocked["collision"]["obstacle"]) == \
            ("tool", "block")
        # The tool (r 0.05 m) meets the block (a 0.1 m cube centred at 0.3 rad) at the
        # angle where the sphere first touches the cube: between 0.1 and 0.2 rad.
        assert 0.1 < blocked["collision"]["positions"]["swing"] < 0.2

        seen = len(_swing_states(echo))
        with pytest.raises(slicer_client.CommandRefusedError) as refused:
            robot.execute({"swing": GOAL}, action=ACTION)
        assert refused.value.code == ErrorCode.REJECTED and refused.value.field == "positions"
        assert "link 'tool' touches obstacle 'block'" in str(refused.value)
        wait_until(lambda: len(_swing_states(echo)) >= seen + 10, timeout=30,
                   what="ten more joint states")
        assert all(s == pytest.approx(-1.0, abs=1e-6) for s in _swing_states(echo)[seen:])

        # The block moved away (its tf frame): the path is clear, the arm goes.
        placed = _at(-2.5)
        wait_until(lambda: planned(True), timeout=30, what="a clear plan")
        handle = robot.execute({"swing": GOAL}, action=ACTION, duration_s=2.0)
        result = handle.result(timeout=scaled(30))
        assert handle.status == "succeeded" and result["error_code"] == 0
        wait_until(lambda: _swing_states(echo)[-1] == pytest.approx(GOAL, abs=1e-6),
                   timeout=30, what="the arm at the goal on /swing/joint_states")
        # On the way it went from -1.0 to the goal, never beyond.
        moved = [s for s in _swing_states(echo)[seen:] if abs(s + 1.0) > 1e-6]
        assert moved and all(-1.0 - 1e-6 <= s <= GOAL + 1e-6 for s in moved)
        assert moved == sorted(moved)
    finally:
        ros.close()

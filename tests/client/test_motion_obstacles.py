"""Obstacles from Slicer, the tool's distance to them, plan and execute (issue 46), end to
end: a real daemon, the client over real TCP publishing a model to ROS (the Slicer -> ROS
model path) and marking it an obstacle, a tf frame moved by the client (the obstacle
follows it), and rclpy subscribers in other processes reading the std_msgs/Float64
distance and the arm's joint states. Expected distances come from trimesh's closest point
(not coal, not the daemon's code). For execute, the demo's joint motion process serves
FollowJointTrajectory for a one-joint arm with a Slicer model in its way: executing to a
goal behind it is refused naming the link and the obstacle, and nothing moves; with the
model moved away the arm reaches the goal."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pytest

import slicer_client
from protocol.commands import ErrorCode
from motion_robots import ARM_URDF, BARE_URDF, RADIUS, SWING_ACTION, box_mm, start_swing
from support import (Child, Processes, RunningDaemon, assert_clean_exit, scaled, start_daemon,
                     wait_robot_described, wait_until)

pytestmark = pytest.mark.ros
pytest.importorskip("pinocchio", reason="motion needs pin (pyproject's dependencies)")
trimesh = pytest.importorskip("trimesh")

BOX_MM = box_mm()
BLOCK_AT_M = np.array([0.2, 0.45, 0.0])  # in the robot's base frame (via tf)


@pytest.fixture(scope="module")
def robot_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("motion_robots")
    (folder / "swing.urdf").write_text(ARM_URDF)
    (folder / "bare.urdf").write_text(BARE_URDF)
    return folder


@pytest.fixture(scope="module")
def daemon(module_processes: Processes, robot_dir: Path) -> Iterator[RunningDaemon]:
    running = start_daemon(module_processes, "--robot-dir", str(robot_dir),
                           "--deny-frame", "secret*")
    yield running
    assert_clean_exit(running)


def _expected_mm(swing: float, block_at_m: np.ndarray) -> float:
    """The sphere's distance to the block, by trimesh: closest point to its centre - r."""
    centre = 0.5 * np.array([math.cos(swing), math.sin(swing), 0.0])
    box = trimesh.Trimesh(BOX_MM.vertices / 1000.0 + block_at_m, BOX_MM.faces)
    _, distance, _ = trimesh.proximity.closest_point(box, [centre])
    return (float(distance[0]) - RADIUS) * 1000.0


def test_the_tool_distance_to_a_slicer_model(daemon: RunningDaemon, robot_dir: Path,
                                             processes: Processes) -> None:
    ros = slicer_client.connect("127.0.0.1", daemon.port, reconnect=False)
    try:
        robot = ros.robot("swing", source={"kind": "file", "path": str(robot_dir / "swing.urdf")})
        wait_robot_described(robot)
        # The block's frame, placed by a tf broadcast from the client (as a Slicer
        # transform node would be).
        frame = ros.tf_broadcaster("base", "block_frame")
        placed = np.eye(4)
        placed[:3, 3] = BLOCK_AT_M * 1000.0
        frame.broadcast(placed)
        reply = robot.set_obstacle("block", "/obstacles/block")
        assert reply["links"] == ["tool"]
        model = ros.publish_model("/obstacles/block", (BOX_MM.vertices, BOX_MM.faces),
                                  frame="block_frame", type="visualization_msgs/msg/Marker")

        def measured(swing: float) -> dict[str, Any]:
            answers: list[dict[str, Any]] = []

            def ready() -> bool:
                robot.set_joints({"swing": swing})
                frame.broadcast(placed)
                model.send_model((BOX_MM.vertices, BOX_MM.faces))
                answers.append(robot.obstacle_distances("tool"))
                got = answers[-1]
                return (got["positions"]["swing"] == pytest.approx(swing)
                        and bool(got["distances"]) and not got["unplaced"])
            wait_until(ready, timeout=30, what=f"the distance at swing {swing}")
            return answers[-1]

        at_rest = measured(0.3)
        [distance] = at_rest["distances"]
        assert distance["obstacle"] == "block"
        assert distance["distance_mm"] == pytest.approx(_expected_mm(0.3, BLOCK_AT_M), abs=0.1)
        assert at_rest["contacts"] == []

        # The block's frame moves (tf): the obstacle follows it.
        placed[:3, 3] = (200.0, 600.0, 0.0)
        moved = measured(0.3)
        assert moved["distances"][0]["distance_mm"] == pytest.approx(
            _expected_mm(0.3, np.array([0.2, 0.6, 0.0])), abs=0.1)

        # The same distance on ROS, read by an rclpy subscriber in another process.
        robot.publish_distance("tool", "block", "/swing/tool_distance", rate_hz=20.0)
        echo = processes.python("echo_distance", "echo_subscriber.py", "/swing/tool_distance",
                                "std_msgs/msg/Float64")
        echo.wait_for_output("READY", timeout=30)

        def on_ros() -> list[float]:
            return [json.loads(line[4:])["data"] for line in echo.lines()
                    if line.startswith("MSG ")]
        wait_until(lambda: len(on_ros()) >= 3, timeout=30, what="three distances on ROS")
        expected = _expected_mm(0.3, np.array([0.2, 0.6, 0.0]))
        assert on_ros()[-1] * 1000.0 == pytest.approx(expected, abs=0.1)  # metres on ROS

        # Swung into the block: a contact, and a solve there is refused naming both.
        placed[:3, 3] = BLOCK_AT_M * 1000.0
        into = measured(math.atan2(0.45, 0.2))
        assert into["contacts"] == [{"link": "tool", "obstacle": "block"}]
        assert into["distances"][0]["distance_mm"] == 0.0
        c, s = math.cos(1.15), math.sin(1.15)  # the tool at swing 1.15: inside the block
        target = np.array([[c, -s, 0.0, 500.0 * c], [s, c, 0.0, 500.0 * s],
                           [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
        with pytest.raises(slicer_client.IkFailedError) as failed:
            robot.solve_ik(target, tip="tool")
        assert (failed.value.reason, failed.value.link, failed.value.obstacle) == \
            ("collision", "tool", "block")
        robot.remove_obstacle("block")
        assert robot.solve_ik(target, tip="tool")["swing"] == pytest.approx(1.15, abs=1e-6)

        # Bad input: a degenerate mesh is refused with the reason, the daemon serving on.
        robot.set_obstacle("flat", "/obstacles/flat")
        flat = ros.publish_model("/obstacles/flat", (np.zeros((4, 3)), [[0, 1, 2], [1, 2, 3]]),
                                 frame="base", type="visualization_msgs/msg/Marker")
        reasons: list[str] = []

        def refused() -> bool:
            flat.send_model((np.zeros((4, 3)), [[0, 1, 2], [1, 2, 3]]))
            unplaced = robot.obstacle_distances("tool")["unplaced"]
            reasons[:] = [u["reason"] for u in unplaced if u["obstacle"] == "flat"]
            return bool(reasons) and "degenerate" in reasons[0]
        wait_until(refused, timeout=30, what="the flat mesh refused")
        assert "triangles with an area" in reasons[0]

        # A frame the policy denies: a Mesh's frame is refused with the request (a Marker's
        # frame_id is judged as it arrives; this client cannot publish one there anyway).
        with pytest.raises(slicer_client.CommandRefusedError) as caught:
            robot.set_obstacle("hidden", "/obstacles/hidden", type="Mesh", frame="secret_room")
        assert caught.value.field == "frame" and caught.value.code == ErrorCode.FORBIDDEN

        # A robot with no geometry at all cannot have obstacles: refused, naming it.
        bare = ros.robot("bare", source={"kind": "file", "path": str(robot_dir / "bare.urdf")})
        wait_robot_described(bare)
        with pytest.raises(slicer_client.CommandRefusedError) as caught:
            bare.set_obstacle("block", "/obstacles/block")
        assert caught.value.field == "name" and "collision geometry" in str(caught.value)
        with pytest.raises(slicer_client.CommandRefusedError) as caught:
            robot.obstacle_distances("no_link")
        assert caught.value.field == "link"

        # The robot removed: its obstacles' subscriptions and its distance topic go too.
        ros.command("remove_robot", {"name": "swing"})
        wait_until(lambda: "motion: robot swing dropped (1 obstacle(s), 1 distance topic(s))"
                   in daemon.child.output(), timeout=30, what="the motion state dropped")
    finally:
        ros.close()


# ---------------------------------------------------------------------------- execute

ACTION = SWING_ACTION
GOAL = 1.5  # rad; the arm is first sent to -1.0


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
    _, echo = start_swing(processes, robot_dir / "swing.urdf")
    ros = slicer_client.connect("127.0.0.1", daemon.port, reconnect=False)
    try:
        robot = ros.robot("driven", namespace="swing",  # the other test's "swing" lives on
                          source={"kind": "file", "path": str(robot_dir / "swing.urdf")})
        wait_robot_described(robot)
        # The daemon hears the arm's joint states (discovery may take a while here).
        def heard() -> bool:
            try:
                robot.plan({"swing": -1.0})
            except slicer_client.CommandRefusedError as error:
                assert error.code == ErrorCode.UNAVAILABLE, error
                return False
            return True
        wait_until(heard, timeout=30, what="the arm's joint states heard by the daemon")
        # First to -1.0, no obstacle yet: the controller then holds it there.
        first = robot.execute({"swing": -1.0}, action=ACTION, duration_s=1.0)
        assert first.result(timeout=scaled(30))["error_code"] == 0
        wait_until(lambda: bool(_swing_states(echo)) and
                   _swing_states(echo)[-1] == pytest.approx(-1.0, abs=1e-6),
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
        # The first configuration in contact is where trimesh first finds the sphere's
        # centre within its radius of the cube (a step either way: a touch is a tie).
        start = blocked["start"]["swing"]
        cube = trimesh.Trimesh(BOX_MM.vertices / 1000.0 + _at(0.3)[:3, 3] / 1000.0,
                               BOX_MM.faces)
        angles = start + (GOAL - start) * np.arange(251) / 250
        centres = np.stack([0.5 * np.cos(angles), 0.5 * np.sin(angles),
                            np.zeros_like(angles)], axis=1)
        gaps = trimesh.proximity.closest_point(cube, centres)[1] - RADIUS
        assert abs(blocked["collision"]["step"] - int(np.argmax(gaps <= 1e-9))) <= 1

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


def test_a_reloaded_robot_keeps_its_obstacles(daemon: RunningDaemon) -> None:
    """The robot's description changes (a new URDF on its topic): motion rebuilds its model
    and sets its obstacles again on it, so solves and distances go on avoiding them."""
    ros = slicer_client.connect("127.0.0.1", daemon.port, reconnect=False)
    try:
        description = ros.publisher("/reloading/robot_description", "std_msgs/msg/String",
                                    qos={"durability": "transient_local", "depth": 1})
        description.publish(ARM_URDF)
        robot = ros.robot("reloading", source={"kind": "topic",
                                               "topic": "/reloading/robot_description"})
        wait_robot_described(robot)
        robot.set_obstacle("block", "/reloading/block")
        model = ros.publish_model("/reloading/block", (BOX_MM.vertices, BOX_MM.faces),
                                  frame="base", type="visualization_msgs/msg/Marker")

        def measured() -> bool:
            robot.set_joints({"swing": 0.0}, topic="/joint_states")
            model.send_model((BOX_MM.vertices + (300.0, 0.0, 0.0), BOX_MM.faces))
            got = robot.obstacle_distances("tool")
            return bool(got["distances"]) and not got["unplaced"]
        wait_until(measured, timeout=30, what="the block measured")
        # A new description (the tool 10 cm further out): the robot reloads.
        description.publish(ARM_URDF.replace('xyz="0.5 0 0"', 'xyz="0.6 0 0"'))
        wait_until(lambda: any(r["name"] == "reloading" and r["loads"] == 2 for r in
                               ros.command("list_robots", {})["robots"]),
                   timeout=30, what="the reload")
        answers: list[dict[str, Any]] = []

        def again() -> bool:
            model.send_model((BOX_MM.vertices + (300.0, 0.0, 0.0), BOX_MM.faces))
            answers.append(robot.obstacle_distances("tool"))
            return bool(answers[-1]["distances"]) and not answers[-1]["unplaced"]
        wait_until(again, timeout=30, what="the block measured after the reload")
        # The block spans x 0.25..0.35 m; the tool (r 0.05) now at 0.6 m: 0.2 m away.
        assert answers[-1]["distances"][0]["distance_mm"] == pytest.approx(200.0, abs=0.1)
    finally:
        ros.close()

"""Obstacles from Slicer and the tool's distance to them (issue 46), end to end: a real
daemon, the client over real TCP publishing a model to ROS (the Slicer -> ROS model path)
and marking it an obstacle, a tf frame moved by the client (the obstacle follows it), and
an rclpy subscriber in another process reading the std_msgs/Float64 distance. Expected
distances come from trimesh's closest point (not coal, not the daemon's code)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pytest

import slicer_client
from motion_robots import ARM_URDF, BARE_URDF, RADIUS, box_mm, wait_loaded as _loaded
from support import Processes, RunningDaemon, assert_clean_exit, start_daemon, wait_until

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
    running = start_daemon(module_processes, "--robot-dir", str(robot_dir))
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
        _loaded(robot)
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

        # A robot with no geometry at all cannot have obstacles: refused, naming it.
        bare = ros.robot("bare", source={"kind": "file", "path": str(robot_dir / "bare.urdf")})
        _loaded(bare)
        with pytest.raises(slicer_client.CommandRefusedError) as caught:
            bare.set_obstacle("block", "/obstacles/block")
        assert caught.value.field == "name" and "collision geometry" in str(caught.value)
        with pytest.raises(slicer_client.CommandRefusedError) as caught:
            robot.obstacle_distances("no_link")
        assert caught.value.field == "link"
    finally:
        ros.close()

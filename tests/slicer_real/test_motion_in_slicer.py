"""The ROS2Bridge module's Motion logic in a real Slicer scene against `make demo`'s daemon
(issue 46): targets from the scene solved by the daemon's IK and shown by the preview robot
(scenes/motion.py). The target is the tool flange at joint positions chosen here, by
yourdfpy's forward kinematics (not the daemon's)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from bridge.robots.demo import demo_urdf_path
from motion_robots import ARM_URDF, RADIUS, SWING_ACTION, box_mm, start_swing
from support import Processes, RunningDaemon, start_daemon, wait_until

pytestmark = pytest.mark.ros
yourdfpy = pytest.importorskip("yourdfpy")
trimesh = pytest.importorskip("trimesh")

ACTION = SWING_ACTION
GOAL_RAD = 1.5  # the swing arm's goal, behind the block
TIP = "tool_flange"
GOAL = {"joint_1": 0.4, "joint_2": -0.6, "joint_3": 1.1, "joint_4": -0.3, "joint_5": 0.8,
        "joint_6": 0.2}


def _flange_mm(tmp_path: Path, positions: dict[str, float] = GOAL) -> list[list[float]]:
    """The demo's flange in its base frame (mm) at `positions`, by yourdfpy's FK."""
    urdf, _ = demo_urdf_path(tmp_path)
    model = yourdfpy.URDF.load(str(urdf), load_meshes=False, load_collision_meshes=False,
                               build_collision_scene_graph=False)
    model.update_cfg(positions)
    matrix = np.array(model.get_transform(frame_to=TIP, frame_from="base_link"))
    matrix[:3, 3] *= 1000.0
    return matrix.tolist()


def _distance_mm(a: list[list[float]], b: list[list[float]]) -> float:
    return float(np.linalg.norm(np.array(a)[:3, 3] - np.array(b)[:3, 3]))


def _angle_deg(a: list[list[float]], b: list[list[float]]) -> float:
    ra, rb = np.array(a)[:3, :3], np.array(b)[:3, :3]
    return math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(ra.T @ rb) - 1.0) / 2.0))))


def test_the_motion_preview_follows_targets_from_the_scene(
        run_scene, demo: RunningDaemon, tmp_path: Path) -> None:
    got = run_scene("motion", timeout=300, port=demo.port, robot="demo", models=14,
                    tip=TIP, root="base_link", target_in_root=_flange_mm(tmp_path))
    target = got["target_world"]
    # A transform node: solved; the preview's flange is at the target; preview models green.
    first = got["transform"]
    assert first["solved"] and first["status"].startswith("Solved: tool_flange"), first
    assert _distance_mm(first["preview_tip"], target) <= 0.1
    assert _angle_deg(first["preview_tip"], target) <= 0.1
    assert first["preview_models"] == 14
    assert all(c == pytest.approx([0.25, 0.8, 0.35]) for c in first["colours"])
    # The planned path in Slicer's sequence browser: its first, middle and last items put
    # the preview's flange where yourdfpy's FK puts it at those configurations (the last:
    # at the target), at their times along the path.
    path = got["path"]
    assert path["clear"] and path["items"] == min(50, path["checked"]), path
    assert path["status"].startswith("Path planned:")
    root = np.array(path["root_world"])
    for item in path["scrubbed"]:
        want = (root @ np.array(_flange_mm(tmp_path, item["positions"]))).tolist()
        assert _distance_mm(item["preview_tip"], want) <= 0.1, item
        assert float(item["index_value"]) == pytest.approx(item["time_s"], abs=1e-5)
    assert _distance_mm(path["scrubbed"][-1]["preview_tip"], target) <= 0.1
    # Dragged 20 times between two frames: solved fewer times than it moved, and the
    # preview ends at the newest position.
    dragged = got["dragged"]
    assert 1 <= dragged["solves"] < dragged["moves"], dragged
    assert _distance_mm(dragged["preview_tip"], dragged["target"]) <= 0.1, dragged
    # Unreachable: refused with the reason, the best attempt shown red.
    far = got["unreachable"]
    assert not far["solved"] and far["reason"] == "unreachable", far
    assert far["status"].startswith("Not solved (unreachable)")
    assert all(c == pytest.approx([0.9, 0.1, 0.1]) for c in far["colours"])
    # A markups point with the same orientation: solved to the same pose.
    assert got["markups"]["solved"]
    assert _distance_mm(got["markups"]["preview_tip"], target) <= 0.1
    assert _angle_deg(got["markups"]["preview_tip"], target) <= 0.1
    # The preview is removed whole. (That solving never moves the arm is checked where
    # the arm stands still: tests/client/test_motion_solve_ik.py; the demo's arm moves.)
    assert got["previews_left"] == 0


def test_a_scene_model_as_obstacle_refuses_then_allows_execution(
        run_scene, processes: Processes, tmp_path: Path) -> None:
    """Issue 46's second "Done when" through the module: a Slicer model in the arm's way
    refuses execution naming the link and the obstacle; moved away, the arm reaches the
    goal, read on /swing/joint_states by an rclpy subscriber in another process."""
    (tmp_path / "swing.urdf").write_text(ARM_URDF)
    daemon = start_daemon(processes, "--robot-dir", str(tmp_path))
    _, echo = start_swing(processes, tmp_path / "swing.urdf")
    got = run_scene("motion_execute", timeout=300, port=daemon.port,
                    urdf=str(tmp_path / "swing.urdf"), action=ACTION, goal=GOAL_RAD)
    assert got["first"] == "succeeded" and got["obstacle"] == "block"
    # The distance streamed to the scene, against trimesh's closest point on the same block
    # (a 10 cm cube at 0.3 rad on the 500 mm circle) from the tool sphere (r 50 mm) at -1.0.
    block = box_mm()
    block.apply_translation((500.0 * math.cos(0.3), 500.0 * math.sin(0.3), 0.0))
    centre = np.array([[500.0 * math.cos(-1.0), 500.0 * math.sin(-1.0), 0.0]])
    nearest, _, _ = trimesh.proximity.closest_point(block, centre)
    want = float(np.linalg.norm(nearest[0] - centre[0])) - RADIUS * 1000.0
    assert got["watched"] == ["block"]
    assert got["distance_mm"] == pytest.approx(want, abs=0.1), (got["distance_mm"], want)
    assert got["distance_line"] == f"tool to block: {want:.1f} mm"
    assert "link 'tool' touches obstacle 'block'" in got["refused"], got["refused"]
    assert got["plans"][-1] is True and False in got["plans"]
    assert got["second"] == {"status": "succeeded", "error_code": 0}
    # A segmentation (a cube segment at -2.0 rad) as an obstacle: its distance from the tool,
    # now at the goal, as trimesh has it.
    assert got["segmentation_obstacle"] == "organ"
    organ = box_mm()
    organ.apply_translation((500.0 * math.cos(-2.0), 500.0 * math.sin(-2.0), 0.0))
    tool = np.array([[500.0 * math.cos(GOAL_RAD), 500.0 * math.sin(GOAL_RAD), 0.0]])
    nearest, _, _ = trimesh.proximity.closest_point(organ, tool)
    want_organ = float(np.linalg.norm(nearest[0] - tool[0])) - RADIUS * 1000.0
    assert got["organ_distance_mm"] == pytest.approx(want_organ, abs=0.1)

    def swing() -> list[float]:
        return [dict(zip(m["name"], m["position"]))["swing"]
                for m in (json.loads(line[4:]) for line in echo.lines()
                          if line.startswith("MSG "))]
    wait_until(lambda: swing() and swing()[-1] == pytest.approx(GOAL_RAD, abs=1e-6),
               timeout=30, what="the arm at the goal on /swing/joint_states")

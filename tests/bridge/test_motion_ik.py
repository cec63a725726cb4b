"""Inverse kinematics on pinocchio (issue 46): targets from random valid configurations of
real robots are solved, each solution checked by an independent FK (yourdfpy's, not
pinocchio's nor the project's), within limits; unreachable targets and bad input refused
with the reason."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from bridge.robots import RobotModel, load_robot, load_robot_file
from bridge.robots.demo import demo_urdf_path
from jointy_urdf import JOINTY_URDF
from seven_dof_urdf import SEVEN_DOF_URDF
from support import require_shared

pytest.importorskip("pinocchio", reason="motion needs pin (pyproject's dependencies)")
yourdfpy = pytest.importorskip("yourdfpy")

from bridge.motion.errors import MotionInputError  # noqa: E402
from bridge.motion.ik import solve_ik  # noqa: E402
from bridge.motion.model import MotionModel  # noqa: E402
from bridge.motion.ik import COLLISION, JOINT_LIMIT, UNREACHABLE  # noqa: E402

TARGETS = 300  # per robot; >= 99 % must be solved
MM, DEG = 0.1, 0.1  # the bound on every solution's error


def _demo(tmp: Path) -> RobotModel:
    urdf, packages = demo_urdf_path(tmp)
    return load_robot_file(urdf, package_paths=packages)


def _omni(_: Path) -> RobotModel:
    folder = require_shared("robots/sensable_omni_model")
    return load_robot_file(folder / "urdf/omni.urdf",
                           package_paths={"sensable_omni_model": folder})


def _seven(_: Path) -> RobotModel:
    return load_robot(SEVEN_DOF_URDF)


def _jointy(_: Path) -> RobotModel:
    return load_robot(JOINTY_URDF)


# robot, tip link, actuated joints moving the tip
ROBOTS = {
    "demo": (_demo, "tool_flange", 6),  # 6 revolute + a gripper (prismatic and its mimic)
    "omni": (_omni, "stylus", 6),  # the real Phantom Omni (6 revolute)
    "seven_dof": (_seven, "tcp", 7),  # a Panda's chain, 7 revolute + mimic fingers
    "jointy": (_jointy, "d", 3),  # revolute, continuous, prismatic with a mimic
}


def _independent_fk(robot: RobotModel, tmp: Path):  # type: ignore[no-untyped-def]
    path = tmp / "independent.urdf"
    path.write_text(robot.urdf)
    return yourdfpy.URDF.load(str(path), load_meshes=False, load_collision_meshes=False,
                              build_collision_scene_graph=False)


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    cos = (np.trace(a.T @ b) - 1.0) / 2.0
    return math.degrees(math.acos(max(-1.0, min(1.0, cos))))


def _within_limits(robot: RobotModel, positions: dict[str, float]) -> list[str]:
    """Joints (mimics computed as the URDF says) outside their URDF limits."""
    outside = []
    values = dict(positions)
    for name, joint in robot.joints.items():
        if joint.mimic is not None:
            values[name] = joint.mimic.multiplier * values.get(joint.mimic.joint, 0.0) \
                + joint.mimic.offset
    for name, joint in robot.joints.items():
        if joint.limits is None or joint.type == "continuous" or name not in values:
            continue
        if not joint.limits.lower - 1e-9 <= values[name] <= joint.limits.upper + 1e-9:
            outside.append(name)
    return outside


@pytest.mark.parametrize("name", list(ROBOTS))
def test_random_reachable_targets_are_solved(name: str, tmp_path: Path) -> None:
    load, tip, moving = ROBOTS[name]
    robot = load(tmp_path)
    model = MotionModel(robot)
    assert int(model.moves_frame(model.frame_id(tip)).sum()) == moving
    urdf = _independent_fk(robot, tmp_path)
    rng = np.random.default_rng(46)
    solved = 0
    worst_mm = worst_deg = 0.0
    for _ in range(TARGETS):
        truth = model.random_theta(rng)
        target = model.link_pose(truth, tip)
        # Seeded from another random state (the current one, as the op does).
        seed = model.positions_of(model.random_theta(rng))
        result = solve_ik(model, target, tip, seed)
        if not result.ok:
            continue
        solved += 1
        assert _within_limits(robot, result.positions) == []
        cfg = {n: v for n, v in result.positions.items()}
        for joint_name, joint in robot.joints.items():  # yourdfpy wants the mimics too
            if joint.mimic is not None:
                cfg.pop(joint_name, None)
        urdf.update_cfg(cfg)
        reached = urdf.get_transform(frame_to=tip, frame_from=robot.root_link)
        error_mm = float(np.linalg.norm(reached[:3, 3] - target[:3, 3])) * 1000.0
        error_deg = _angle_deg(reached[:3, :3], target[:3, :3])
        worst_mm, worst_deg = max(worst_mm, error_mm), max(worst_deg, error_deg)
        assert error_mm <= MM and error_deg <= DEG, (name, result, error_mm, error_deg)
        assert result.residual_mm <= MM and result.residual_deg <= DEG
    rate = solved / TARGETS
    print(f"{name}: {solved}/{TARGETS} solved ({rate:.1%}); worst {worst_mm:.2e} mm, "
          f"{worst_deg:.2e} deg")
    assert rate >= 0.99, f"{name}: {solved}/{TARGETS} solved"


def test_the_solve_starts_from_the_seed_and_leaves_other_joints(tmp_path: Path) -> None:
    robot = _demo(tmp_path)
    model = MotionModel(robot)
    seed = {"joint_1": 0.3, "joint_2": -0.4, "joint_3": 0.9, "joint_4": 0.1, "joint_5": 0.5,
            "joint_6": -0.2, "finger_left_joint": 0.012}
    target = model.link_pose(model.theta_of(seed), "tool_flange")
    result = solve_ik(model, target, "tool_flange", seed)
    assert result.ok and result.attempts == 1 and result.iterations == 1
    assert result.positions == pytest.approx(seed, abs=1e-12)
    # A nearby target: solved from the seed in one attempt, the gripper untouched.
    moved = target.copy()
    moved[:3, 3] += (0.01, -0.005, 0.0)
    near = solve_ik(model, moved, "tool_flange", seed)
    assert near.ok and near.attempts == 1
    assert near.positions["finger_left_joint"] == 0.012
    # The same branch as the seed (no flip of elbow or wrist): small changes only.
    assert max(abs(near.positions[j] - seed[j]) for j in seed) < 0.3


def test_unreachable_target_is_refused_with_the_residual(tmp_path: Path) -> None:
    model = MotionModel(_demo(tmp_path))
    target = np.eye(4)
    target[:3, 3] = (3.0, 0.0, 0.5)  # 3 m away; the arm reaches < 1 m
    result = solve_ik(model, target, "tool_flange")
    assert not result.ok
    assert result.failure is not None and result.failure.reason == UNREACHABLE
    assert result.residual_mm > 1500.0  # the best attempt's distance, in mm


ONE_JOINT = """<robot name="one_joint">
  <link name="base"/><link name="arm"/><link name="tip"/>
  <joint name="swing" type="revolute"><parent link="base"/><child link="arm"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="mount" type="fixed"><parent link="arm"/><child link="tip"/>
    <origin xyz="0.5 0 0"/></joint>
</robot>"""


def test_a_target_beyond_a_limit_names_the_joint() -> None:
    model = MotionModel(load_robot(ONE_JOINT))
    beyond = model.link_pose(np.array([2.0]), "tip")  # swing = 2 rad, its limit is 1
    result = solve_ik(model, beyond, "tip")
    assert result.failure is not None and result.failure.reason == JOINT_LIMIT
    assert result.failure.joints == ("swing",)
    assert result.positions["swing"] == pytest.approx(1.0)  # the nearest it gets
    # The tip 0.5 m from the axis: at swing = 1 it is 0.5 * |2 sin(0.5)| = 0.479 m away.
    assert result.residual_mm == pytest.approx(479.4, abs=0.1)
    assert result.residual_deg == pytest.approx(math.degrees(1.0), abs=1e-6)


def test_a_solution_through_an_obstacle_is_refused_naming_both() -> None:
    from bridge.motion.collisions import CollisionWorld

    model = MotionModel(load_robot(ONE_JOINT.replace(
        '<link name="tip"/>',
        '<link name="tip"><collision><geometry><sphere radius="0.05"/></geometry>'
        '</collision></link>')))
    world = CollisionWorld(model)
    target = model.link_pose(np.array([0.5]), "tip")
    box = _box_mesh(0.1)
    world.set_obstacle("tumour", box[0], box[1], target)  # a 0.1 m box where the tip goes
    result = solve_ik(model, target, "tip", world=world)
    assert result.failure is not None and result.failure.reason == COLLISION
    assert (result.failure.link, result.failure.obstacle) == ("tip", "tumour")
    assert result.residual_mm < 1e-3  # it reached the target; the contact refused it
    world.remove_obstacle("tumour")
    assert solve_ik(model, target, "tip", world=world).ok


def _box_mesh(size: float) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    box = trimesh.creation.box((size, size, size))
    return np.asarray(box.vertices), np.asarray(box.faces)


@pytest.mark.parametrize("bad, field", [
    (np.full((4, 4), np.nan), "target"),
    (np.diag([2.0, 1.0, 1.0, 1.0]), "target rotation"),
    (np.eye(3), "target"),
])
def test_bad_targets_are_typed_errors(bad: np.ndarray, field: str) -> None:
    model = MotionModel(load_robot(ONE_JOINT))
    with pytest.raises(MotionInputError) as caught:
        solve_ik(model, bad, "tip")
    assert caught.value.field == field


def test_an_unknown_tip_link_is_a_typed_error() -> None:
    model = MotionModel(load_robot(ONE_JOINT))
    with pytest.raises(MotionInputError) as caught:
        solve_ik(model, np.eye(4), "wrist")
    assert caught.value.field == "tip"
    assert "a link of robot 'one_joint' (base, arm, tip)" in str(caught.value)

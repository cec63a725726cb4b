"""Forward kinematics against matrices written out by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bridge.robots import Kinematics, RobotError, parse_urdf

ARM = """<robot name="arm">
  <link name="base"/><link name="turn"/><link name="slide"/><link name="spin"/>
  <link name="follower"/><link name="follower2"/><link name="tool"/><link name="free"/>
  <joint name="hinge" type="revolute">
    <parent link="base"/><child link="turn"/>
    <origin xyz="1 2 3"/><axis xyz="1 0 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
  <joint name="rail" type="prismatic">
    <parent link="turn"/><child link="slide"/>
    <origin xyz="0 0 0.5" rpy="0 0 1.5707963267948966"/><axis xyz="0 0 2"/>
    <limit lower="0" upper="1" effort="1" velocity="1"/>
  </joint>
  <joint name="wheel" type="continuous">
    <parent link="slide"/><child link="spin"/><axis xyz="0 0 1"/>
  </joint>
  <joint name="copy" type="revolute">
    <parent link="base"/><child link="follower"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
    <mimic joint="hinge" multiplier="-2" offset="0.1"/>
  </joint>
  <joint name="copy_of_copy" type="prismatic">
    <parent link="base"/><child link="follower2"/><axis xyz="1 0 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
    <mimic joint="copy" multiplier="0.5"/>
  </joint>
  <joint name="mount" type="fixed">
    <parent link="spin"/><child link="tool"/><origin xyz="0.1 0 0"/>
  </joint>
  <joint name="float" type="floating">
    <parent link="base"/><child link="free"/><origin xyz="0 0 9"/>
  </joint>
</robot>"""


def matrix(rows) -> np.ndarray:
    return np.array(rows, dtype=np.float64)


@pytest.fixture(scope="module")
def arm() -> Kinematics:
    return Kinematics(parse_urdf(ARM))


def test_revolute_at_90_degrees(arm: Kinematics) -> None:
    poses = arm.link_poses({"hinge": math.pi / 2})
    # 90 degrees about x: y -> z, z -> -y; the origin translates by (1, 2, 3).
    np.testing.assert_allclose(poses["turn"], matrix([[1, 0, 0, 1], [0, 0, -1, 2],
                                                      [0, 1, 0, 3], [0, 0, 0, 1]]), atol=1e-12)


def test_prismatic_moves_along_its_normalised_axis(arm: Kinematics) -> None:
    poses = arm.link_poses({"rail": 0.25})
    # origin z + 0.5 and a quarter turn about z; the axis (0 0 2) is a unit z: +0.25.
    np.testing.assert_allclose(poses["slide"], matrix([[0, -1, 0, 1], [1, 0, 0, 2],
                                                       [0, 0, 1, 3.75], [0, 0, 0, 1]]),
                               atol=1e-12)


def test_chain_with_continuous_and_fixed(arm: Kinematics) -> None:
    poses = arm.link_poses({"hinge": math.pi / 2, "rail": 0.25, "wheel": math.pi})
    # base->turn: Rx(90) at (1,2,3); turn->slide: Rz(90) at (0,0,0.75) in turn's frame,
    # which Rx(90) maps to (0,-0.75,0); slide->spin: Rz(180); spin->tool: (0.1, 0, 0).
    rx = matrix([[1, 0, 0], [0, 0, -1], [0, 1, 0]])
    rz90 = matrix([[0, -1, 0], [1, 0, 0], [0, 0, 1]])
    rz180 = matrix([[-1, 0, 0], [0, -1, 0], [0, 0, 1]])
    spin_r = rx @ rz90 @ rz180
    spin_t = np.array([1.0, 2 - 0.75, 3.0])
    np.testing.assert_allclose(poses["spin"][:3, :3], spin_r, atol=1e-12)
    np.testing.assert_allclose(poses["spin"][:3, 3], spin_t, atol=1e-12)
    np.testing.assert_allclose(poses["tool"][:3, 3], spin_t + spin_r @ [0.1, 0, 0], atol=1e-12)


def test_mimic_joints_and_chains_of_them(arm: Kinematics) -> None:
    q = arm.positions_vector({"hinge": 0.3})
    by_name = dict(zip(arm.joint_names, q))
    assert by_name["copy"] == pytest.approx(-2 * 0.3 + 0.1)
    assert by_name["copy_of_copy"] == pytest.approx(0.5 * (-2 * 0.3 + 0.1))
    poses = arm.link_poses({"hinge": 0.3, "copy": 99.0})  # a mimic's own value is ignored
    angle = -0.5
    np.testing.assert_allclose(poses["follower"][:3, :3],
                               matrix([[math.cos(angle), -math.sin(angle), 0],
                                       [math.sin(angle), math.cos(angle), 0], [0, 0, 1]]),
                               atol=1e-12)
    np.testing.assert_allclose(poses["follower2"][:3, 3], (-0.25, 0, 0), atol=1e-12)


def test_floating_is_held_fixed_with_a_warning(arm: Kinematics) -> None:
    assert any("'float'" in w and "fixed" in w for w in arm.description.warnings)
    assert "float" in arm.fixed_joints
    np.testing.assert_allclose(arm.link_poses({"float": 5.0})["free"][:3, 3], (0, 0, 9))


def test_joint_lists_and_transforms(arm: Kinematics) -> None:
    assert set(arm.actuated_joints) == {"hinge", "rail", "wheel"}
    assert set(arm.moving_joints) == {"hinge", "rail", "wheel", "copy", "copy_of_copy"}
    assert set(arm.fixed_joints) == {"mount", "float"}
    static = arm.fixed_joint_transforms()
    np.testing.assert_allclose(static["mount"][:3, 3], (0.1, 0, 0))
    moving = arm.joint_transforms({"hinge": math.pi / 2}, ["hinge", "ghost"])
    assert list(moving) == ["hinge"]
    np.testing.assert_allclose(moving["hinge"][:3, 3], (1, 2, 3))


def test_unknown_names_are_ignored_and_bad_values_refused(arm: Kinematics) -> None:
    np.testing.assert_allclose(arm.link_poses({"not_a_joint": 1.0})["turn"][:3, 3], (1, 2, 3))
    with pytest.raises(RobotError, match="hinge"):
        arm.link_poses({"hinge": float("nan")})
    with pytest.raises(RobotError, match="hinge"):
        arm.link_poses({"hinge": "ninety"})  # type: ignore[dict-item]

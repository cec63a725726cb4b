"""The built-in demo arm: generated package, every visual loads, FK, determinism, motion."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from bridge.robots import MeshCache, load_robot_file, to_polydata
from bridge.robots.demo import DEMO_PACKAGE, demo_urdf_path
from bridge.robots.demo.joint_motion import JointMotion
from bridge.robots.demo.meshgen import FOREARM_RGBA, MESH_FILES


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    urdf, packages = demo_urdf_path(tmp_path_factory.mktemp("demo"))
    return urdf, packages, load_robot_file(urdf, package_paths=packages, cache=MeshCache())


def test_package_layout_and_paths(demo) -> None:
    urdf, packages, _ = demo
    assert list(packages) == [DEMO_PACKAGE]
    root = packages[DEMO_PACKAGE]
    assert urdf == root / "urdf" / "demo_arm.urdf"
    assert (root / "package.xml").is_file()
    assert sorted(p.name for p in (root / "meshes").iterdir()) == sorted(MESH_FILES)


def test_every_visual_loads_without_warnings(demo) -> None:
    _, _, model = demo
    assert model.warnings == ()
    assert len(model.links) == 11
    assert {v.link for v in model.visuals} == set(model.links)
    assert len(model.visuals) == 14  # base, wrist 3 and the flange have two each
    kinds = {v.link: v.source.split()[0] for v in model.visuals}
    assert kinds["shoulder_link"].endswith("shoulder.stl")
    assert kinds["upper_arm_link"].endswith("upper_arm.obj")
    assert kinds["forearm_link"].endswith("forearm.dae")
    forearm = model.visuals_of("forearm_link")[0]
    assert forearm.colour_source == "mesh"
    assert forearm.rgba == pytest.approx(FOREARM_RGBA, abs=1 / 255)
    # The DAE is in centimetres and the OBJ in millimetres (scale 0.001): both come out in mm.
    np.testing.assert_allclose(np.ptp(forearm.vertices, axis=0)[2], 300, atol=1e-3)
    upper = model.visuals_of("upper_arm_link")[0]
    np.testing.assert_allclose(np.ptp(upper.vertices, axis=0), (90, 90, 390), atol=0.5)
    for v in model.visuals:
        to_polydata(v).pack()


def test_forward_kinematics_of_the_demo(demo) -> None:
    _, _, model = demo
    straight = model.link_poses({})
    # Joint origins along z: 0.06 + 0.10 + 0.30 + 0.03 + 0.30 + 0.035 + 0.06 + 0.02.
    assert straight["tool_flange"][:3, 3] == pytest.approx((0, 0, 0.905))
    bent = model.link_poses({"joint_2": math.pi / 2})
    # Shoulder pitch of 90 degrees about y lays the arm along +x from the shoulder axis.
    assert bent["tool_flange"][:3, 3] == pytest.approx((0.905 - 0.16, 0, 0.16), abs=1e-12)
    fingers = model.link_poses({"finger_left_joint": 0.02})
    assert fingers["finger_left"][1, 3] - fingers["finger_right"][1, 3] == pytest.approx(0.044)


def test_generated_meshes_are_deterministic(tmp_path: Path) -> None:
    a_urdf, a_packages = demo_urdf_path(tmp_path / "a")
    b_urdf, b_packages = demo_urdf_path(tmp_path / "b")
    a_root, b_root = a_packages[DEMO_PACKAGE], b_packages[DEMO_PACKAGE]
    for name in MESH_FILES:
        assert (a_root / "meshes" / name).read_bytes() == (b_root / "meshes" / name).read_bytes()
    assert a_urdf.read_bytes() == b_urdf.read_bytes()
    # Second call: the existing folder is reused, nothing rewritten.
    before = (a_root / "meshes" / "forearm.dae").stat().st_mtime_ns
    assert demo_urdf_path(tmp_path / "a") == (a_urdf, a_packages)
    assert (a_root / "meshes" / "forearm.dae").stat().st_mtime_ns == before


def test_joint_motion_stays_within_limits(demo) -> None:
    _, _, model = demo
    motion = JointMotion(model.description)
    assert set(motion.joint_names) == set(model.kinematics.actuated_joints)
    assert "finger_right_joint" not in motion.joint_names  # a mimic: the publisher's job
    samples = [motion.positions_at(t) for t in np.linspace(0, 60, 601)]
    for name in motion.joint_names:
        limits = model.description.joints[name].limits
        values = [s[name] for s in samples]
        assert limits.lower <= min(values) and max(values) <= limits.upper, name
        assert max(values) - min(values) > 0.5 * (limits.upper - limits.lower), name


@pytest.mark.ros
def test_joint_motion_node_publishes_joint_states(processes, demo) -> None:
    urdf, _, model = demo
    echo = processes.python("echo", "echo_subscriber.py", "/joint_states",
                            "sensor_msgs/msg/JointState", "--count", "3")
    echo.wait_for_output("READY", timeout=30)
    node = processes.start("joint_motion", [sys.executable, "-u", "-m",
                                            "bridge.robots.demo.joint_motion", str(urdf)])
    node.wait_for_output("joint motion ready", timeout=30)
    for _ in range(3):
        msg = json.loads(echo.wait_for_output("MSG ", timeout=30).split("MSG ", 1)[1])
        assert set(msg["name"]) == set(model.kinematics.actuated_joints)
        for name, q in zip(msg["name"], msg["position"]):
            limits = model.description.joints[name].limits
            assert limits.lower <= q <= limits.upper
    assert node.stop() == 0
    assert "Traceback" not in node.output()

"""robot.solve_ik through a real `slicer-ros2-bridge demo` over real TCP (issue 46): the
target is the tool flange's pose (mm) at joint positions chosen here, computed by
yourdfpy's FK, not the daemon's; the solution is checked by the same independent FK. The
solve starts from the demo's live /joint_states, and the arm does not move for it."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Iterator

import numpy as np
import pytest

import slicer_client
from bridge.robots.demo import demo_urdf_path
from protocol.conversions import rotation_to_quaternion
from support import Processes, RunningDaemon, spare_domain, wait_until

pytestmark = pytest.mark.ros
pytest.importorskip("pinocchio", reason="motion needs pin (pyproject's dependencies)")
yourdfpy = pytest.importorskip("yourdfpy")

TIP = "tool_flange"
GOAL = {"joint_1": 0.4, "joint_2": -0.6, "joint_3": 1.1, "joint_4": -0.3, "joint_5": 0.8,
        "joint_6": 0.2}


@pytest.fixture(scope="module")
def demo(module_processes: Processes) -> Iterator[RunningDaemon]:
    """`slicer-ros2-bridge demo` on a ROS domain of its own, once it says it is up."""
    child = module_processes.bridge("demo", "--port", "0",
                                    env={"ROS_DOMAIN_ID": spare_domain(1)})
    line = child.wait_for_output(" (OpenIGTLink); ROS node", timeout=60)
    port = int(line.split(" (OpenIGTLink)")[0].rsplit(":", 1)[1])
    child.wait_for_output("Stop with Ctrl-C", timeout=90)
    yield RunningDaemon(child, port)
    child.stop()


@pytest.fixture(scope="module")
def fk(tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    urdf, _ = demo_urdf_path(tmp_path_factory.mktemp("demo_fk"))
    model = yourdfpy.URDF.load(str(urdf), load_meshes=False, load_collision_meshes=False,
                               build_collision_scene_graph=False)

    def pose_mm(positions: dict[str, float]) -> np.ndarray:
        model.update_cfg(dict(positions))
        matrix = np.array(model.get_transform(frame_to=TIP, frame_from="base_link"))
        matrix[:3, 3] *= 1000.0
        return matrix
    return pose_mm


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(a.T @ b) - 1.0) / 2.0))))


def test_solve_ik_from_the_client_reaches_the_target(demo: RunningDaemon, fk,  # type: ignore[no-untyped-def]
                                                     tmp_path: Path) -> None:
    ros = slicer_client.connect("127.0.0.1", demo.port, reconnect=False)
    try:
        robot = ros.robot("demo")
        wait_until(lambda: robot.joints() is not None, timeout=30, what="the demo robot")
        target = fk(GOAL)
        positions = robot.solve_ik(target, tip=TIP)
        reached = fk(positions)
        assert np.linalg.norm(reached[:3, 3] - target[:3, 3]) <= 0.1  # mm
        assert _angle_deg(reached[:3, :3], target[:3, :3]) <= 0.1
        joints = {j["name"]: j for j in robot.joints()["joints"]}
        for name, value in positions.items():
            limits = joints[name]
            assert limits["lower"] - 1e-9 <= value <= limits["upper"] + 1e-9, name
        # Later solves start from the arm's live joint state, which the daemon subscribed
        # to with the robot's first solve (until it arrives: from zero).
        answers = []

        def from_live_state() -> bool:
            answers.append(ros.command("solve_ik", {"name": "demo", "tip": TIP,
                                                    "target": target.tolist()}))
            return answers[-1]["seed"] == "joint_states"
        wait_until(from_live_state, timeout=30, what="a solve seeded from /joint_states")
        assert answers[-1]["solved"] is True
        assert answers[-1]["residual_mm"] < 0.1 and answers[-1]["residual_deg"] < 0.1

        # The same target as a pose: position (mm) and quaternion x, y, z, w.
        as_pose = robot.solve_ik((target[:3, 3], rotation_to_quaternion(target[:3, :3])),
                                 tip=TIP, seed=GOAL)
        # Seeded at the answer: the answer, and the gripper (not given) at 0.
        assert as_pose == pytest.approx({**GOAL, "finger_left_joint": 0.0}, abs=1e-6)

        # Unreachable: refused with the reason and the residual, nothing raised in the daemon.
        far = target.copy()
        far[:3, 3] = (3000.0, 0.0, 500.0)
        with pytest.raises(slicer_client.IkFailedError) as failed:
            robot.solve_ik(far, tip=TIP)
        assert failed.value.reason == "unreachable"
        assert failed.value.residual_mm > 1500.0

        # Bad input: typed refusals naming the field; the daemon keeps serving.
        with pytest.raises(slicer_client.CommandRefusedError) as caught:
            robot.solve_ik(target, tip="no_such_link")
        assert caught.value.field == "tip" and "a link of robot" in str(caught.value)
        sheared = target.tolist()
        sheared[0][1] = 0.5
        with pytest.raises(slicer_client.CommandRefusedError) as caught:
            ros.command("solve_ik", {"name": "demo", "tip": TIP, "target": sheared})
        assert caught.value.field.startswith("target")
        with pytest.raises(slicer_client.CommandRefusedError) as caught:
            ros.command("solve_ik", {"name": "nobody", "tip": TIP, "target": target.tolist()})
        assert caught.value.field == "name"
        again = robot.solve_ik(target, tip=TIP, seed=GOAL)
        assert {j: again[j] for j in GOAL} == pytest.approx(GOAL, abs=1e-6)
    finally:
        ros.close()
    output = demo.child.output()
    assert "Traceback" not in output, output[-4000:]

"""Motion on a real `slicer-ros2-bridge demo` over real TCP (issue 46).

robot.solve_ik: the target is the tool flange's pose (mm) at joint positions chosen here,
computed by yourdfpy's FK, not the daemon's; the solution is checked by the same
independent FK. The solve starts from the demo's live /joint_states.

Execute on the demo arm: with a Slicer model placed in the arm's way, executing to a goal
behind it is refused naming the link and the obstacle; with the model removed the arm
reaches the goal, checked by an rclpy subscriber in another process on /joint_states."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pytest

import slicer_client
from bridge.robots.demo import demo_urdf_path
from protocol.conversions import rotation_to_quaternion
from protocol.commands import ErrorCode
from support import Processes, RunningDaemon, scaled, spare_domain, wait_until

pytestmark = pytest.mark.ros
pytest.importorskip("pinocchio", reason="motion needs pin (pyproject's dependencies)")
yourdfpy = pytest.importorskip("yourdfpy")
trimesh = pytest.importorskip("trimesh")

TIP = "tool_flange"
GOAL = {"joint_1": 0.4, "joint_2": -0.6, "joint_3": 1.1, "joint_4": -0.3, "joint_5": 0.8,
        "joint_6": 0.2}


DOMAIN = spare_domain(1)


@pytest.fixture(scope="module")
def demo(module_processes: Processes) -> Iterator[RunningDaemon]:
    """`slicer-ros2-bridge demo` on a ROS domain of its own, once it says it is up."""
    child = module_processes.bridge("demo", "--port", "0", env={"ROS_DOMAIN_ID": DOMAIN})
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


def _states(echo: Any) -> list[dict[str, float]]:
    return [dict(zip(m["name"], m["position"])) for m in
            (json.loads(line[4:]) for line in echo.lines() if line.startswith("MSG "))]


def test_executing_through_a_model_is_refused_and_without_it_the_arm_gets_there(
        demo: RunningDaemon, fk, processes: Processes) -> None:  # type: ignore[no-untyped-def]
    echo = processes.python("echo_demo", "echo_subscriber.py", "/joint_states",
                            "sensor_msgs/msg/JointState", env={"ROS_DOMAIN_ID": DOMAIN})
    echo.wait_for_output("READY", timeout=30)
    ros = slicer_client.connect("127.0.0.1", demo.port, reconnect=False)
    try:
        robot = ros.robot("demo")
        robot.wait_until_loaded()
        reach = {"joint_2": 0.6, "joint_3": 0.6, "joint_4": 0.0, "joint_5": 0.5,
                 "joint_6": 0.0}  # the flange 0.59 m out: joint_1 sweeps it on an arc
        start = {**reach, "joint_1": -0.8}
        goal = {**reach, "joint_1": 0.8}
        # To the start, nothing in the way: the demo's controller then holds the arm there.
        first = robot.execute(start, duration_s=1.0)
        assert first.result(timeout=scaled(30))["error_code"] == 0
        wait_until(lambda: bool(_states(echo)) and _states(echo)[-1]["joint_1"] ==
                   pytest.approx(-0.8, abs=1e-6), timeout=30, what="the arm at the start")

        # A 6 cm block where the tool flange passes half-way (joint_1 = 0), from Slicer.
        middle = fk({**reach, "joint_1": 0.0})[:3, 3]
        block = trimesh.creation.box((60.0, 60.0, 60.0))
        robot.set_obstacle("block", "/demo/obstacles/block")
        model = ros.publish_model("/demo/obstacles/block",
                                  (block.vertices + middle, block.faces), frame="base_link",
                                  type="visualization_msgs/msg/Marker")
        plans: list[dict[str, Any]] = []

        def planned() -> bool:
            model.send_model((block.vertices + middle, block.faces))
            plans.append(robot.plan(goal))
            return not plans[-1]["clear"]
        wait_until(planned, timeout=30, what="the block in the plan")
        collision = plans[-1]["collision"]
        assert collision["obstacle"] == "block" and 0.2 < collision["fraction"] < 0.5
        seen = len(_states(echo))
        with pytest.raises(slicer_client.CommandRefusedError) as refused:
            robot.execute(goal)
        assert refused.value.code == ErrorCode.REJECTED
        assert f"link {collision['link']!r} touches obstacle 'block'" in str(refused.value)
        wait_until(lambda: len(_states(echo)) >= seen + 10, timeout=30,
                   what="ten more joint states")
        assert all(s["joint_1"] == pytest.approx(-0.8, abs=1e-6) for s in _states(echo)[seen:])

        # The model taken away: the arm reaches the goal.
        robot.remove_obstacle("block")
        assert robot.plan(goal)["clear"]
        handle = robot.execute(goal, duration_s=2.0)
        assert handle.result(timeout=scaled(30))["error_code"] == 0
        wait_until(lambda: _states(echo)[-1]["joint_1"] == pytest.approx(0.8, abs=1e-6),
                   timeout=30, what="the arm at the goal on /joint_states")
        reached = _states(echo)[-1]
        assert {j: reached[j] for j in goal} == pytest.approx(goal, abs=1e-6)
    finally:
        ros.close()

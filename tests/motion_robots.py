"""Robots and an obstacle for the motion tests through a daemon (issue 46)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np

from support import Child, Processes


RADIUS = 0.05  # the tool: a sphere 0.5 m from the swing axis
ARM_URDF = """<robot name="swing_arm">
  <link name="base"/><link name="arm"/>
  <link name="tool"><collision><geometry><sphere radius="0.05"/></geometry></collision></link>
  <joint name="swing" type="revolute"><parent link="base"/><child link="arm"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="mount" type="fixed"><parent link="arm"/><child link="tool"/>
    <origin xyz="0.5 0 0"/></joint>
</robot>"""
BARE_URDF = """<robot name="bare"><link name="base"/><link name="tip"/>
  <joint name="j" type="revolute"><parent link="base"/><child link="tip"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>"""


def box_mm() -> Any:
    """A 10 cm block (trimesh), in mm, centred on its frame."""
    import trimesh

    box = trimesh.creation.box((100.0, 100.0, 100.0))
    assert np.allclose(box.bounds, [[-50.0] * 3, [50.0] * 3])
    return box


SWING_ACTION = "/swing/follow_joint_trajectory"


def start_swing(processes: Processes, urdf: Path) -> tuple[Child, Child]:
    """The swing arm's controller (the demo's joint motion process serving
    FollowJointTrajectory on `SWING_ACTION`) and an rclpy subscriber of its joint states,
    both in processes of their own, once each is ready."""
    motion = processes.start("swing-motion", [
        sys.executable, "-u", "-m", "bridge.robots.demo.joint_motion", str(urdf),
        "--namespace", "swing", "--rate", "20", "--trajectory-action", SWING_ACTION,
        "--yield-s", "0"])
    motion.wait_for_output("joint motion ready", timeout=30)
    echo = processes.python("echo_swing", "echo_subscriber.py", "/swing/joint_states",
                            "sensor_msgs/msg/JointState")
    echo.wait_for_output("READY", timeout=30)
    return motion, echo

"""What the player's tests share: the no-ROS environment, the demo robot's bag, starting
a player, and forward kinematics computed independently (yourdfpy)."""

from __future__ import annotations

import re
import sys

import numpy as np
from typing import TYPE_CHECKING

from support import Child, Processes

if TYPE_CHECKING:  # rosbags: the test extra
    from bags import RobotBag

# Every ROS import fails in the player's process: rclpy, the rosidl runtime, and the
# message packages a ROS install has (the guard names each refused import on stderr).
NO_ROS_SITECUSTOMIZE = '''
import importlib.abc
import sys

ROS = ("rclpy", "rcl", "rosidl", "rmw", "ament", "launch", "tf2", "rosbag2", "rpyutils",
       "builtin_interfaces", "std_msgs", "sensor_msgs", "geometry_msgs",
       "visualization_msgs", "shape_msgs", "nav_msgs", "trajectory_msgs", "action_msgs",
       "unique_identifier_msgs", "lifecycle_msgs", "std_srvs", "example_interfaces",
       "control_msgs", "rosgraph_msgs", "service_msgs", "type_description_interfaces",
       "statistics_msgs", "diagnostic_msgs", "stereo_msgs", "actionlib_msgs")


class NoRos(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        top = name.split(".")[0]
        if top.startswith(ROS) or top.endswith(("_msgs", "_interfaces")):
            sys.stderr.write(f"NO-ROS GUARD: refused import of {name}\\n")
            raise ImportError(f"no ROS here: {name}")
        return None


sys.meta_path.insert(0, NoRos())
'''


def start_player(processes: Processes, env: dict[str, str], *args: str) -> tuple[Child, int]:
    child = processes.start("play", [sys.executable, "-u", "-m", "bridge.console", "play",
                                     *args, "--port", "0"], env=env)
    line = child.wait_for_output("listening on", timeout=60)
    match = re.search(r"listening on [\d.]+:(\d+)", line)
    assert match, line
    return child, int(match.group(1))


# ------------------------------------------------------------------ independent references


def expected_link_poses(bag: RobotBag, index: int) -> dict[str, np.ndarray]:
    """world <- link (mm) at state ``index``: yourdfpy's forward kinematics at the bag's
    joint values, after the bag's world -> base_link transform."""
    import yourdfpy

    robot = yourdfpy.URDF.load(_urdf_file(bag), load_meshes=False, build_scene_graph=True)
    robot.update_cfg(bag.joints[index])
    world = np.eye(4)
    world[:3, 3] = bag.base[index]
    out = {}
    for link in robot.link_map:
        pose = world @ robot.get_transform(link, robot.base_link)
        pose[:3, 3] *= 1000.0
        out[link] = pose
    return out


def _urdf_file(bag: RobotBag) -> str:
    path = bag.path.parent / "robot.urdf"
    path.write_text(bag.urdf)
    return str(path)



"""What the player's tests share: the no-ROS environment, the demo robot's bag, starting
a player, and forward kinematics computed independently (yourdfpy)."""

from __future__ import annotations

import json
import re
import socket
import sys
import threading
from typing import TYPE_CHECKING, Any, Optional

import numpy as np

from protocol.framing import Decoder, encode
from protocol.messages import Command, Message, Status, TrackingData
from support import Child, Processes, scaled

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


# ------------------------------------------------------------------ a raw reader


class RawReader:
    """OpenIGTLink over one socket with protocol/ alone: every message decoded, the newest
    per device kept (and per element of a TDATA, a robot's link poses, in `poses`),
    COMMANDs answered by their command id."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=30)
        self.sock.sendall(encode(Message("", Status(text="raw reader")), header_version=2))
        self.latest: dict[str, Message] = {}
        self.poses: dict[str, np.ndarray] = {}  # TDATA element name -> its newest matrix
        self.replies: dict[int, dict[str, Any]] = {}
        self.cond = threading.Condition()
        self._ids = iter(range(1, 1 << 30))
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        decoder = Decoder(max_body_size=1 << 28)
        try:
            while True:
                data = self.sock.recv(1 << 20)
                if not data:
                    return
                decoder.feed(data)
                while (message := decoder.next_message()) is not None:
                    with self.cond:
                        if message.type_name == "RTS_COMMAND":
                            self.replies[message.body.command_id] = json.loads(
                                message.body.text)
                        else:
                            self.latest[message.device_name] = message
                        if isinstance(message.body, TrackingData):
                            self.poses.update((e.name, e.matrix) for e in message.body.elements)
                        self.cond.notify_all()
        except OSError:
            return

    def command(self, op: str, arguments: Optional[dict[str, Any]] = None) -> dict[str, Any]:
        command_id = next(self._ids)
        self.sock.sendall(encode(Message("raw", Command(command_id=command_id, name=op,
                                                        text=json.dumps(arguments or {}))),
                                 header_version=2))
        with self.cond:
            assert self.cond.wait_for(lambda: command_id in self.replies, scaled(30)), op
            return self.replies.pop(command_id)

    def wait(self, predicate: Any, what: str, timeout: float = 30.0) -> None:
        with self.cond:
            assert self.cond.wait_for(lambda: predicate(self.latest), scaled(timeout)), what

    def close(self) -> None:
        self.sock.close()
        self._thread.join(5)

"""The Python robot state publisher as a real process, checked by independent rclpy peers."""

from __future__ import annotations

import json
import math
import signal
import sys
from pathlib import Path

import pytest

from bridge.robots.demo import demo_urdf_path
from bridge.robots.state_publisher import build_parser
from support import require_shared

pytestmark = pytest.mark.ros


def start_state_publisher(processes, *args: str):
    child = processes.start("state_publisher",
                            [sys.executable, "-u", "-m", "bridge.robots.state_publisher", *args])
    child.wait_for_output("ready", timeout=30)
    return child


def echo(processes, topic: str, msg_type: str, *flags: str):
    child = processes.python(f"echo{topic.replace('/', '_')}", "echo_subscriber.py", topic,
                             msg_type, *flags)
    child.wait_for_output("READY", timeout=30)
    return child


def message(child) -> dict:
    line = child.wait_for_output("MSG ", timeout=30)
    return json.loads(line.split("MSG ", 1)[1])


def by_child(msg: dict) -> dict[str, dict]:
    return {t["child_frame_id"]: t for t in msg["transforms"]}


def close(value: dict, expected: tuple[float, ...], keys: str) -> None:
    assert [value[k] for k in keys] == pytest.approx(list(expected), abs=1e-9)


def test_omni_tf_and_robot_description(processes) -> None:
    omni = require_shared("robots/sensable_omni_model")
    urdf = omni / "urdf" / "omni.urdf"
    rsp = start_state_publisher(processes, str(urdf))
    description = echo(processes, "/robot_description", "std_msgs/msg/String",
                       "--transient-local", "--count", "1")
    assert message(description)["data"] == urdf.read_text()
    static = echo(processes, "/tf_static", "tf2_msgs/msg/TFMessage", "--transient-local",
                  "--count", "1")
    assert message(static)["transforms"] == []  # the Omni has no fixed joint
    tf = echo(processes, "/tf", "tf2_msgs/msg/TFMessage", "--count", "1")
    processes.python("joints", "robot_joint_state_publisher.py", "--stamp", "1234", "5678",
                     "waist=0.5", "shoulder=0.2", "elbow=-0.3", "other_robot_joint=7")
    frames = by_child(message(tf))
    # Only the joints the message names; values in METRES and radians, from omni.urdf.
    assert set(frames) == {"torso", "upper_arm", "lower_arm"}
    torso = frames["torso"]
    assert torso["header"]["frame_id"] == "base"
    assert torso["header"]["stamp"] == {"sec": 1234, "nanosec": 5678}
    close(torso["transform"]["translation"], (0, 0, 0.09), "xyz")
    close(torso["transform"]["rotation"], (0, 0, math.sin(0.25), math.cos(0.25)), "xyzw")
    upper = frames["upper_arm"]["transform"]
    close(upper["translation"], (-0.0075, 0, 0.035), "xyz")
    close(upper["rotation"], (math.sin(0.1), 0, 0, math.cos(0.1)), "xyzw")
    # elbow: origin rpy (-1.5, 0, 0) then -0.3 about the same x axis: -1.8 about x in all.
    lower = frames["lower_arm"]["transform"]
    close(lower["translation"], (0.0075, 0.134, 0), "xyz")
    close(lower["rotation"], (math.sin(-0.9), 0, 0, math.cos(-0.9)), "xyzw")
    assert rsp.stop(signal.SIGTERM) == 0
    assert "Traceback" not in rsp.output()


def test_demo_with_namespace_prefix_static_and_mimic(processes, tmp_path: Path) -> None:
    urdf, packages = demo_urdf_path(tmp_path)
    rsp = start_state_publisher(processes, str(urdf), "--namespace", "demo", "--frame-prefix",
                                "arm1/", "--node-name", "arm_publisher",
                                "--package-path", f"unused_pkg={tmp_path}")
    assert "/demo/arm_publisher" in rsp.output()
    description = echo(processes, "/demo/robot_description", "std_msgs/msg/String",
                       "--transient-local", "--count", "1")
    assert "slicer_ros2_bridge_demo_arm" in message(description)["data"]
    static = echo(processes, "/tf_static", "tf2_msgs/msg/TFMessage", "--transient-local",
                  "--count", "1")
    frames = by_child(message(static))
    assert set(frames) == {"arm1/forearm_link", "arm1/tool_flange"}
    assert frames["arm1/forearm_link"]["header"]["frame_id"] == "arm1/elbow_link"
    close(frames["arm1/forearm_link"]["transform"]["translation"], (0, 0, 0.03), "xyz")
    close(frames["arm1/tool_flange"]["transform"]["translation"], (0, 0, 0.02), "xyz")
    tf = echo(processes, "/tf", "tf2_msgs/msg/TFMessage", "--count", "1")
    processes.python("joints", "robot_joint_state_publisher.py", "--topic", "/demo/joint_states",
                     "finger_left_joint=0.01", "joint_1=1.5707963267948966")
    frames = by_child(message(tf))
    assert set(frames) == {"arm1/shoulder_link", "arm1/finger_left", "arm1/finger_right"}
    close(frames["arm1/finger_left"]["transform"]["translation"], (0, 0.012, 0.028), "xyz")
    # The mimic finger follows along its own axis (0 -1 0).
    close(frames["arm1/finger_right"]["transform"]["translation"], (0, -0.012, 0.028), "xyz")
    half = math.sqrt(0.5)
    close(frames["arm1/shoulder_link"]["transform"]["rotation"], (0, 0, half, half), "xyzw")
    assert rsp.stop(signal.SIGINT) == 0
    assert "Traceback" not in rsp.output()


def test_bad_urdf_exits_2_with_the_reason(processes, tmp_path: Path) -> None:
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot name='r'><link name='a'/><link name='b'/></robot>")
    child = processes.start("state_publisher",
                            [sys.executable, "-u", "-m", "bridge.robots.state_publisher", str(bad)])
    assert child.popen.wait(30) == 2
    assert "exactly one root link" in child.output()
    assert "Traceback" not in child.output()


def test_command_line_options() -> None:
    args = build_parser().parse_args(["r.urdf", "--package-path", "a=/x", "--package-path",
                                      "b=/y", "--namespace", "ns", "--frame-prefix", "p/"])
    assert args.package_path == ["a=/x", "b=/y"]
    assert (args.namespace, args.frame_prefix, args.node_name) == ("ns", "p/",
                                                                   "robot_state_publisher")

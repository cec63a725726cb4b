"""The Python robot state publisher (`slicer-ros2-bridge state-publisher`) as a real process
fed what a ROS graph may send it: joint states with a NaN, with more names than positions,
naming no joint of the robot, with a zero stamp; a new robot_description that is not a
valid URDF (set through the daemon's parameter client); and a URDF file that is not UTF-8.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import pytest

from slicer_client.connection import Connection
from support import Child, Processes, scaled

pytestmark = pytest.mark.ros

URDF = """<?xml version="1.0"?>
<robot name="sp">
  <link name="base"/><link name="arm"/><link name="tip"/><link name="shadow"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="arm"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="tip_joint" type="fixed"><parent link="arm"/><child link="tip"/>
    <origin xyz="0 0 0.1"/></joint>
  <joint name="shadow_joint" type="continuous"><parent link="base"/><child link="shadow"/>
    <mimic joint="tip_joint"/></joint>
</robot>
"""


def state_publisher(processes: Processes, *args: str) -> Child:
    return processes.start("state_publisher", [sys.executable, "-u", "-m",
                                               "bridge.robots.state_publisher", *args])


def joints(processes: Processes, *args: str) -> Child:
    child = processes.python("joints", "robot_joint_state_publisher.py", "--topic",
                             "/spx/joint_states", *args)
    child.wait_for_output("READY", timeout=30)
    return child


def test_joint_states_it_ignores_and_a_zero_stamp(processes: Processes,
                                                  tmp_path: Path) -> None:
    urdf = tmp_path / "sp.urdf"
    urdf.write_text(URDF)
    publisher = state_publisher(processes, str(urdf), "--namespace", "spx",
                                "--frame-prefix", "spx/")
    publisher.wait_for_output("ready", timeout=30)
    # The URDF's warning is the node's first word.
    assert "mimics 'tip_joint', a fixed joint" in publisher.output()
    tf = processes.python("tf", "echo_subscriber.py", "/tf", "tf2_msgs/msg/TFMessage")
    tf.wait_for_output("READY", timeout=30)

    nan = joints(processes, "j1=nan")
    line = publisher.wait_for_output("non-finite position ignored", timeout=30)
    assert "joint 'j1'" in line
    nan.stop()
    lengths = processes.python("lengths", "publish_json.py", "/spx/joint_states",
                               "sensor_msgs/msg/JointState",
                               json.dumps({"name": ["j1", "j2"], "position": [0.1]}))
    lengths.wait_for_output("PUBLISHED 10", timeout=30)
    publisher.wait_for_output("joint state with 2 names and 1 positions ignored")
    lengths.stop()
    unknown = joints(processes, "ghost=1.0")
    assert "MSG " not in tf.output()  # nothing usable came: no /tf at all
    unknown.stop()
    # Each warning once, however many messages repeated it.
    output = publisher.output()
    assert output.count("non-finite position ignored") == 1
    assert output.count("names and 1 positions ignored") == 1

    joints(processes, "--stamp", "0", "0", "j1=0.5")
    message: dict[str, Any] = json.loads(tf.wait_for_output("MSG ", timeout=30)
                                         .split("MSG ", 1)[1])
    (arm,) = [t for t in message["transforms"] if t["child_frame_id"] == "spx/arm"]
    # A zero stamp is replaced by the node's clock.
    assert arm["header"]["stamp"]["sec"] > 0
    assert arm["header"]["frame_id"] == "spx/base"
    assert arm["transform"]["rotation"]["z"] == pytest.approx(0.24740395925452294)


def test_a_new_description_that_is_not_a_valid_urdf_is_refused(
        processes: Processes, client: Connection, tmp_path: Path) -> None:
    urdf = tmp_path / "sp.urdf"
    urdf.write_text(URDF)
    publisher = state_publisher(processes, str(urdf), "--namespace", "spy")
    publisher.wait_for_output("ready", timeout=30)
    node = "/spy/robot_state_publisher"
    client.command("create_parameter_client", {"node": node}, timeout=scaled(30))
    try:
        reply = client.command("set_parameters", {"node": node, "values": {
            "robot_description": {"type": "string",
                                  "value": "<robot name='x'><joint name='j'/></robot>"}}},
            timeout=scaled(30))
        result = reply["results"]["robot_description"]
        assert result["ok"] is False
        assert "robot 'x': expected at least one <link>, got none" in result["reason"]
        value = client.command("get_parameters", {"node": node,
                                                  "names": ["robot_description"]},
                               timeout=scaled(30))
        assert value["values"]["robot_description"]["value"] == URDF
    finally:
        client.command("remove_parameter_client", {"node": node})


def test_a_urdf_file_that_is_not_utf8_is_refused_before_ros_starts(
        processes: Processes, tmp_path: Path) -> None:
    urdf = tmp_path / "latin1.urdf"
    urdf.write_bytes("<robot name='caf\u00e9'><link name='a'/></robot>".encode("latin-1"))
    child = state_publisher(processes, str(urdf))
    assert child.popen.wait(scaled(30)) == 2
    output = child.output()
    assert f"state-publisher: {urdf}: expected a readable UTF-8 URDF file" in output
    assert "Traceback" not in output


@pytest.mark.parametrize("args, said", [
    (["--package-path", "nonsense", "robot.urdf"],
     "state-publisher: --package-path: expected NAME=DIR (a package name, '=', a folder), "
     "got nonsense"),
    (["package://no_such_pkg/urdf/robot.urdf", "--package-path", "other=/tmp"],
     "expected a known package, got no package 'no_such_pkg' in package paths other, "
     "ROS_PACKAGE_PATH"),
    (["package://just_a_package"],
     "state-publisher: package://just_a_package: expected package://PACKAGE/PATH"),
    ([" "], "state-publisher: filename: expected a mesh URI or path, got an empty string"),
], ids=["package-path", "unknown-package", "package-without-path", "blank"])
def test_a_urdf_it_cannot_find_is_refused_by_name(processes: Processes, args: list[str],
                                                  said: str) -> None:
    child = state_publisher(processes, *args)
    assert child.popen.wait(scaled(30)) == 2
    output = child.output()
    assert said in output and "Traceback" not in output, output[-2000:]

"""`--ros-args` on the real daemon, as `ros2 run slicer_ros2_bridge bridge --ros-args ...`
passes them: node name, namespace, a remapped topic, and parameters that set options."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from slicer_client.connection import Connection
from support import REPO, Processes, pick_free_port

pytestmark = pytest.mark.ros


def _start(processes: Processes, *args: str):
    child = processes.bridge("run", *args)
    child.wait_for_output("listening on", timeout=60)
    return child


def test_node_name_namespace_and_a_parameter_that_sets_the_port(processes: Processes) -> None:
    port = pick_free_port()
    daemon = _start(processes, "--ros-args", "-r", "__node:=lab_bridge", "-r", "__ns:=/lab",
                    "-p", f"port:={port}")
    assert f"listening on 127.0.0.1:{port}" in daemon.output()
    with Connection("127.0.0.1", port) as client:
        assert client.command("hello", timeout=30)["node"] == "/lab/lab_bridge"
    assert daemon.stop() == 0, daemon.output()[-2000:]


def test_the_command_line_wins_over_a_ros_parameter(processes: Processes) -> None:
    port, other = pick_free_port(), pick_free_port()
    daemon = _start(processes, "--port", str(port), "--ros-args", "-p", f"port:={other}")
    assert f"listening on 127.0.0.1:{port}" in daemon.output()
    assert daemon.stop() == 0


def test_a_remapped_topic_is_bridged_from_where_ros_puts_it(processes: Processes) -> None:
    port = pick_free_port()
    _start(processes, "--port", str(port), "--ros-args", "-r", "/ra_chatter:=/ra_remapped")
    processes.python("pub", "publish_json.py", "/ra_remapped", "std_msgs/msg/String",
                     json.dumps({"data": "through the remap"}))
    with Connection("127.0.0.1", port) as client:
        reply = client.command("create_subscriber", {"topic": "/ra_chatter", "type": "String"},
                               timeout=30)
        message = client.wait_for(reply["device"], timeout=30)
        assert message.body.text == "through the remap"


@pytest.mark.parametrize(("ros_args", "says"), [
    (["-p", "port:=not_a_port"], "-p port: expected a value --port takes, got 'not_a_port'"),
    (["-p", "read_only:=3"], "-p read_only: expected true or false, got 3"),
    (["-p", f"port:={pick_free_port()}", "--no-such-ros-flag"], "--no-such-ros-flag"),
])
@pytest.mark.integration
def test_bad_ros_args_are_one_line_and_exit_2(ros_args: list[str], says: str) -> None:
    # No --port here: it would win over -p port and hide the bad value.
    result = subprocess.run([sys.executable, "-m", "bridge.cli", "run", "--ros-args", *ros_args],
                            cwd=REPO, capture_output=True, text=True, timeout=120)
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and says in lines[0], result.stderr

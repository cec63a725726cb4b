"""Daemon paths no other test runs, driven as a user would: a served action whose client
takes too long (to end a goal, or to accept one) seen by a real rclpy ActionClient in
another process, and the daemon's options set from a ROS params file (`--ros-args
--params-file FILE`), seen over real TCP.
"""

from __future__ import annotations

import json
import re
import threading
from pathlib import Path
from typing import Any

import pytest

from protocol.commands import ErrorCode
from slicer_client.client import Client
from slicer_client.connection import CommandRefusedError
from support import Processes, RunningDaemon, assert_clean_exit, scaled, wait_until

pytestmark = pytest.mark.ros

GRIPPER = "control_msgs/action/GripperCommand"
DECISION_TIMEOUT_S = 10  # bridge.actions.served.DECISION_TIMEOUT_S, as the daemon logs it


def result_of(line: str) -> dict[str, Any]:
    return json.loads(line[line.index("RESULT ") + 7:])  # type: ignore[no-any-return]


# ---------------------------------------------------------------------------- served actions


def test_a_served_goal_its_client_does_not_end_in_time_is_aborted(
        ros: Client, daemon: RunningDaemon, processes: Processes) -> None:
    """goal_timeout passes with the client's execute still running: the daemon aborts the
    goal (the ROS client gets ABORTED), refuses the goal's later feedback, ignores the late
    answer, and the action goes on serving the next goals."""
    goal_timeout = scaled(1.0)
    release = threading.Event()
    started = threading.Event()
    late_feedback: list[BaseException] = []
    late_done = threading.Event()

    def execute(goal: dict[str, Any], feedback: Any, cancelled: Any) -> tuple[str, Any]:
        position = goal["command"]["position"]
        if position < 0.5:  # the slow goal: ends only when the test says
            started.set()
            release.wait(scaled(60))
            try:
                feedback({"position": position})
            except CommandRefusedError as error:
                late_feedback.append(error)
            finally:
                late_done.set()
            return "succeeded", {"position": position, "reached_goal": True}
        return "succeeded", {"position": position, "reached_goal": True}

    ros.serve_action("/slow_to_end", GRIPPER, execute, goal_timeout=goal_timeout)
    slow = processes.python("slow-caller", "gripper_action_client.py", "/slow_to_end", "0.3")
    try:
        assert started.wait(scaled(30))
        slow.wait_for_output("ACCEPTED", timeout=30)
        assert result_of(slow.wait_for_output("RESULT ", timeout=30)) == {
            "status": 6, "position": 0.0, "reached_goal": False}  # ABORTED, an empty Result
        line = daemon.child.wait_for_output("did not end a goal of /slow_to_end")
        assert line.endswith(f"did not end a goal of /slow_to_end within {goal_timeout:g} s; "
                             f"it is aborted")
    finally:
        release.set()
    assert late_done.wait(scaled(20))
    (error,) = late_feedback
    assert error.code == ErrorCode.NOT_FOUND and error.field == "goal_id"
    # The late answer ended nothing more; the next goal is served as usual.
    fast = processes.python("fast-caller", "gripper_action_client.py", "/slow_to_end", "0.7")
    assert result_of(fast.wait_for_output("RESULT ", timeout=30)) == {
        "status": 4, "position": 0.7, "reached_goal": True}  # SUCCEEDED
    (listed,) = [b for b in ros.list_bridges()["bridges"] if b.get("action") == "/slow_to_end"]
    assert listed["goals"] == 2
    assert "Traceback" not in daemon.child.output()


def test_a_goal_its_deciding_client_does_not_answer_in_time_is_rejected(
        ros: Client, daemon: RunningDaemon, processes: Processes) -> None:
    """accept() takes longer than the daemon's 10 s decision timeout: the ROS client gets
    REJECTED, the goal is never executed, the late verdict is ignored, and the next goal is
    decided and executed as usual."""
    release = threading.Event()
    asked: list[float] = []
    executed: list[float] = []
    verdict_sent = threading.Event()

    def accept(goal: dict[str, Any]) -> bool:
        position = goal["command"]["position"]
        asked.append(position)
        if position < 0.5:  # the undecided goal: answers (yes) only when the test says
            release.wait(scaled(60))
            verdict_sent.set()
        return True

    def execute(goal: dict[str, Any], feedback: Any, cancelled: Any) -> tuple[str, Any]:
        executed.append(goal["command"]["position"])
        return "succeeded", {"position": goal["command"]["position"], "reached_goal": True}

    ros.serve_action("/slow_to_decide", GRIPPER, execute, accept=accept)
    undecided = processes.python("undecided", "gripper_action_client.py", "/slow_to_decide",
                                 "0.3")
    try:
        line = daemon.child.wait_for_output("did not accept or reject a goal of /slow_to_decide",
                                            timeout=DECISION_TIMEOUT_S + 30)
        assert line.endswith(f"did not accept or reject a goal of /slow_to_decide within "
                             f"{DECISION_TIMEOUT_S} s; it is rejected")
        # The ROS client hears REJECTED, unless Fast DDS dropped the response (its reply
        # reader not matched yet on a loaded machine: see gripper_action_client.py); a
        # rejected goal is never on the status topic, so nothing else can tell it then.
        wait_until(lambda: {"REJECTED", "NO_RESPONSE"} & set(undecided.lines()),
                   timeout=60, what="the undecided goal's answer (or its loss)")
        assert "ACCEPTED" not in undecided.lines()
    finally:
        release.set()
    assert verdict_sent.wait(scaled(20))
    decided = processes.python("decided", "gripper_action_client.py", "/slow_to_decide", "0.8")
    decided.wait_for_output("ACCEPTED", timeout=30)
    assert result_of(decided.wait_for_output("RESULT ", timeout=30)) == {
        "status": 4, "position": 0.8, "reached_goal": True}
    assert asked == [0.3, 0.8] and executed == [0.8]
    assert "Traceback" not in daemon.child.output()


# ---------------------------------------------------------------------------- --params-file


def start_with(processes: Processes, *args: str) -> RunningDaemon:
    """A daemon whose port may come from its ROS parameters (start_daemon's --port 0 on the
    command line would win over them)."""
    child = processes.bridge("run", *args)
    line = child.wait_for_output(" (OpenIGTLink); ROS node", timeout=30)
    listening = re.search(r"listening on \S+:(\d+) \(OpenIGTLink\)", line)
    assert listening, line
    return RunningDaemon(child, int(listening.group(1)))


def refused(client: Any, op: str, args: dict[str, Any]) -> CommandRefusedError:
    with pytest.raises(CommandRefusedError) as info:
        client.command(op, args, timeout=scaled(10))
    return info.value


def test_options_from_a_params_file(processes: Processes, tmp_path: Path) -> None:
    """`/**` parameters set the daemon's options (port, node name, read-only, a repeatable
    glob list); a parameter that names no option (use_sim_time) is left to rcl."""
    params = tmp_path / "bridge.yaml"
    params.write_text("/**:\n"
                      "  ros__parameters:\n"
                      "    port: 0\n"
                      "    node_name: pf_bridge\n"
                      "    read_only: true\n"
                      "    allow_topic: [/pf_*, /other_ok]\n"
                      "    use_sim_time: false\n")
    daemon = start_with(processes, "--ros-args", "--params-file", str(params))
    assert daemon.port != 18944  # port 0: the kernel's choice, not the default
    with daemon.connect() as client:
        assert client.command("hello", timeout=scaled(10))["node"] == "/pf_bridge"
        error = refused(client, "create_publisher", {"topic": "/pf_out", "type": "String"})
        assert error.code == ErrorCode.FORBIDDEN and "read-only" in str(error)
        error = refused(client, "create_subscriber", {"topic": "/elsewhere", "type": "String"})
        assert error.code == ErrorCode.FORBIDDEN and error.field == "topic"
        for topic in ("/pf_in", "/other_ok"):
            assert client.command("create_subscriber", {"topic": topic, "type": "String"},
                                  timeout=scaled(10))["device"]
    assert_clean_exit(daemon)


def test_the_command_line_and_later_parameters_win_over_a_params_file(
        processes: Processes, tmp_path: Path) -> None:
    params = tmp_path / "bridge.yaml"
    params.write_text("/**:\n  ros__parameters:\n    port: 0\n    node_name: from_file\n"
                      "    read_only: true\n")
    # --node-name on the command line wins; -p after the file wins over it, as in rcl.
    daemon = start_with(processes, "--node-name", "from_cli", "--ros-args",
                        "--params-file", str(params), "-p", "read_only:=false")
    with daemon.connect() as client:
        assert client.command("hello", timeout=scaled(10))["node"] == "/from_cli"
        assert client.command("create_publisher", {"topic": "/pf_written", "type": "String"},
                              timeout=scaled(10))["device"]
    assert_clean_exit(daemon)


def test_a_params_file_section_applies_only_to_the_nodes_it_names(
        processes: Processes, tmp_path: Path) -> None:
    """One params file for a whole launch: the daemon takes its own node's section (by name,
    by namespace and name, or nested) and `/**`, never another node's (robot_state_publisher
    has a frame_prefix too, and any node may have a `port` or `read_only`)."""
    params = tmp_path / "launch.yaml"
    params.write_text("/**:\n"
                      "  ros__parameters:\n"
                      "    port: 0\n"
                      "robot_state_publisher:\n"
                      "  ros__parameters:\n"
                      "    frame_prefix: PSM1/\n"
                      "    read_only: true\n"
                      "/lab:\n"
                      "  lab_bridge:\n"
                      "    ros__parameters:\n"
                      "      allow_topic: [/lab_*]\n"
                      "/elsewhere/lab_bridge:\n"
                      "  ros__parameters:\n"
                      "    max_clients: 1\n")
    daemon = start_with(processes, "--node-name", "lab_bridge", "--namespace", "/lab",
                        "--ros-args", "--params-file", str(params))
    with daemon.connect() as client, daemon.connect() as second:
        assert client.command("hello", timeout=scaled(10))["node"] == "/lab/lab_bridge"
        # Not read-only, and no max_clients 1: robot_state_publisher's and /elsewhere's.
        assert second.command("create_publisher", {"topic": "/lab_out", "type": "String"},
                              timeout=scaled(10))["device"]
        # Its own nested section applies.
        error = refused(client, "create_subscriber", {"topic": "/other", "type": "String"})
        assert error.code == ErrorCode.FORBIDDEN and error.field == "topic"
        # No frame prefix: a tf lookup's relative frame stays as it is.
        reply = client.command("create_tf_lookup", {"parent": "world", "child": "tool"},
                               timeout=scaled(10))
        assert (reply["parent"], reply["child"]) == ("world", "tool")
    assert_clean_exit(daemon)


@pytest.mark.integration
def test_an_unreadable_params_file_or_value_is_one_line_and_exit_2(tmp_path: Path) -> None:
    import subprocess
    import sys

    from support import REPO

    bad = tmp_path / "bad.yaml"
    bad.write_text("/**: [unclosed\n")
    cases = [(["--params-file", str(tmp_path / "absent.yaml")],
              "--params-file: expected a readable YAML file, got "
              f"{tmp_path / 'absent.yaml'} ([Errno 2] No such file or directory"),
             (["--params-file", str(bad)],
              f"--params-file: expected a readable YAML file, got {bad} (while parsing a flow "
              "sequence in \"<unicode string>\", line 1, column 6"),
             (["-p", "port:=[1"], "-p port: expected a YAML value, got '[1' (while parsing")]
    for ros_args, says in cases:
        result = subprocess.run([sys.executable, "-m", "bridge.cli", "run", "--ros-args",
                                 *ros_args],
                                cwd=REPO, capture_output=True, text=True, timeout=120)
        assert result.returncode == 2, result.stderr
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(
            f"slicer-ros2-bridge: --ros-args: {says}"), result.stderr

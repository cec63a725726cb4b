"""Robots whose description comes from a latched topic or a parameter of a real rclpy node
in another process, as it changes: the same text again (nothing reloads), a malformed one
(the robot stays as it was and its STATUS says why), one whose root frame the daemon's frame
policy denies, then a good new one (reloaded). Also: a parameter that is not a string or
not set, joints published on the topic a client picks, and the joint_states topic of a
robot read from a topic.
"""

from __future__ import annotations

import json
from typing import Any, Iterator

import pytest

from protocol.commands import ErrorCode
from protocol.messages import Status, StatusCode
from slicer_client.connection import CommandRefusedError, Connection
from support import Child, Processes, RunningDaemon, assert_clean_exit, start_daemon, wait_until

pytestmark = pytest.mark.ros

LOAD_TIMEOUT = 30.0


def urdf(root: str = "base", *, tool: bool = False, broken: bool = False) -> str:
    extra = ('<link name="tool"><visual><geometry><sphere radius="0.01"/></geometry></visual>'
             '</link><joint name="tool_joint" type="fixed"><parent link="arm"/>'
             '<child link="tool"/></joint>') if tool else ""
    child = "nowhere" if broken else "arm"
    return (f'<robot name="topical"><link name="{root}"><visual><geometry><box size="0.1 0.1 '
            f'0.1"/></geometry></visual></link><link name="arm"/>'
            f'<joint name="j1" type="revolute"><parent link="{root}"/><child link="{child}"/>'
            f'<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/>'
            f'</joint>{extra}</robot>')


@pytest.fixture(scope="module")
def daemon(module_processes: Processes) -> Iterator[RunningDaemon]:
    running = start_daemon(module_processes, "--deny-frame", "secret_*")
    yield running
    assert_clean_exit(running)


def publish(processes: Processes, topic: str, text: str) -> Child:
    child = processes.python("description", "publish_json.py", topic, "std_msgs/msg/String",
                             json.dumps({"data": text}), "--transient-local")
    child.wait_for_output("PUBLISHED 1")
    return child


def summary(client: Connection, name: str) -> dict[str, Any]:
    (found,) = [r for r in client.command("list_robots")["robots"] if r["name"] == name]
    return found


def status_saying(client: Connection, device: str, code: int, text: str) -> Status:
    message = client.wait_for(device, lambda m: isinstance(m.body, Status)
                              and m.body.code == code and text in m.body.text,
                              timeout=LOAD_TIMEOUT)
    assert isinstance(message.body, Status)
    return message.body


def test_a_topic_description_that_changes(processes: Processes, client: Connection) -> None:
    topic = "/rtopic/robot_description"
    first = publish(processes, topic, urdf())
    created = client.command("create_robot", {"name": "rt", "source": {
        "kind": "topic", "topic": topic}}, timeout=LOAD_TIMEOUT)
    try:
        if created["state"] == "waiting":  # the publisher was not discovered in 2 s
            wait_until(lambda: summary(client, "rt")["state"] == "loaded", LOAD_TIMEOUT,
                       "rt to load")
        # The publisher repeats the same text 20 times a second: it loads once.
        first.wait_for_output("PUBLISHED 40")
        assert summary(client, "rt")["loads"] == 1
        joints = client.command("describe_robot_joints", {"name": "rt"})
        assert joints["joint_states_topic"] == "/rtopic/joint_states"
        assert [j["name"] for j in joints["joints"]] == ["j1"]
        # Joints on a topic the client picks, then another: one publisher at a time.
        for topic_name, angle in (("/rtopic/joints_a", 0.5), ("/rtopic/joints_b", -0.25)):
            reply = client.command("set_robot_joints", {"name": "rt", "topic": topic_name,
                                                        "positions": {"j1": angle}})
            assert reply["topic"] == topic_name and reply["positions"] == {"j1": angle}
        with pytest.raises(CommandRefusedError) as out_of_range:
            client.command("set_robot_joints", {"name": "rt", "positions": {"j1": 2.0}})
        assert out_of_range.value.field.startswith("positions")
        first.stop()
        # A malformed description: the robot stays loaded as it was, its STATUS says why.
        broken = publish(processes, topic, urdf(broken=True))
        status = status_saying(client, "urdf:rt", StatusCode.CONFIG_ERROR, "nowhere")
        assert status.text.startswith("description not loaded: source.topic: expected a "
                                      "valid URDF (topic /rtopic/robot_description)")
        state = summary(client, "rt")
        assert state["state"] == "loaded" and state["loads"] == 1 and state["links"] == 2
        assert "nowhere" in state["reason"]
        broken.stop()
        # A root frame the daemon's policy denies: refused on reload, the robot stays.
        secret = publish(processes, topic, urdf(root="secret_base"))
        status = status_saying(client, "urdf:rt", StatusCode.CONFIG_ERROR, "secret_base")
        assert "fixed_frame" in status.text
        assert summary(client, "rt")["fixed_frame"] == "base"
        secret.stop()
        # A good new description reloads it: the tool link appears.
        publish(processes, topic, urdf(tool=True))
        wait_until(lambda: summary(client, "rt")["loads"] == 2, LOAD_TIMEOUT, "the reload")
        state = summary(client, "rt")
        assert state["links"] == 3 and state["state"] == "loaded" and "reason" not in state
        status_saying(client, "urdf:rt", StatusCode.OK, "3 links")
    finally:
        client.command("remove_robot", {"name": "rt"})


def test_a_parameter_that_is_not_a_string_or_not_set(processes: Processes,
                                                     client: Connection) -> None:
    node = processes.python("params", "param_node.py", "robot_params")
    node.wait_for_output("READY")
    wait_until(lambda: "/robot_params/get_parameters" in {
        s["service"] for s in client.command("list_services")["services"]}, LOAD_TIMEOUT,
        "the node's parameter services")
    with pytest.raises(CommandRefusedError) as refused:
        client.command("create_robot", {"name": "counted", "source": {
            "kind": "parameter", "node": "/robot_params", "parameter": "count"}},
            timeout=LOAD_TIMEOUT)
    error = refused.value
    assert error.code == ErrorCode.WRONG_TYPE and error.field == "source.parameter"
    assert "a string parameter holding URDF XML (count of /robot_params)" in str(error)
    assert "got a integer parameter" in str(error)
    waiting = client.command("create_robot", {"name": "unset", "source": {
        "kind": "parameter", "node": "/robot_params", "parameter": "no_such_description"}},
        timeout=LOAD_TIMEOUT)
    try:
        assert waiting["state"] == "waiting"
        assert "no_such_description of /robot_params" in waiting["reason"]
    finally:
        client.command("remove_robot", {"name": "unset"})


def test_a_parameter_description_that_changes_to_a_malformed_one(
        processes: Processes, client: Connection) -> None:
    node = processes.python("params", "param_node.py", "robot_params_too", "--description",
                            urdf())
    node.wait_for_output("READY")
    source = {"kind": "parameter", "node": "/robot_params_too",
              "parameter": "robot_description"}
    created = client.command("create_robot", {"name": "rp", "source": source},
                             timeout=LOAD_TIMEOUT)
    client.command("create_parameter_client", {"node": "/robot_params_too"},
                   timeout=LOAD_TIMEOUT)
    try:
        if created["state"] == "waiting":
            wait_until(lambda: summary(client, "rp")["state"] == "loaded", LOAD_TIMEOUT,
                       "rp to load")
        reply = client.command("set_parameters", {"node": "/robot_params_too", "values": {
            "robot_description": {"type": "string", "value": urdf(broken=True)}}},
            timeout=LOAD_TIMEOUT)
        assert reply["results"]["robot_description"]["ok"], reply  # the node takes any text
        node.wait_for_output("CHANGED")
        status = status_saying(client, "urdf:rp", StatusCode.CONFIG_ERROR, "nowhere")
        assert status.text.startswith(
            "description not loaded: source.parameter: expected a valid URDF (parameter "
            "robot_description of /robot_params_too)"), status.text
        state = summary(client, "rp")
        assert state["state"] == "loaded" and state["loads"] == 1 and state["links"] == 2
    finally:
        client.command("remove_robot", {"name": "rp"})
        client.command("remove_parameter_client", {"node": "/robot_params_too"})


def test_a_waiting_robot_whose_node_comes_with_a_parameter_of_another_type(
        processes: Processes, client: Connection) -> None:
    """Created before its node exists, the robot waits; the node then comes with the
    parameter as an integer: the robot is in error, saying so (STATUS and list_robots)."""
    waiting = client.command("create_robot", {"name": "rcount", "source": {
        "kind": "parameter", "node": "/robot_params_late", "parameter": "count"}},
        timeout=LOAD_TIMEOUT)
    try:
        assert waiting["state"] == "waiting" and "node not available yet" in waiting["reason"]
        processes.python("params", "param_node.py", "robot_params_late").wait_for_output(
            "READY")
        status = status_saying(client, "urdf:rcount", StatusCode.CONFIG_ERROR, "count")
        assert status.text == (
            "description not loaded: source.parameter: expected a string parameter holding "
            "URDF XML (count of /robot_params_late), got a integer parameter")
        state = summary(client, "rcount")
        assert state["state"] == "error" and state["loads"] == 0
        assert "got a integer parameter" in state["reason"]
    finally:
        client.command("remove_robot", {"name": "rcount"})

"""Races on a running daemon (issue 22, items 1 and 10): the start-up window, creates and
removes of one bridge at once, and type clashes that rcl reports untyped. Raw TCP clients
and a real daemon; every refusal is a typed error reply, never INTERNAL, and the daemon
lives on."""

from __future__ import annotations

import errno
import json
from pathlib import Path

from hardening_tools import RawClient, ask, command_bytes, reply_to, send_command
from protocol.commands import ErrorCode
from support import Processes, pick_free_port, start_daemon, wait_until

ABSENT_NODE = "/nobody_answers_here"


def _connect_once(port: int) -> RawClient | None:
    """A connection if the daemon accepts one now, None if it refuses it."""
    try:
        return RawClient(port)
    except OSError as error:
        if error.errno != errno.ECONNREFUSED:
            raise
        return None


def test_clients_reach_the_daemon_only_once_its_config_bridges_exist(
        processes: Processes, tmp_path: Path) -> None:
    """The issue's start-up window: a parameter client of an absent node holds start-up
    for its readiness wait (2 s). A client that connects as early as it can must find the
    operator's bridges made and owned by the operator: it cannot remove them, own them,
    or make start-up fail by taking their topic with another type."""
    config = tmp_path / "bridges.yaml"
    config.write_text(f"subscribers:\n  - {{topic: /op_pose, type: PoseStamped}}\n"
                      f"parameter_clients:\n  - {{node: {ABSENT_NODE}}}\n")
    port = pick_free_port()
    daemon = processes.bridge("run", "--port", str(port), "--config", str(config))
    early: list[RawClient] = []

    def accepted() -> bool:
        client = _connect_once(port)
        if client is not None:
            early.append(client)
        return client is not None or daemon.popen.poll() is not None

    # Poll the port from the daemon's first moment: the first connection it accepts.
    wait_until(accepted, timeout=30, what="the daemon accepting a connection")
    assert early, daemon.output()[-3000:]
    client = early[0]
    try:
        # Sent in one go, as fast as a client can: all of them after the config's bridges.
        send_command(client, "remove_parameter_client", {"node": ABSENT_NODE}, 1)
        send_command(client, "create_subscriber", {"topic": "/op_pose", "type": "String"}, 2)
        send_command(client, "create_subscriber", {"topic": "/op_pose",
                                                   "type": "PoseStamped"}, 3)
        send_command(client, "remove_subscriber", {"topic": "/op_pose"}, 4)
        replies = [reply_to(client, command_id) for command_id in (1, 2, 3, 4)]
        assert [r["ok"] for r in replies] == [False, False, True, False], replies
        assert (replies[0]["error"]["code"], replies[0]["error"]["field"]) == (
            ErrorCode.FORBIDDEN, "node")
        assert replies[1]["error"]["code"] == ErrorCode.ALREADY_EXISTS
        assert replies[2]["result"]["existed"] is True
        assert (replies[3]["error"]["code"], replies[3]["error"]["field"]) == (
            ErrorCode.FORBIDDEN, "topic")
        listed = ask(client, "list_bridges", {}, 5)["result"]["bridges"]
        kinds = {(b["kind"], b.get("topic") or b.get("node")) for b in listed}
        assert {("subscriber", "/op_pose"), ("parameter_client", ABSENT_NODE)} <= kinds
    finally:
        client.close()
    daemon.wait_for_output("listening on", timeout=5)
    assert daemon.popen.poll() is None, daemon.output()[-3000:]
    assert "failed unexpectedly" not in daemon.output()


def test_a_remove_racing_a_create_of_the_same_bridge_waits_for_it(
        processes: Processes) -> None:
    """create_parameter_client of an absent node waits up to 2 s for it; a remove of that
    client arriving meanwhile (the root of the start-up crash: InvalidHandle, INTERNAL)
    runs once the create is done. Two creates at once make one client. The requests go in
    one write, so the daemon reads them in this order."""
    daemon = start_daemon(processes)
    first, second = RawClient(daemon.port), RawClient(daemon.port)
    try:
        created = {"node": ABSENT_NODE}
        first.send(b"".join(command_bytes(op, json.dumps(created).encode(), i) for i, op in (
            (1, "create_parameter_client"), (2, "remove_parameter_client"),
            (3, "create_parameter_client"))))
        send_command(second, "create_parameter_client", created, 4)
        made, removed, again = (reply_to(first, i, timeout=20) for i in (1, 2, 3))
        assert made["ok"] and made["result"]["ready"] is False, made
        assert removed["ok"] and removed["result"]["node"] == ABSENT_NODE, removed
        other = reply_to(second, 4, timeout=20)
        assert again["ok"] and other["ok"], (again, other)
        # One of them made it, the other found it.
        assert sorted([again["result"]["existed"], other["result"]["existed"]]) == [False,
                                                                                   True]
        listed = ask(first, "list_bridges", {}, 5)["result"]["bridges"]
        assert [b["node"] for b in listed if b["kind"] == "parameter_client"] == [ABSENT_NODE]
    finally:
        first.close()
        second.close()
    assert "failed unexpectedly" not in daemon.child.output()
    assert daemon.child.popen.poll() is None


def test_a_robot_on_a_topic_bridged_as_another_type_is_a_typed_refusal(
        processes: Processes) -> None:
    """rcl refuses a second DDS topic of another type in one process as an untyped
    RCLError ("invalid allocator"); the daemon says which type the topic has."""
    daemon = start_daemon(processes)
    client = RawClient(daemon.port)
    try:
        assert ask(client, "create_subscriber", {"topic": "/described",
                                                 "type": "PoseStamped"}, 1)["ok"]
        reply = ask(client, "create_robot", {"name": "clash", "source": {
            "kind": "topic", "topic": "/described"}}, 2, timeout=20)
        assert not reply["ok"], reply
        error = reply["error"]
        assert (error["code"], error["field"]) == (ErrorCode.ALREADY_EXISTS, "source.topic")
        assert "geometry_msgs/msg/PoseStamped" in error["message"], error
        # Nothing of the robot is left: the name is free.
        listed = ask(client, "list_robots", {}, 3)["result"]["robots"]
        assert listed == []
    finally:
        client.close()
    assert "failed unexpectedly" not in daemon.child.output()

"""The security options on a running daemon: read-only, globs, networks, limits, config."""

from __future__ import annotations

import socket
from pathlib import Path
from typing import Iterator

import pytest

from hardening_tools import RawClient, read_until_closed, transform_bytes
from protocol.commands import ErrorCode
from protocol.messages import StatusCode
from slicer_client.connection import CommandRefusedError, Connection
from support import (Processes, RunningDaemon, assert_clean_exit, pick_free_port, scaled,
                     start_daemon, wait_until)

pytestmark = pytest.mark.ros


@pytest.fixture(scope="module")
def locked(module_processes: Processes) -> Iterator[RunningDaemon]:
    running = start_daemon(module_processes, "--read-only", "--deny-topic", "/secret*",
                           "--allow-parameter", "/slicer_bridge.ui_*",
                           "--max-clients", "3", "--max-bridges-per-client", "2")
    yield running
    assert_clean_exit(running)


def refusal(client: Connection, op: str, args: dict) -> CommandRefusedError:
    with pytest.raises(CommandRefusedError) as refused:
        client.command(op, args)
    return refused.value


def test_read_only_refuses_writes_with_forbidden_and_serves_reads(locked: RunningDaemon) -> None:
    with locked.connect() as client:
        error = refusal(client, "create_publisher", {"topic": "/arm/target",
                                                     "type": "PoseStamped"})
        assert error.code == ErrorCode.FORBIDDEN and error.field == "op"
        assert "read-only" in str(error)
        for op, args in (("publish", {"topic": "/x", "value": "hi"}),
                         ("call_service", {"service": "/arm/enable",
                                           "type": "std_srvs/srv/SetBool"}),
                         ("server_declare_parameter", {"name": "ui_x", "value": {
                             "type": "integer", "value": 1}}),
                         ("create_tf_broadcaster", {"parent": "a", "child": "b"})):
            assert refusal(client, op, args).code == ErrorCode.FORBIDDEN
        assert client.command("create_subscriber", {"topic": "/open_topic",
                                                    "type": "String"})["device"]
        assert client.command("hello")["ops"]


def test_data_messages_are_refused_with_access_denied(locked: RunningDaemon) -> None:
    raw = RawClient(locked.port)
    try:
        raw.send(transform_bytes([1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0], "target"))
        status = raw.read_until(lambda m: m.type_name == "STATUS" and m.device_name == "target")
        assert status.body.code == StatusCode.ACCESS_DENIED and "read-only" in status.body.text
    finally:
        raw.close()


def test_topic_and_parameter_globs(locked: RunningDaemon) -> None:
    with locked.connect() as client:
        error = refusal(client, "create_subscriber", {"topic": "/secret/plans",
                                                      "type": "String"})
        assert error.code == ErrorCode.FORBIDDEN and error.field == "topic"
        assert "/secret*" in str(error)
        # A relative name is judged once resolved: no way around the glob.
        assert refusal(client, "create_subscriber", {"topic": "secret_x",
                                                     "type": "String"}).field == "topic"
        error = refusal(client, "get_parameters", {"node": "/robot", "names": ["speed"]})
        assert error.code == ErrorCode.FORBIDDEN and error.field == "names"
        assert "/robot.speed" in str(error)
        assert client.command("server_get_parameters", {"names": ["ui_colour"]}) is not None


def test_max_bridges_per_client_names_the_limit(locked: RunningDaemon) -> None:
    with locked.connect() as first, locked.connect() as second:
        first.command("create_tf_lookup", {"parent": "w", "child": "q1"})
        # Asking again for an existing bridge costs nothing.
        assert first.command("create_tf_lookup", {"parent": "w", "child": "q1"})["existed"]
        first.command("create_tf_lookup", {"parent": "w", "child": "q2"})
        error = refusal(first, "create_tf_lookup", {"parent": "w", "child": "q3"})
        assert error.code == ErrorCode.LIMIT_REACHED
        assert "at most 2 bridges per client" in str(error)
        second.command("create_tf_lookup", {"parent": "w", "child": "q3"})  # its own count
        # A --read-only daemon's clients remove nothing, so no slot comes free that way.
        error = refusal(first, "remove_tf_lookup", {"parent": "w", "child": "q1"})
        assert error.code == ErrorCode.FORBIDDEN and "read-only" in str(error)
        assert refusal(first, "create_tf_lookup", {"parent": "w", "child": "q4"}).code == \
            ErrorCode.LIMIT_REACHED


def test_max_clients_extra_client_gets_a_status_and_is_closed(locked: RunningDaemon) -> None:
    clients = [locked.connect() for _ in range(3)]
    try:
        with socket.create_connection(("127.0.0.1", locked.port)) as extra:
            said = read_until_closed(extra)
        assert [m.type_name for m in said] == ["STATUS"]
        assert said[0].body.code == StatusCode.RESOURCE_ERROR
        assert "at most 3" in said[0].body.text and "--max-clients" in said[0].body.text
        assert clients[0].command("hello")["ops"]
        clients.pop().close()
        # A slot is free again once the daemon has seen the close.
        from support import wait_until

        def admitted() -> bool:
            try:
                with Connection("127.0.0.1", locked.port) as again:
                    return bool(again.command("hello", timeout=2)["ops"])
            except Exception:
                return False
        wait_until(admitted, timeout=10, what="a fourth client admitted after one left")
    finally:
        for client in clients:
            client.close()
    assert "refused client 127.0.0.1" in locked.child.output()


def test_clients_outside_allow_are_told_why_and_closed_at_once(processes: Processes) -> None:
    daemon = start_daemon(processes, "--allow", "10.0.0.0/8", "--allow", "fd00::/8")
    with socket.create_connection(("127.0.0.1", daemon.port)) as refused:
        said = read_until_closed(refused)  # one STATUS: the address is all it reveals
    assert [m.type_name for m in said] == ["STATUS"]
    assert said[0].body.code == StatusCode.ACCESS_DENIED
    # Its own address only: a refused peer learns nothing of the allow list (issue 43).
    assert said[0].body.text == ("client address: expected an allowed one (--allow), got "
                                 "127.0.0.1; closing")
    assert "10.0.0.0" not in said[0].body.text and "fd00" not in said[0].body.text
    line = daemon.child.wait_for_output("refused client 127.0.0.1")
    assert "not in the allowed networks (--allow)" in line
    assert_clean_exit(daemon)


def test_allow_admits_loopback_when_listed(processes: Processes) -> None:
    daemon = start_daemon(processes, "--allow", "127.0.0.0/8")
    with daemon.connect() as client:
        assert client.command("hello")["ops"]
    assert_clean_exit(daemon)


@pytest.mark.parametrize("config,message", [
    ("security: {read_only: true}\npublishers:\n  - {topic: /target, type: PoseStamped}\n",
     "publishers[0]: op: expected an op that only receives"),
    ("security: {deny_topics: ['/cmd_*']}\nsubscribers:\n  - {topic: /cmd_vel, "
     "type: geometry_msgs/msg/Twist}\n", "subscribers[0]: topic: expected a topic this"),
    ("security: {max_clients: -1}\n", "max_clients: expected a positive integer"),
])
def test_start_up_bridges_and_settings_are_checked(processes: Processes, tmp_path: Path,
                                                   config: str, message: str) -> None:
    path = tmp_path / "bridge.yaml"
    path.write_text(config)
    child = processes.bridge("run", "--port", str(pick_free_port()), "--config", str(path))
    assert child.popen.wait(60) == 2, child.output()
    assert message in child.output(), child.output()


def test_a_bad_option_is_a_clear_error(processes: Processes) -> None:
    child = processes.bridge("run", "--port", str(pick_free_port()), "--allow", "10.0.0.0/33")
    assert child.popen.wait(60) == 2
    assert "expected an IPv4 or IPv6 address or CIDR block" in child.output()


def test_reconnecting_does_not_multiply_the_bridges(processes: Processes) -> None:
    daemon = start_daemon(processes, "--max-bridges-per-client", "3", "--max-bridges", "5")
    made = 0
    for _ in range(2):  # a client that makes its fill, keeps it, leaves, and comes back
        with daemon.connect() as client:
            for _ in range(3):
                if made == 5:
                    break
                client.command("create_tf_lookup", {"parent": "w", "child": f"r{made}"})
                client.command("keep_bridge", {"kind": "tf_lookup", "parent": "w",
                                               "child": f"r{made}"})
                made += 1
    with daemon.connect() as client:
        # Kept bridges outlive their client: the daemon-wide count holds after reconnects.
        error = refusal(client, "create_tf_lookup", {"parent": "w", "child": "r5"})
        assert error.code == ErrorCode.LIMIT_REACHED
        assert "at most 5 bridges made by clients, all together (--max-bridges" in str(error)
        # Any client may remove a client's bridge, and that frees the daemon-wide slot.
        client.command("remove_tf_lookup", {"parent": "w", "child": "r0"})
        client.command("create_tf_lookup", {"parent": "w", "child": "r5"})
        listed = [b for b in client.command("list_bridges")["bridges"]
                  if b.get("kind") == "tf_lookup"]
        assert len(listed) == 5
    # One not kept ends with its client, and its slot with it.
    with daemon.connect() as client:
        client.command("remove_tf_lookup", {"parent": "w", "child": "r1"})
        client.command("create_tf_lookup", {"parent": "w", "child": "r6"})
    with daemon.connect() as client:
        wait_until(lambda: not any(b.get("child") == "r6" for b in
                                   client.command("list_bridges")["bridges"]),
                   timeout=scaled(10), what="the bridge not kept to end")
        client.command("create_tf_lookup", {"parent": "w", "child": "r7"})
    assert_clean_exit(daemon)

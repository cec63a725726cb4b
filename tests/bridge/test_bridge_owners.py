"""Who owns a bridge and when it ends (issue 43, item 7; docs/security.md, "Who owns a
bridge"), with the real daemon, real TCP and rclpy publishers in processes of their own.

What the issue saw: a script's bridges outlived it, so a wrong type stuck and every later
client, a plain OpenIGTLink one (3D Slicer's connector) too, got every leftover stream. Now
a script's bridges end with it unless it keeps them; the operator's stay; a bridge two
clients asked for lives while either does; a reconnecting client ends with its bridges.
"""

from __future__ import annotations

import socket
from pathlib import Path
from typing import Any, Iterator

import pytest

import slicer_client
from protocol.commands import ErrorCode
from protocol.framing import Decoder
from slicer_client.client import Client
from slicer_client.transport import open_transport
from support import (Processes, RunningDaemon, assert_clean_exit, operator_daemon, refused,
                     scaled, start_daemon, wait_until)

pytestmark = pytest.mark.ros

OPERATOR_TOPIC = "/own_op"
SCRIPT_TOPIC = "/own_script"
RATE_HZ = "50"


@pytest.fixture(scope="module")
def daemon(module_processes: Processes, tmp_path_factory: pytest.TempPathFactory) \
        -> Iterator[RunningDaemon]:
    running = operator_daemon(module_processes, tmp_path_factory.mktemp("owners"),
                              OPERATOR_TOPIC, SCRIPT_TOPIC, rate_hz=RATE_HZ)
    yield running
    assert_clean_exit(running)


def bridges(daemon: RunningDaemon) -> list[dict[str, Any]]:
    """The daemon's bridges, as a connection that asks for nothing sees them."""
    with daemon.connect() as watcher:
        return list(watcher.command("list_bridges")["bridges"])


def named(daemon: RunningDaemon, kind: str, **identity: str) -> dict[str, Any] | None:
    for bridge in bridges(daemon):
        if bridge["kind"] == kind and all(bridge.get(k) == v for k, v in identity.items()):
            return bridge
    return None


def device_of(daemon: RunningDaemon, topic: str) -> str:
    bridge = named(daemon, "subscriber", topic=topic)
    assert bridge is not None, bridges(daemon)
    return str(bridge["device"])


def plain_client_devices(daemon: RunningDaemon, until_device: str, count: int = 25) -> set[str]:
    """The devices a plain OpenIGTLink client (it never sends: 3D Slicer's connector before
    anyone asks for anything) receives until ``count`` messages of ``until_device`` came."""
    decoder = Decoder()
    seen: set[str] = set()
    got = 0
    with socket.create_connection(("127.0.0.1", daemon.port), timeout=scaled(20)) as sock:
        while got < count:
            data = sock.recv(1 << 16)
            assert data, f"the daemon closed the plain client after {seen}"
            decoder.feed(data)
            for message in decoder.messages():
                seen.add(message.device_name)
                got += message.device_name == until_device
    return seen


def wait_ended(daemon: RunningDaemon, kind: str, **identity: str) -> None:
    wait_until(lambda: named(daemon, kind, **identity) is None, timeout=scaled(10),
               what=f"the {kind} {identity} to end")


def test_a_scripts_bridges_end_with_it_and_a_plain_client_gets_only_the_operators(
        daemon: RunningDaemon) -> None:
    """The issue's leftovers: a script's subscriber (a live stream) and parameter client
    (of a node that is not there) are gone once it exits; a plain client that connects
    afterwards gets the operator's stream and nothing of the script's."""
    with slicer_client.connect("127.0.0.1", daemon.port) as script:
        sub = script.subscribe(SCRIPT_TOPIC, "PoseStamped")
        params = script.parameters("/own_no_such_node")
        wait_until(lambda: sub.count > 0, timeout=scaled(20), what="the script's stream")
        mine = {sub.device, params.device}
        assert named(daemon, "subscriber", topic=SCRIPT_TOPIC)["clients"] == 1
    wait_ended(daemon, "subscriber", topic=SCRIPT_TOPIC)
    wait_ended(daemon, "parameter_client", node="/own_no_such_node")
    operator = device_of(daemon, OPERATOR_TOPIC)
    seen = plain_client_devices(daemon, operator)
    assert operator in seen
    assert not seen & mine, seen
    assert "removed the subscriber /own_script: its last client left" in \
        daemon.child.output()


def test_a_wrong_type_does_not_stick_past_its_script(daemon: RunningDaemon) -> None:
    with slicer_client.connect("127.0.0.1", daemon.port) as first:
        first.subscribe("/own_force", "std_msgs/msg/Float64")
    wait_ended(daemon, "subscriber", topic="/own_force")
    with slicer_client.connect("127.0.0.1", daemon.port) as later:
        assert later.subscribe("/own_force", "std_msgs/msg/Float32").info["existed"] is False


def test_a_kept_bridge_stays_for_every_client_until_one_removes_it(
        daemon: RunningDaemon) -> None:
    with slicer_client.connect("127.0.0.1", daemon.port) as script:
        sub = script.subscribe(SCRIPT_TOPIC, "PoseStamped")
        sub.keep()
        saved = script.state().to_json()
        # Only a live bridge of a kind that can outlive its client is kept.
        error = refused(lambda: script.command("keep_bridge", {"kind": "subscriber",
                                                               "topic": "/own_never"}))
        assert error.code == ErrorCode.NOT_FOUND and error.field == "topic"
        error = refused(lambda: script.command("keep_bridge", {"kind": "served_service",
                                                               "service": "/own_srv"}))
        assert error.code == ErrorCode.OUT_OF_RANGE and error.field == "kind"
    assert '"kept": true' in saved
    wait_until(lambda: named(daemon, "subscriber", topic=SCRIPT_TOPIC)["clients"] == 0,
               timeout=scaled(10), what="the script's leaving")
    kept = named(daemon, "subscriber", topic=SCRIPT_TOPIC)
    assert kept is not None and kept["stays"] is True
    assert kept["device"] in plain_client_devices(daemon, kept["device"], count=5)
    with slicer_client.connect("127.0.0.1", daemon.port) as other:
        assert other.remove_bridge("create_subscriber", SCRIPT_TOPIC) is True
        # The saved state keeps it again, as the script left it.
        restored = other.restore(slicer_client.BridgeState.from_json(saved))
        assert restored[0].spec.kept
    assert named(daemon, "subscriber", topic=SCRIPT_TOPIC)["stays"] is True
    with slicer_client.connect("127.0.0.1", daemon.port) as other:
        assert other.remove_bridge("create_subscriber", SCRIPT_TOPIC) is True


def test_the_operators_bridges_stay_when_a_client_that_shared_one_leaves(
        daemon: RunningDaemon) -> None:
    with slicer_client.connect("127.0.0.1", daemon.port) as script:
        assert script.subscribe(OPERATOR_TOPIC, "PoseStamped").info["existed"] is True
        assert named(daemon, "subscriber", topic=OPERATOR_TOPIC)["stays"] is True
    wait_until(lambda: named(daemon, "subscriber", topic=OPERATOR_TOPIC)["clients"] == 0,
               timeout=scaled(10), what="the script's leaving")
    assert named(daemon, "subscriber", topic=OPERATOR_TOPIC)["stays"] is True


def test_a_shared_bridge_lives_while_either_of_its_two_clients_does(
        daemon: RunningDaemon) -> None:
    with slicer_client.connect("127.0.0.1", daemon.port) as second:
        with slicer_client.connect("127.0.0.1", daemon.port) as first:
            first.subscribe(SCRIPT_TOPIC, "PoseStamped")
            sub = second.subscribe(SCRIPT_TOPIC, "PoseStamped")
            assert sub.info["existed"] is True
            assert named(daemon, "subscriber", topic=SCRIPT_TOPIC)["clients"] == 2
        wait_until(lambda: named(daemon, "subscriber", topic=SCRIPT_TOPIC)["clients"] == 1,
                   timeout=scaled(10), what="the first client's leaving")
        before = sub.count
        wait_until(lambda: sub.count > before + 5, timeout=scaled(20),
                   what="the second client's stream after the first left")
    wait_ended(daemon, "subscriber", topic=SCRIPT_TOPIC)


def test_a_reconnected_client_still_has_its_bridges_and_they_end_with_it(
        daemon: RunningDaemon) -> None:
    """A link lost under a client (its socket shut, as a pulled cable ends up): the daemon
    drops the old connection and its bridges may end with it, the client re-creates them
    on the new one; either order ends with the same bridges, held by the new connection."""
    transport = open_transport("127.0.0.1", daemon.port, retry_interval=0.1)
    client = Client(transport)
    try:
        sub = client.subscribe(SCRIPT_TOPIC, "PoseStamped")
        params = client.parameters("/own_reconnect_node")
        old = transport.connection
        old._sock.shutdown(socket.SHUT_RDWR)  # type: ignore[attr-defined]
        wait_until(lambda: transport.reconnects == 1 and transport.connected,
                   timeout=scaled(20), what="the reconnect")
        for kind, identity in (("subscriber", {"topic": SCRIPT_TOPIC}),
                               ("parameter_client", {"node": "/own_reconnect_node"})):
            wait_until(lambda k=kind, i=identity: (named(daemon, k, **i) or {}).get(
                "clients") == 1, timeout=scaled(10), what=f"the {kind} held once")
        before = sub.count
        wait_until(lambda: sub.count > before + 5, timeout=scaled(20),
                   what="the stream after the reconnect")
        assert params.device
    finally:
        transport.close()
    wait_ended(daemon, "subscriber", topic=SCRIPT_TOPIC)
    wait_ended(daemon, "parameter_client", node="/own_reconnect_node")


def test_the_daemon_stops_cleanly_with_clients_and_their_bridges_still_there(
        processes: Processes, tmp_path: Path) -> None:
    running = start_daemon(processes)
    client = slicer_client.connect("127.0.0.1", running.port)
    client.subscribe("/own_at_stop", "String")
    client.parameters("/own_at_stop_node")
    assert_clean_exit(running)
    client.close()

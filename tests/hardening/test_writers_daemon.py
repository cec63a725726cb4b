"""Who may change ROS (issue 23): the writers' key, --trust, and TLS, on a running daemon
with a real rclpy subscriber in another process, judged by what it received."""

from __future__ import annotations

import json
import os
import re
import stat
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Iterator

import pytest

import slicer_client
from protocol.auth import proof
from protocol.commands import ErrorCode
from protocol.liveness import DEAD_AFTER_S
from protocol.messages import Message, Status, StatusCode, String
from hardening_tools import make_certificate
from slicer_client.connection import CommandRefusedError, Connection
from support import (REPO, Child, Processes, RunningDaemon, assert_clean_exit, scaled,
                     start_daemon, wait_until)

pytestmark = pytest.mark.ros

TOPIC = "/guarded"
STRING = "std_msgs/msg/String"


def keygen(path: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "bridge.console", "keygen", str(path),
                           *extra], capture_output=True, text=True, timeout=60, cwd=REPO)


def received(echo: Child) -> list[str]:
    return [json.loads(line[4:])["data"] for line in echo.lines()
            if line.startswith("MSG ")]


def refusal(client: Any, op: str, args: dict[str, Any]) -> CommandRefusedError:
    with pytest.raises(CommandRefusedError) as refused:
        client.command(op, args)
    return refused.value


@pytest.fixture(scope="module")
def key_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("keys") / "writers.key"
    made = keygen(path)
    assert made.returncode == 0, made.stderr
    return path


@pytest.fixture(scope="module")
def keyed_daemon(module_processes: Processes, key_file: Path,
                 tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningDaemon]:
    config = tmp_path_factory.mktemp("config") / "bridge.yaml"
    config.write_text(f"publishers:\n  - {{topic: {TOPIC}, type: {STRING}}}\n")
    running = start_daemon(module_processes, "--key-file", str(key_file),
                           "--config", str(config))
    yield running
    assert_clean_exit(running)


@pytest.mark.integration
def test_keygen_writes_an_owner_only_key_and_never_replaces_one(tmp_path: Path) -> None:
    path = tmp_path / "k"
    made = keygen(path)
    assert made.returncode == 0, made.stderr
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o600
    assert re.fullmatch(r"[0-9a-f]{64}\n", path.read_text())
    first = path.read_text()
    again = keygen(path)
    assert again.returncode == 2 and "exists" in again.stderr and "--force" in again.stderr
    assert path.read_text() == first
    assert keygen(path, "--force").returncode == 0 and path.read_text() != first


def test_without_the_key_a_connection_changes_nothing(keyed_daemon: RunningDaemon,
                                                      processes: Processes,
                                                      key_file: Path, tmp_path: Path) -> None:
    echo = processes.python("echo", "echo_subscriber.py", TOPIC, STRING)
    echo.wait_for_output("READY", timeout=30)
    plain = keyed_daemon.connect()  # as a plain OpenIGTLink client would, with no key
    try:
        auth = plain.command("hello", {})["auth"]
        assert auth["writes"] is False and re.fullmatch(r"[0-9a-f]{64}", auth["challenge"])
        assert "key" in auth["why"] and "--trust" in auth["why"]
        refused = refusal(plain, "create_publisher", {"topic": "/cmd_vel",
                                                      "type": "geometry_msgs/msg/Twist"})
        assert refused.code == ErrorCode.FORBIDDEN and "presented the daemon's key" in \
            str(refused)
        assert refusal(plain, "publish", {"topic": TOPIC, "message": {"data": "x"}}
                       ).code == ErrorCode.FORBIDDEN
        device = next(b["device"] for b in plain.command("list_bridges")["bridges"]
                      if b.get("topic") == TOPIC)
        plain.send(Message(device_name=device, body=String("from the plain client")))
        status = plain.wait_for(device, lambda m: isinstance(m.body, Status), timeout=10)
        assert isinstance(status.body, Status)
        assert status.body.code == StatusCode.ACCESS_DENIED and "key" in status.body.text
        # A wrong key is refused, and a challenge is good for one answer only.
        wrong = tmp_path / "wrong.key"
        assert keygen(wrong).returncode == 0
        challenge = plain.command("hello", {})["auth"]["challenge"]
        nonce = "ab" * 16
        bad = refusal(plain, "authenticate", {"nonce": nonce, "proof": proof(
            bytes.fromhex(wrong.read_text().strip()), challenge, nonce)})
        assert bad.code == ErrorCode.FORBIDDEN and bad.field == "proof"
        right = proof(bytes.fromhex(key_file.read_text().strip()), challenge, nonce)
        assert "send hello again" in str(refusal(plain, "authenticate",
                                                 {"nonce": nonce, "proof": right}))
        assert plain.command("hello", {})["auth"]["writes"] is False
    finally:
        plain.close()
    # The key's holder writes; nothing the plain client sent reached ROS.
    ros = slicer_client.connect("127.0.0.1", keyed_daemon.port, key_file=str(key_file))
    try:
        assert ros.may_write
        publisher = ros.publisher(TOPIC, STRING)

        def published_and_seen() -> bool:
            publisher.publish("from the key holder")  # again until discovery is done
            return "from the key holder" in received(echo)

        wait_until(published_and_seen, 30, "the key holder's message at the subscriber")
    finally:
        ros.close()
    assert "from the plain client" not in received(echo)
    assert "x" not in received(echo)


def test_a_wrong_key_leaves_the_client_read_only_and_says_so(keyed_daemon: RunningDaemon,
                                                             tmp_path: Path) -> None:
    wrong = tmp_path / "wrong.key"
    assert keygen(wrong).returncode == 0
    ros = slicer_client.connect("127.0.0.1", keyed_daemon.port, key_file=str(wrong))
    try:
        assert not ros.may_write
        assert any(e.startswith("authenticate: ") and "proof" in e for e in ros.errors)
        with pytest.raises(CommandRefusedError, match="presented the daemon's key"):
            ros.command("create_publisher", {"topic": "/x", "type": STRING})
    finally:
        ros.close()


def test_a_trusted_network_writes_without_a_key(processes: Processes, key_file: Path) -> None:
    running = start_daemon(processes, "--key-file", str(key_file), "--trust", "127.0.0.1/32")
    plain = running.connect()
    try:
        assert plain.command("hello", {})["auth"] == {"writes": True}
        plain.command("create_publisher", {"topic": "/trusted", "type": STRING})
    finally:
        plain.close()
    assert_clean_exit(running)


def test_a_bad_key_file_stops_the_start_in_one_line(processes: Processes,
                                                    tmp_path: Path) -> None:
    bad = tmp_path / "bad.key"
    bad.write_text("not a key\n")
    child = processes.bridge("run", "--port", "1", "--key-file", str(bad))
    assert child.popen.wait(scaled(60)) == 2
    output = child.output()
    assert "key_file" in output and "64 hex digits" in output and "Traceback" not in output


@pytest.fixture(scope="module")
def certificate(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    return make_certificate(tmp_path_factory.mktemp("tls"))


def test_the_tls_port_serves_clients_that_check_its_certificate(
        processes: Processes, key_file: Path, certificate: tuple[Path, Path]) -> None:
    from support import pick_free_port

    cert, key = certificate
    tls_port = pick_free_port()
    running = start_daemon(processes, "--key-file", str(key_file), "--tls-cert", str(cert),
                           "--tls-key", str(key), "--tls-port", str(tls_port))
    running.child.wait_for_output("over TLS", timeout=30)
    try:
        ros = slicer_client.connect("127.0.0.1", tls_port, tls=True, ca_file=str(cert),
                                    key_file=str(key_file))
        try:
            assert ros.may_write
            lost: list[str] = []
            ros.on_connection_change(lambda up, reason: None if up else lost.append(reason))
            ros.command("create_publisher", {"topic": "/over_tls", "type": STRING})
            assert any(b.get("topic") == "/over_tls" for b in ros.list_bridges()["bridges"])
            # Heartbeats keep coming over TLS (a transport paused with nothing buffered
            # once held them back: the client took the link for dead after 3 s).
            time.sleep(DEAD_AFTER_S + 1.5)
            assert not lost, lost
            assert any(b.get("topic") == "/over_tls" for b in ros.list_bridges()["bridges"])
        finally:
            ros.close()
        # A client that does not check against this certificate is refused by its own TLS.
        with pytest.raises(Exception, match="certificate|TLS|SSL"):
            slicer_client.connect("127.0.0.1", tls_port, tls=True, reconnect=False)
        # The plain port still serves plain clients (read-only without the key).
        plain = Connection("127.0.0.1", running.port)
        try:
            assert plain.command("hello", {})["auth"]["writes"] is False
        finally:
            plain.close()
    finally:
        assert_clean_exit(running)
    assert "has permissions" not in running.child.output()  # both keys are 0600


def test_key_files_others_may_read_are_warned_of_at_start(
        processes: Processes, key_file: Path, certificate: tuple[Path, Path],
        tmp_path: Path) -> None:
    """As ssh warns of a private key others may read (issue 43, item 6): one line each."""
    cert, tls_key = certificate
    loose_key, loose_tls_key = tmp_path / "writers.key", tmp_path / "tls-key.pem"
    loose_key.write_bytes(key_file.read_bytes())
    loose_key.chmod(0o644)
    loose_tls_key.write_bytes(tls_key.read_bytes())
    loose_tls_key.chmod(0o640)
    running = start_daemon(processes, "--key-file", str(loose_key), "--tls-cert", str(cert),
                           "--tls-key", str(loose_tls_key), "--tls-port", "0")
    running.child.wait_for_output("over TLS", timeout=30)
    output = running.child.output()
    assert f"WARNING bridge: --key-file {loose_key} has permissions 0644: readable " \
           f"by others, who could then write through the daemon; expected 0600 (chmod 600 " \
           f"{loose_key})\n" in output, output[-3000:]
    assert f"WARNING bridge: --tls-key {loose_tls_key} has permissions 0640: " \
           f"readable by its group, who could then pose as the daemon; expected 0600 " \
           f"(chmod 600 {loose_tls_key})\n" in output, output[-3000:]
    assert output.count("has permissions") == 2
    with Connection("127.0.0.1", running.port) as client:  # it serves all the same
        assert client.command("hello")["ops"]
    assert_clean_exit(running)

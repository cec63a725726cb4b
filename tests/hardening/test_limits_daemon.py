"""Bounded under abuse, on a running daemon: the frame deadline (slowloris), client slots
held by unfinished frames, and the daemon-wide budget of partly received bodies."""

from __future__ import annotations

import re
import select
import socket
import subprocess
import sys
import time
from typing import Any

import pytest

from hardening_tools import RawClient, command_bytes, header, is_reply, read_until_closed
from protocol.messages import StatusCode
from slicer_client.connection import Connection
from support import REPO, Processes, pick_free_port, scaled, start_daemon, wait_until

MIB = 1 << 20


def is_status(message) -> bool:  # type: ignore[no-untyped-def]
    return message.type_name == "STATUS"


def still_open(sock: socket.socket) -> bool:
    """Nothing came from the daemon on ``sock``: no EOF, no reset, no STATUS. (It sends
    nothing unasked to a client of a daemon without bridges.)"""
    readable, _, _ = select.select([sock], [], [], 0)
    return not readable


def clients(daemon_port: int) -> list[dict[str, Any]]:
    """The daemon's connected clients (list_bridges), the lister among them."""
    with Connection("127.0.0.1", daemon_port) as lister:
        return list(lister.command("list_bridges", timeout=scaled(10))["clients"])


def test_a_half_sent_frame_is_closed_at_the_deadline_and_a_silent_client_stays(
        processes: Processes) -> None:
    daemon = start_daemon(processes, "--frame-deadline", "1")
    silent = socket.create_connection(("127.0.0.1", daemon.port), timeout=5)  # receives only
    try:
        slow = socket.create_connection(("127.0.0.1", daemon.port), timeout=5)
        start = time.monotonic()
        slow.sendall(header("STRING", "x", 64, 0)[:7])  # 7 bytes of a header, then nothing
        replies = read_until_closed(slow, timeout=10)
        took = time.monotonic() - start
        slow.close()
        assert replies and replies[-1].type_name == "STATUS", replies
        assert replies[-1].body.code == StatusCode.TIME_OUT
        assert "frame deadline" in replies[-1].body.text and "got 7 bytes" in replies[-1].body.text
        assert took >= 1.0  # not before its deadline
        # Connected before the slow one and silent ever since: still welcome, and served.
        assert still_open(silent)
        served = RawClient(daemon.port)
        served.send(command_bytes("hello", b"{}", command_id=5))
        assert served.read_until(is_reply(5), timeout=10)
        served.close()
        assert still_open(silent)
    finally:
        silent.close()
    log = daemon.child.output()
    assert len(re.findall(r"unfinished 1\.0 s after its first byte", log)) == 1, log[-3000:]


def test_frames_finished_within_the_deadline_are_never_cut(processes: Processes) -> None:
    """A frame sent slowly, but each within its deadline, goes through: the deadline
    restarts with every frame."""
    daemon = start_daemon(processes, "--frame-deadline", "2")
    client = RawClient(daemon.port)
    try:
        for command_id in range(1, 4):
            data = command_bytes("hello", b"{}", command_id=command_id)
            client.send(data[:30])
            wait_until(lambda: any(c["receiving_bytes"] == 30 for c in clients(daemon.port)),
                       timeout=10, what="the daemon holding 30 bytes of a frame")
            client.send(data[30:])
            assert client.read_until(is_reply(command_id), timeout=10)
    finally:
        client.close()


def test_stalled_frames_make_room_for_a_new_client(processes: Processes) -> None:
    daemon = start_daemon(processes, "--max-clients", "3", "--frame-deadline", "600")
    stalled = [socket.create_connection(("127.0.0.1", daemon.port), timeout=5)
               for _ in range(3)]
    admitted: list[RawClient] = []

    def try_to_join() -> bool:
        """A newcomer is refused (max_clients) until a stalled frame is a second old."""
        client = RawClient(daemon.port)
        client.send(command_bytes("hello", b"{}", command_id=3))
        reply = client.read_until(lambda m: is_reply(3)(m) or is_status(m), timeout=10)
        if reply.type_name == "RTS_COMMAND":
            admitted.append(client)
            return True
        assert reply.body.code == StatusCode.RESOURCE_ERROR and "max-clients" in reply.body.text
        client.close()
        return False

    try:
        for sock in stalled:
            sock.sendall(header("STRING", "x", 64, 0)[:7])
        wait_until(try_to_join, timeout=20, what="a newcomer admitted")
        wait_until(lambda: sum(not still_open(s) for s in stalled) == 1, timeout=10,
                   what="one stalled client closed")
        (evicted,) = [sock for sock in stalled if not still_open(sock)]
        replies = read_until_closed(evicted, timeout=10)
        assert replies[-1].body.code == StatusCode.RESOURCE_ERROR
        assert "client slots are taken" in replies[-1].body.text
        assert sum(still_open(s) for s in stalled) == 2  # one was enough
    finally:
        for client in admitted:
            client.close()
        for sock in stalled:
            sock.close()


def test_half_sent_bodies_share_one_budget(processes: Processes) -> None:
    daemon = start_daemon(processes, "--max-message-bytes", str(8 * MIB),
                          "--max-receive-buffer-bytes", str(16 * MIB), "--frame-deadline", "600")
    body = 7 * MIB
    holders = [socket.create_connection(("127.0.0.1", daemon.port), timeout=5)
               for _ in range(2)]
    try:
        for sock in holders:
            sock.sendall(header("STRING", "x", body, 0) + bytes(MIB))
        wait_until(lambda: sum(c["receiving_bytes"] >= MIB for c in clients(daemon.port)) == 2,
                   timeout=10, what="two bodies being received")
        # A third large body does not fit in what is left: refused from its header.
        third = socket.create_connection(("127.0.0.1", daemon.port), timeout=5)
        third.sendall(header("STRING", "x", body, 0))
        replies = read_until_closed(third, timeout=10)
        third.close()
        assert replies[-1].body.code == StatusCode.RESOURCE_ERROR, replies
        text = replies[-1].body.text
        assert "shared budget for partly received bodies (16777216 bytes" in text, text
        assert f"got {body}" in text
        # Small messages are not held back by it.
        small = RawClient(daemon.port)
        small.send(command_bytes("hello", b"{}", command_id=4))
        assert small.read_until(is_reply(4), timeout=10)
        small.close()
        # A holder that leaves gives its share back: a new large body fits again.
        holders.pop().close()
        fourth = RawClient(daemon.port)
        fourth.send(header("STRING", "x", body, 0) + bytes(MIB))
        wait_until(lambda: sum(c["receiving_bytes"] >= MIB for c in clients(daemon.port)) == 2,
                   timeout=10, what="the freed share taken by a new body")
        assert still_open(fourth.sock)
        fourth.close()
    finally:
        for sock in holders:
            sock.close()
    assert "Traceback" not in daemon.child.output()


@pytest.mark.integration
def test_a_budget_below_the_message_size_is_refused_at_start() -> None:
    result = subprocess.run([sys.executable, "-m", "bridge.cli", "run", "--port",
                             str(pick_free_port()), "--max-message-bytes", "1000",
                             "--max-receive-buffer-bytes", "999"],
                            cwd=REPO, capture_output=True, text=True, timeout=scaled(60))
    assert result.returncode == 2
    assert "--max-receive-buffer-bytes: expected at least --max-message-bytes (1000), got 999" \
        in result.stderr

"""A daemon whose process runs out of descriptors (issue 43): the descriptor limit of the
running daemon is lowered to what it has open (`prlimit --pid`), so every new descriptor
fails with EMFILE, whoever asks. Accept says so in one line per interval, the shared-memory
port watch fails, says so in one line and runs again; once descriptors are free again,
clients are served, and the watch still runs."""

from __future__ import annotations

import os
import re
import resource
import shutil
import socket
import subprocess

import pytest

from hardening_tools import read_until_closed
from protocol.messages import StatusCode
from support import Processes, assert_clean_exit, scaled, start_daemon, wait_until

pytestmark = pytest.mark.ros

WATCH_FAILED = "thread shm-port-watch failed (OSError: [Errno 24] Too many open files"


def set_descriptor_limit(pid: int, soft: int) -> None:
    hard = resource.getrlimit(resource.RLIMIT_NOFILE)[1]
    subprocess.run(["prlimit", "--pid", str(pid), f"--nofile={soft}:{hard}"], check=True,
                   timeout=30)


def lowest_free_descriptor(pid: int) -> int:
    used = {int(fd) for fd in os.listdir(f"/proc/{pid}/fd")}
    return next(fd for fd in range(len(used) + 1) if fd not in used)


def test_out_of_descriptors_is_said_once_and_every_thread_goes_on(
        processes: Processes) -> None:
    if shutil.which("prlimit") is None or not os.path.isdir("/dev/shm"):
        pytest.skip("needs util-linux's prlimit and /dev/shm (the watch reads it)")
    running = start_daemon(processes)
    pid = running.child.popen.pid
    output = running.child.output
    before = len(os.listdir(f"/proc/{pid}/fd"))
    set_descriptor_limit(pid, lowest_free_descriptor(pid))  # nothing new opens now
    try:
        waiting = [socket.create_connection(("127.0.0.1", running.port)) for _ in range(5)]
        wait_until(lambda: "cannot accept a connection" in output(), timeout=10,
                   what="the accept failure said")
        wait_until(lambda: WATCH_FAILED in output(), timeout=15,
                   what="the port watch's failure said")
    finally:
        set_descriptor_limit(pid, 1024)
    # The clients that waited in the backlog are taken now, and new ones are served.
    with running.connect() as client:
        assert client.command("hello")["ops"]
    for sock in waiting:
        sock.close()
    said = output()
    assert said.count("cannot accept a connection") == 1, said[-3000:]
    line = next(line for line in said.splitlines() if "cannot accept a connection" in line)
    assert re.search(r"on port \d+: Too many open files \((all|\d+) of \d+ descriptors open "
                     r"\(ulimit -n\)\); trying again in 0.5 s$", line), line
    assert said.count(WATCH_FAILED) == 1 and "Traceback" not in said, said[-3000:]
    # The watch still runs: out of descriptors again, it fails again (and says so). (Once
    # the clients' descriptors are closed: a hole below the limit would let it open one.)
    wait_until(lambda: len(os.listdir(f"/proc/{pid}/fd")) <= before, timeout=10,
               what="the clients' descriptors closed")
    set_descriptor_limit(pid, lowest_free_descriptor(pid))
    try:
        wait_until(lambda: output().count(WATCH_FAILED) == 2, timeout=scaled(20),
                   what="the port watch's next turn")
    finally:
        set_descriptor_limit(pid, 1024)
    # One descriptor left: accept takes it, and a plain client needs a second (for direct
    # writes): that client is closed, in one line, and the next one is served.
    set_descriptor_limit(pid, lowest_free_descriptor(pid) + 1)
    try:
        with socket.create_connection(("127.0.0.1", running.port)) as one:
            one.settimeout(scaled(10))
            assert one.recv(1) == b""
        wait_until(lambda: "(its second descriptor); closing it" in output(), timeout=10,
                   what="the client without a second descriptor said")
    finally:
        set_descriptor_limit(pid, 1024)
    with running.connect() as client:
        assert client.command("hello")["ops"]
    assert "Traceback" not in output()
    assert_clean_exit(running)


def test_clients_past_the_room_the_descriptor_limit_leaves_are_refused(
        processes: Processes) -> None:
    """--max-clients 64 under ``ulimit -n`` 200: the daemon says at start how many fit
    (128 descriptors kept aside, 2 a client), refuses the others with a STATUS saying why,
    and its descriptors stay under the limit."""
    if shutil.which("prlimit") is None:
        pytest.skip("needs util-linux's prlimit")
    running = start_daemon(processes, "--max-clients", "64", nofile=200)
    pid = running.child.popen.pid
    said_at_start = re.search(r"the descriptor limit \(ulimit -n 200\) leaves room for (\d+) "
                              r"clients, fewer than --max-clients 64: the others are refused",
                              running.child.output())
    assert said_at_start, running.child.output()
    room = int(said_at_start.group(1))
    assert 10 <= room < 64, room
    clients = []
    try:
        for _ in range(room):
            clients.append(running.connect())
        assert all(c.command("hello")["ops"] for c in clients[-2:])
        with socket.create_connection(("127.0.0.1", running.port)) as extra:
            said = read_until_closed(extra)
        assert [m.type_name for m in said] == ["STATUS"]
        assert said[0].body.code == StatusCode.RESOURCE_ERROR
        assert said[0].body.text == (f"clients: expected at most {room} (what the daemon's "
                                     f"descriptor limit leaves room for), got one more; "
                                     f"closing")
        assert len(os.listdir(f"/proc/{pid}/fd")) < 200 - 64
    finally:
        for client in clients:
            client.close()
    assert f"{room} clients already connected, all the descriptor limit" in \
        running.child.output()
    assert_clean_exit(running)

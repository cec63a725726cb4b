"""Who may connect, judged on the TLS port as on the plain one (issue 43): before any
handshake, on the raw TCP connection. A host outside ``--allow`` is a network namespace of
its own (tests/netns.py); the daemon runs with the usual descriptor limit, 1024."""

from __future__ import annotations

import os
import re
import sys
import time
from pathlib import Path
from typing import Iterator

import pytest

from bridge.core.server import HANDSHAKE_TIMEOUT_S
from hardening_tools import make_certificate
from netns import Hosts
from support import (REPO, Child, Processes, RunningDaemon, assert_clean_exit, scaled,
                     start_daemon, wait_until)

pytestmark = pytest.mark.ros

HARDENING_PEERS = Path(__file__).resolve().parent / "peers"
PREFIX = "10.78.0"  # the cable: the daemon's host .1, the outside host .2
DAEMON, OUTSIDE = f"{PREFIX}.1", f"{PREFIX}.2"
TLS_PORT = 18945  # the namespace is new: every port is free there
IDLE = 1100  # the issue's: more than the daemon's 1024 descriptors
FD_LIMIT = 1024


def descriptors(pid: int) -> int:
    return len(os.listdir(f"/proc/{pid}/fd"))


def summary(child: Child) -> dict[str, float]:
    line = child.wait_for_output("SUMMARY", timeout=scaled(60))
    return {k: float(v) for k, v in re.findall(r"(\w+)=(-?[\d.]+)", line)}


@pytest.fixture
def outside_host(tmp_path: Path) -> Iterator[tuple[Hosts, Path]]:
    with Hosts(["bridge", "outside"], cables=[("bridge", "outside", PREFIX)]) as net:
        yield net, tmp_path


def test_idle_tls_connections_from_outside_allow_cost_nothing(
        outside_host: tuple[Hosts, Path], processes: Processes) -> None:
    net, folder = outside_host
    cert, key = make_certificate(folder, DAEMON)
    env = {"PYTHONPATH": str(REPO)}
    # The set-up: --host A --allow A/32, TLS, a limit of 1024 descriptors.
    daemon = processes.start("daemon", net.argv("bridge", [
        "prlimit", f"--nofile={FD_LIMIT}:{FD_LIMIT}", "--", sys.executable, "-u", "-m",
        "bridge.console", "run", "--host", DAEMON, "--allow", f"{DAEMON}/32",
        "--tls-cert", str(cert), "--tls-key", str(key), "--tls-port", str(TLS_PORT)]),
        env=env)
    daemon.wait_for_output("over TLS", timeout=scaled(60))
    pid = daemon.popen.pid  # ip netns exec and prlimit exec the daemon itself
    assert "bridge.console" in Path(f"/proc/{pid}/cmdline").read_text()
    before = descriptors(pid)
    log_before = len(daemon.output())

    flood = processes.start("outside", net.argv("outside", [
        sys.executable, "-u", str(HARDENING_PEERS / "idle_connections.py"), DAEMON,
        str(TLS_PORT), str(IDLE), "--hold", str(scaled(20))]), env=env)
    opened = flood.wait_for_output("OPEN", timeout=scaled(60))
    peak = descriptors(pid)
    # Meanwhile a client on an allowed address says hello, over a new connection each time.
    hellos = processes.start("allowed", net.argv("bridge", [
        sys.executable, "-u", str(HARDENING_PEERS / "tls_hellos.py"), DAEMON, str(TLS_PORT),
        str(cert), "10"]), env=env)
    done = hellos.wait_for_output("DONE", timeout=scaled(120))
    peak = max(peak, descriptors(pid))
    seen = summary(flood)
    output = daemon.output()
    grown = len(output) - log_before
    print(f"\n{opened.strip()}; daemon fds {before} -> peak {peak}; {seen}; log grew "
          f"{grown} bytes; hellos: {done.strip()}")

    assert opened.split()[1:] == [str(IDLE), "0"], opened  # every connect was accepted
    # Every one was closed at once, with no handshake: none held, none waiting 60 s.
    assert seen["closed"] == IDLE and seen["held"] == 0, seen
    assert 0 <= seen["last_close_s"] < scaled(5), seen
    assert done.split()[1:] == ["10", "0"], hellos.output()
    assert peak - before <= 16, (before, peak)
    assert "Traceback" not in output and "out of system resource" not in output
    assert grown < 4000, output[log_before:][-3000:]  # a few rate-limited lines
    assert f"refused client {OUTSIDE}:" in output
    daemon.stop()
    assert daemon.popen.returncode == 0, output[-3000:]


def test_idle_handshakes_hold_no_more_than_client_slots_and_end_soon(
        processes: Processes, tmp_path: Path) -> None:
    """Idle connections from an allowed address: each holds a client slot while its
    handshake waits, so there are never more than --max-clients; past the timeout they are
    closed, and a client that completes its handshake takes the slot of a stalled one."""
    cert, key = make_certificate(tmp_path)
    running: RunningDaemon = start_daemon(processes, "--max-clients", "8", "--tls-cert",
                                          str(cert), "--tls-key", str(key),
                                          "--tls-port", "0")
    line = running.child.wait_for_output("over TLS", timeout=scaled(30))
    found = re.search(r":(\d+) \(OpenIGTLink over TLS\)", line)
    assert found, line
    tls_port = found.group(1)
    pid = running.child.popen.pid
    before = descriptors(pid)
    idle = processes.python("idle", str(HARDENING_PEERS / "idle_connections.py"),
                            "127.0.0.1", tls_port, "50",
                            "--hold", str(scaled(HANDSHAKE_TIMEOUT_S + 10)))
    idle.wait_for_output("OPEN", timeout=scaled(30))
    wait_until(lambda: "refused client" in running.child.output(), timeout=10,
               what="the extra idle connections refused")
    assert descriptors(pid) - before <= 8 * 2 + 4
    time.sleep(1.2)  # the held handshakes are now stalled (older than a second)
    hellos = processes.python("hellos", str(HARDENING_PEERS / "tls_hellos.py"),
                              "127.0.0.1", tls_port, str(cert), "3")
    done = hellos.wait_for_output("DONE", timeout=scaled(60))
    assert done.split()[1:] == ["3", "0"], hellos.output()
    seen = summary(idle)
    print(f"\nidle: {seen}; hellos: {done.strip()}")
    # 42 refused at once, 8 held, closed by the timeout or to make room: none outlived it.
    assert seen["held"] == 0 and seen["closed"] == 50, seen
    assert seen["last_close_s"] <= HANDSHAKE_TIMEOUT_S + scaled(3), seen
    assert "TLS handshake" in running.child.output()
    assert_clean_exit(running)

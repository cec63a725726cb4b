"""Helpers for tests: ports, child processes, waiting on events, optional test data."""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional, Sequence

import numpy as np
import pytest

from bridge.platform.shm_locks import (ports_of_domains, release_stuck, remove_dead_segments,
                                  remove_unfinished)
from slicer_client.connection import CommandRefusedError, Connection
from protocol.messages import Message

REPO = Path(__file__).resolve().parent.parent
PEERS = Path(__file__).resolve().parent / "peers"
SHARED = REPO.parent / "shared"

# Every deadline of the suite is multiplied by this one factor: the waiting helpers here
# and in tests/hardening/hardening_tools.py apply it to the timeouts they are given, other
# waits call `scaled`. Deadlines only bound waits on events (a line printed, a message
# received, a condition polled), so a generous factor costs nothing while tests pass; it
# lets the suite hold on a loaded machine. SLICER_BRIDGE_TEST_TIME_SCALE sets it.
TIME_SCALE = float(os.environ.get("SLICER_BRIDGE_TEST_TIME_SCALE", "3"))


# The session's ROS domains (conftest reserves them): ROS_DOMAIN_ID, and after it the spares
# for tests that need a ROS graph of their own (a demo beside the session's peers).
DOMAIN_BLOCK = 3
# Where each session holds the lock of its block (the file named after its first domain).
DOMAIN_LOCKS = Path(tempfile.gettempdir()) / f"slicer-ros2-bridge-domains-{os.getuid()}"


def spare_domain(index: int) -> str:
    """The session's spare ROS domain `index` (1 or 2), as ROS_DOMAIN_ID takes it."""
    if not 1 <= index < DOMAIN_BLOCK:
        raise ValueError(f"a spare domain index 1-{DOMAIN_BLOCK - 1}, got {index}")
    return str(int(os.environ["ROS_DOMAIN_ID"]) + index)


def scaled(seconds: float) -> float:
    """A deadline of ``seconds`` on an idle machine, scaled for this one."""
    return seconds * TIME_SCALE


def pick_free_port() -> int:
    """A port nobody listens on now. Another process may take it before the caller binds
    it: where the daemon may choose (`start_daemon`), it binds port 0 instead."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


class Child:
    """A started process whose combined output goes to a log file we can wait on."""

    def __init__(self, name: str, popen: subprocess.Popen[bytes], log: Path) -> None:
        self.name = name
        self.popen = popen
        self.log = log
        self._read_upto = 0

    @property
    def pid(self) -> int:
        return self.popen.pid

    def output(self) -> str:
        return self.log.read_text(errors="replace")

    def lines(self) -> list[str]:
        """The output's complete lines: one the child is still writing is left out (the
        file can be read between two of its writes)."""
        text = self.output()
        return text[:text.rfind("\n") + 1].splitlines()

    def wait_for_output(self, needle: str, timeout: float = 20.0) -> str:
        """Wait until `needle` appears in the output after what earlier waits consumed;
        return the line holding it. ``timeout`` is scaled (`scaled`)."""
        timeout = scaled(timeout)
        deadline = time.monotonic() + timeout
        while True:
            running = self.popen.poll() is None  # before the read: a last line is then seen
            text = self.output()
            found = text.find(needle, self._read_upto)
            if found >= 0:
                line_end = text.find("\n", found)
                if line_end < 0 and running and time.monotonic() <= deadline:
                    time.sleep(0.02)  # the line is still being written: wait for its end
                    continue
                line_end = len(text) if line_end < 0 else line_end
                line_start = text.rfind("\n", 0, found) + 1
                self._read_upto = line_end
                return text[line_start:line_end]
            if not running:
                raise AssertionError(f"{self.name} exited with {self.popen.returncode} before "
                                     f"printing {needle!r}; output:\n{text[-3000:]}")
            if time.monotonic() > deadline:
                raise AssertionError(f"{self.name} did not print {needle!r} within {timeout} s;"
                                     f" output:\n{text[-3000:]}")
            time.sleep(0.02)

    def stop(self, sig: int = signal.SIGINT, timeout: float = 10.0) -> Optional[int]:
        """Signal the child, wait for it (``timeout``, scaled), kill its whole process
        group if it lingers."""
        if self.popen.poll() is None:
            try:
                self.popen.send_signal(sig)
                self.popen.wait(scaled(timeout))
            except subprocess.TimeoutExpired:
                pass
        try:
            os.killpg(self.popen.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
        try:
            self.popen.wait(5)
        except subprocess.TimeoutExpired:
            pass
        return self.popen.returncode


def _terminal_signals() -> None:
    """A child takes Ctrl-C and hang-ups as from a terminal, even when the suite runs as a
    background job (`nohup make test &` ignores SIGINT and SIGHUP, and children inherit
    that: a Ctrl-C test's process would then never stop)."""
    for sig in (signal.SIGINT, signal.SIGHUP):
        signal.signal(sig, signal.SIG_DFL)


class Processes:
    """Starts children for one test and stops every one of them at teardown."""

    def __init__(self, tmp: Path) -> None:
        self.tmp = tmp
        self.children: list[Child] = []

    def start(self, name: str, argv: Sequence[str], *, env: Optional[dict[str, str]] = None,
              cwd: Optional[Path] = None) -> Child:
        log = self.tmp / f"{name}-{len(self.children)}.log"
        full_env = dict(os.environ)
        full_env.update(env or {})
        with log.open("wb") as out:
            popen = subprocess.Popen(list(argv), stdout=out, stderr=subprocess.STDOUT,
                                     stdin=subprocess.DEVNULL, env=full_env,
                                     cwd=str(cwd or REPO), start_new_session=True,
                                     preexec_fn=_terminal_signals)
        child = Child(name, popen, log)
        self.children.append(child)
        return child

    def python(self, name: str, script: str, *args: str,
               env: Optional[dict[str, str]] = None) -> Child:
        """Run a peer script from tests/peers (or any path) with this venv's Python."""
        path = Path(script)
        if not path.is_absolute():
            path = PEERS / script
        return self.start(name, [sys.executable, "-u", str(path), *args], env=env)

    def bridge(self, *args: str, env: Optional[dict[str, str]] = None,
               nofile: Optional[int] = None) -> Child:
        """Run the `slicer-ros2-bridge` command (its entry point, `python -m bridge.console`)
        with these arguments; `nofile`: under that descriptor limit (util-linux's prlimit,
        which execs it: the child's pid is the daemon's)."""
        limit = ["prlimit", f"--nofile={nofile}:{nofile}", "--"] if nofile else []
        return self.start("bridge", [*limit, sys.executable, "-u", "-m", "bridge.console",
                                     *args], env=env)

    def stop_all(self) -> None:
        for child in reversed(self.children):
            child.stop()
        release_left_port_locks()


def session_domains() -> range:
    """The session's block of ROS domains (ROS_DOMAIN_ID is its first)."""
    first = int(os.environ["ROS_DOMAIN_ID"])
    return range(first, first + DOMAIN_BLOCK)


def release_left_port_locks() -> None:
    """A ROS process killed while opening a Fast DDS shared-memory port (a test's kill -9,
    or the SIGKILL of `Child.stop`) leaves the port's lock taken, and every later ROS
    process of the host that opens that port hangs: every test after it would fail (ci71:
    8). Released here, and said (pytest shows it with the test's output). Only the ports
    of the session's domains: another session's tests hold some of theirs on purpose."""
    ports = ports_of_domains(session_domains())
    for path in remove_unfinished(ports=ports):
        print(f"removed Fast DDS port segment {path}, never finished", file=sys.stderr)
    for name in release_stuck(ports=ports):
        print(f"released Fast DDS port lock {name}, left taken by a killed ROS process",
              file=sys.stderr)
    remove_dead_segments()  # a killed process's segment stays in RAM until removed


def refused(call: Callable[[], object]) -> CommandRefusedError:
    """The refusal `call` (a command) meets; the test fails if it is not refused."""
    with pytest.raises(CommandRefusedError) as info:
        call()
    return info.value


def alive(pid: int) -> bool:
    """Whether process `pid` runs (a zombie does not)."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] not in ("Z", "X")
    except OSError:
        return False


def children_of(pid: int, *, not_under: frozenset[int] = frozenset()
                ) -> list[tuple[int, str, str]]:
    """(pid, state, command) of every live descendant of `pid`, read from /proc; the
    descendants of those in `not_under` are left out (theirs to end)."""
    parents: dict[int, list[int]] = {}
    info: dict[int, tuple[str, str]] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
            cmdline = Path(f"/proc/{entry}/cmdline").read_bytes().replace(b"\0", b" ")
        except OSError:
            continue
        # The command name may hold spaces or parentheses: split after the last ')'.
        fields = stat[stat.rfind(")") + 2:].split()
        state, ppid = fields[0], int(fields[1])
        parents.setdefault(ppid, []).append(int(entry))
        info[int(entry)] = (state, cmdline.decode(errors="replace").strip())
    found: list[tuple[int, str, str]] = []
    stack = list(parents.get(pid, []))
    while stack:
        child = stack.pop()
        state, cmd = info.get(child, ("?", ""))
        if state != "Z":
            found.append((child, state, cmd))
        if child not in not_under:
            stack.extend(parents.get(child, []))
    return found


def wait_until(predicate: Callable[[], bool], timeout: float = 10.0,
               what: str = "condition") -> None:
    """Poll a cheap predicate until it holds; fail naming `what` after `timeout`
    (scaled)."""
    timeout = scaled(timeout)
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(0.01)


def require_shared(relative: str) -> Path:
    """A path under ../shared, or a skip naming what is missing."""
    path = SHARED / relative
    if not path.exists():
        pytest.skip(f"needs {path} (the project's shared test data), which is absent here")
    return path


@dataclass
class RunningDaemon:
    child: Child
    port: int

    def connect(self) -> Connection:
        return Connection("127.0.0.1", self.port)


def start_daemon(processes: Processes, *args: str, env: Optional[dict[str, str]] = None,
                 nofile: Optional[int] = None) -> RunningDaemon:
    # The kernel picks the port as the daemon binds it: a port picked here and bound later
    # could be taken in between by any other process of a busy machine.
    child = processes.bridge("run", "--port", "0", *args, env=env, nofile=nofile)
    line = child.wait_for_output(" (OpenIGTLink); ROS node", timeout=30)
    listening = re.search(r"listening on \S+:(\d+) \(OpenIGTLink\)", line)
    assert listening, line
    return RunningDaemon(child, int(listening.group(1)))


def operator_daemon(processes: Processes, folder: Path, topic: str, *others: str,
                    rate_hz: str) -> RunningDaemon:
    """A daemon whose operator's `--config` streams `topic` (PoseStamped) to every client,
    and a publisher of PoseStamped at `rate_hz` on it and on each of `others`, each in a
    process of its own."""
    config = folder / "bridge.yaml"
    config.write_text(f"subscribers:\n  - {{topic: {topic}, type: PoseStamped}}\n")
    running = start_daemon(processes, "--config", str(config))
    for published in (topic, *others):
        processes.python(f"publisher{published.replace('/', '_')}", "stream_publisher.py",
                         published, rate_hz, "--count", "100000000")
    return running


def assert_clean_exit(daemon: RunningDaemon) -> None:
    """SIGINT stops the daemon with exit code 0, no traceback and nothing at ERROR level."""
    code = daemon.child.stop()
    output = daemon.child.output()
    assert code == 0, output[-3000:]
    assert "Traceback" not in output, output[-3000:]
    assert not re.search(r" (ERROR|CRITICAL) ", output), output[-3000:]


def wait_robot_described(robot: object, timeout: float = 30) -> None:
    """Until the daemon has a client robot's URDF (its describe_robot_joints answers): a
    parameter or file source may still be 'waiting' right after create_robot."""
    from protocol.commands import ErrorCode

    def described() -> bool:
        try:
            robot.joints(refresh=True)  # type: ignore[attr-defined]
        except CommandRefusedError as error:
            assert error.code == ErrorCode.UNAVAILABLE, error
            return False
        return True
    wait_until(described, timeout=timeout,
               what=f"robot {getattr(robot, 'name', '?')} loaded")


def wait_link_pose(connection: Connection, poses_device: str, link_device: str,
                   predicate: Optional[Callable[[np.ndarray], bool]] = None,
                   timeout: float = 30.0) -> np.ndarray:
    """The pose (4x4, mm) of one link, from its robot's TDATA on `poses_device` (each
    element named by the link's device): the first whose matrix `predicate` accepts."""
    from protocol.messages import TrackingData

    def pose(message: Message) -> Optional[np.ndarray]:
        if isinstance(message.body, TrackingData):
            for element in message.body.elements:
                if element.name == link_device:
                    return element.matrix
        return None

    def matches(message: Message) -> bool:
        matrix = pose(message)
        return matrix is not None and (predicate is None or predicate(matrix))
    found = pose(connection.wait_for(poses_device, matches, timeout=timeout))
    assert found is not None
    return found

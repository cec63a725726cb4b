"""The daemon says so when Fast DDS keeps a shared-memory port another process replaced
(`bridge.platform.shm_ports`). The swap itself is made for real: this process maps a port file,
which is then unlinked and made anew under the same name, and the kernel's map of this
process is read, as the daemon reads its own; a real daemon's map shows its real ports,
and a daemon logs a port replaced under it."""

from __future__ import annotations

import logging
import mmap
import os
import re
import shutil
import threading
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import pytest

from bridge.platform.shm_ports import REPORT_AFTER_S, ShmPortWatch, file_inode, replaced_ports
from support import Processes, RunningDaemon, spare_domain, wait_until


TEST_PORTS = ("fastrtps_port99991", "fastrtps_port99993", "fastrtps_port99995")


def own_maps() -> str:
    return Path("/proc/self/maps").read_text()


def make_port(path: Path) -> None:
    path.write_bytes(b"\0" * mmap.PAGESIZE)


@contextmanager
def mapped(path: Path) -> Iterator[None]:
    """`path` (made if missing) mapped by this process while the block runs."""
    if not path.exists():
        make_port(path)
    with path.open("r+b") as file, mmap.mmap(file.fileno(), 0) as mapping:
        yield
        assert mapping[0] == 0  # still mapped to the end


@pytest.fixture
def mapped_port(tmp_path: Path) -> Iterator[Path]:
    """A port file of 'fastrtps_port99991' in tmp_path, mapped as long as the test runs."""
    path = tmp_path / "fastrtps_port99991"
    with mapped(path):
        yield path


def replace(path: Path) -> int:
    """Unlink the file and make a new one of that name, as Fast DDS resets a port; the
    new file's inode."""
    path.unlink()
    make_port(path)
    return os.stat(path).st_ino


class Watched:
    """A `ShmPortWatch` on a clock the test moves, checked by the test (not started)."""

    def __init__(self) -> None:
        self.now = 1000.0
        self.watch = ShmPortWatch(clock=lambda: self.now)

    def check_after(self, seconds: float) -> list[str]:
        """The test's ports reported after `seconds` (not real ones this process may map:
        those are numbered below 65536)."""
        self.now += seconds
        return [name for name in self.watch.check(own_maps()) if name in TEST_PORTS]


def logged(caplog: pytest.LogCaptureFixture) -> list[str]:
    """What was logged about the test's ports."""
    return [r.getMessage() for r in caplog.records
            if any(port in r.getMessage() for port in TEST_PORTS)]


@pytest.fixture
def watched(caplog: pytest.LogCaptureFixture) -> Iterator[Watched]:
    with caplog.at_level(logging.ERROR, logger="bridge.platform.shm_ports"):
        yield Watched()


def test_a_port_mapped_as_it_is_is_not_replaced(mapped_port: Path) -> None:
    assert "fastrtps_port99991" in own_maps()
    assert replaced_ports(own_maps(), file_inode) == {}


def test_a_port_made_anew_under_its_name_is_replaced(mapped_port: Path) -> None:
    new_inode = replace(mapped_port)
    assert replaced_ports(own_maps(), file_inode) == {"fastrtps_port99991": new_inode}


def test_a_port_whose_file_is_gone_loses_nothing(mapped_port: Path) -> None:
    mapped_port.unlink()
    assert "fastrtps_port99991 (deleted)" in own_maps()
    assert replaced_ports(own_maps(), file_inode) == {}


def test_a_lasting_swap_is_logged_once(mapped_port: Path, watched: Watched,
                                       caplog: pytest.LogCaptureFixture) -> None:
    replace(mapped_port)
    assert watched.check_after(0) == []  # Fast DDS may still recover by itself
    assert watched.check_after(REPORT_AFTER_S - 1) == []
    assert watched.check_after(1) == ["fastrtps_port99991"]
    assert watched.check_after(60) == []  # said once
    errors = logged(caplog)
    assert len(errors) == 1
    assert "Fast DDS shared-memory port fastrtps_port99991 is lost" in errors[0]
    assert "Restart the bridge" in errors[0] and "eProsima/Fast-DDS#5053" in errors[0]


def test_a_swap_gone_before_the_deadline_is_not_logged(
        tmp_path: Path, watched: Watched, caplog: pytest.LogCaptureFixture) -> None:
    path = tmp_path / "fastrtps_port99993"
    with mapped(path):
        replace(path)
        assert watched.check_after(0) == []
    assert watched.check_after(REPORT_AFTER_S / 2) == []  # the old mapping went
    assert watched.check_after(REPORT_AFTER_S) == []
    assert logged(caplog) == []


def test_a_swap_that_ends_and_comes_back_is_logged_again(
        tmp_path: Path, watched: Watched, caplog: pytest.LogCaptureFixture) -> None:
    path = tmp_path / "fastrtps_port99995"
    for _ in range(2):
        with mapped(path):
            replace(path)
            assert watched.check_after(0) == []
            assert watched.check_after(REPORT_AFTER_S) == ["fastrtps_port99995"]
        assert watched.check_after(1) == []  # the old mapping went: it ended
    assert len(logged(caplog)) == 2


def test_the_watch_reads_a_map_on_its_thread_until_closed(
        mapped_port: Path, caplog: pytest.LogCaptureFixture) -> None:
    """Started as the daemon starts it, on this process's own map, with short periods."""
    watch = ShmPortWatch(check_interval_s=0.05, report_after_s=0.2)
    with caplog.at_level(logging.ERROR, logger="bridge.platform.shm_ports"):
        watch.start()
        try:
            replace(mapped_port)
            wait_until(lambda: bool(logged(caplog)), what="the swap to be logged")
        finally:
            watch.close()
    ours = logged(caplog)
    assert len(ours) == 1 and "port fastrtps_port99991 is lost" in ours[0]
    assert not [t for t in threading.enumerate() if t.name == "shm-port-watch"]


@pytest.mark.ros
def test_a_running_daemons_ports_are_read_and_none_is_replaced(
        daemon: RunningDaemon) -> None:
    maps = Path(f"/proc/{daemon.child.pid}/maps").read_text()
    assert "/dev/shm/fastrtps_port" in maps  # Fast DDS's same-host transport is in use
    assert replaced_ports(maps, file_inode) == {}




def daemon_ports(pid: int) -> set[str]:
    """The paths of the domain's own port segments process `pid` maps (numbered from 7400:
    the discovery ports below it are shared by every domain of the host)."""
    found = set()
    for line in Path(f"/proc/{pid}/maps").read_text().splitlines():
        number = re.search(r"/dev/shm/fastrtps_port(\d+)$", line)
        if number and int(number.group(1)) >= 7400:
            found.add(line.split()[-1])
    return found


@contextmanager
def replaced_for_a_while(path: Path) -> Iterator[None]:
    """The port made anew under its name, as Fast DDS does to one it finds abandoned, for
    the block; then its own segment is put back under the name. Nothing is left behind:
    a zeroed port file once left here made every process opening that port hang
    (Boost waits for a segment to be initialized), and a lasting copy of a live one
    could carry a lock taken at the moment it was copied."""
    aside, copy = path.with_name(path.name + ".aside"), path.with_name(path.name + ".copy")
    os.link(path, aside)  # the segment keeps a name of its own meanwhile
    try:
        shutil.copyfile(path, copy)
        os.replace(copy, path)  # the name the daemon mapped is gone: "(deleted)" in maps
        yield
    finally:
        os.replace(aside, path)


@pytest.mark.ros
def test_a_daemon_logs_a_port_replaced_under_it(processes: Processes) -> None:
    """End to end, in a spare domain with a daemon of its own (its log ends with the
    error; the module's daemon never sees the port): a ROS peer's port, which the daemon
    maps to write to it, is made anew under the daemon; the daemon's log names it."""
    env = {"ROS_DOMAIN_ID": spare_domain(1)}
    daemon = processes.bridge("run", "--port", "0", env=env)
    daemon.wait_for_output(" (OpenIGTLink); ROS node", timeout=30)
    before = daemon_ports(daemon.pid)
    peer = processes.python("peer", "param_node.py", "shm_watch_peer", env=env)
    peer.wait_for_output("READY", timeout=30)
    found: list[str] = []

    def peer_port_mapped() -> bool:
        found[:] = sorted(daemon_ports(daemon.pid) - before)
        return bool(found)

    wait_until(peer_port_mapped, timeout=30, what="the daemon to map the peer's port")
    name = Path(found[0]).name
    with replaced_for_a_while(Path(found[0])):
        line = daemon.wait_for_output(f"shared-memory port {name} is lost", timeout=40)
    assert "ERROR" in line and "Restart the bridge" in line
    # Its own segment is back under the name (the daemon maps it by the gone name).
    assert os.stat(found[0]).st_ino in {int(m.split()[4]) for m in Path(
        f"/proc/{daemon.pid}/maps").read_text().splitlines() if found[0] in m}

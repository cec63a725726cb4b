"""Fast DDS port locks a killed process left taken are found and released
(`bridge.platform.shm_locks`), on real POSIX named semaphores made here as Fast DDS makes its
own (``sem.fastrtps_port<N>_mutex``), numbered among the session's own domain's ports
where no participant of the suite reaches (another session's daemons leave them alone)."""

from __future__ import annotations

import ctypes
import ctypes.util
import fcntl
import os
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path
from typing import Iterator

import pytest

from bridge.platform.shm_locks import (ports_of_domains, release, release_stuck,
                                  remove_dead_segments, remove_unfinished, stuck_port_locks,
                                  unfinished_ports)
from support import Processes, start_daemon

pytestmark = pytest.mark.skipif(not Path("/dev/shm").is_dir(), reason="no /dev/shm here")

LIBC = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
LIBC.sem_open.restype = ctypes.c_void_p
LIBC.sem_open.argtypes = [ctypes.c_char_p, ctypes.c_int, ctypes.c_uint, ctypes.c_uint]
LIBC.sem_close.argtypes = [ctypes.c_void_p]
LIBC.sem_unlink.argtypes = [ctypes.c_char_p]
LIBC.sem_wait.argtypes = [ctypes.c_void_p]
O_CREAT = 0o100
# The last ports of the session's domain: participant ids 118-119, which nothing here has.
_DOMAIN_FIRST_PORT = 7400 + 250 * int(os.environ["ROS_DOMAIN_ID"])
PORT = _DOMAIN_FIRST_PORT + 249  # the lock's
UNFINISHED_PORT = _DOMAIN_FIRST_PORT + 247  # a segment never finished


def only_port(number: int) -> bool:
    return number == PORT


def value(name: str) -> int:
    with open(f"/dev/shm/sem.{name[1:]}", "rb") as file:
        return int(struct.unpack("<I", file.read(4))[0])


def take(name: str) -> None:
    """Take the lock and never give it back, as a process killed holding it."""
    handle = LIBC.sem_open(name.encode(), 0, 0, 0)
    assert handle and LIBC.sem_wait(handle) == 0
    LIBC.sem_close(handle)


def _segment(directory: Path, ident: str, age_s: float) -> tuple[Path, Path]:
    """A participant segment and its lock file as Fast DDS makes them, `age_s` old, the
    lock held by nobody: as a killed process leaves them."""
    segment, lock_file = directory / f"fastrtps_{ident}", directory / f"fastrtps_{ident}_el"
    segment.write_bytes(b"\1" * 1000)
    lock_file.write_bytes(b"")
    then = time.time() - age_s
    for path in (segment, lock_file):
        os.utime(path, (then, then))
    return segment, lock_file


@pytest.fixture
def lock() -> Iterator[str]:
    """A port lock made taken, as a process killed while holding it leaves it."""
    name = f"/fastrtps_port{PORT}_mutex"
    LIBC.sem_unlink(name.encode())
    handle = LIBC.sem_open(name.encode(), O_CREAT, 0o644, 0)
    assert handle, ctypes.get_errno()
    LIBC.sem_close(handle)
    yield name
    LIBC.sem_unlink(name.encode())


def test_a_lock_left_taken_is_found_and_released(lock: str) -> None:
    assert value(lock) == 0
    assert lock in stuck_port_locks(wait_s=0.2, ports=only_port)
    assert release(lock)
    assert value(lock) == 1
    assert not release(lock)  # not taken: never given back twice
    assert value(lock) == 1
    assert lock not in stuck_port_locks(wait_s=0.2, ports=only_port)  # free: not waited for


def test_a_domain_looks_after_its_own_ports_and_the_shared_ones_only(lock: str) -> None:
    """Fast DDS's domain d uses ports 7400 + 250 d onwards; those below 7400 every domain
    shares. A daemon clears what its own domain may open: another session's test lock, on
    another domain, stays as that test holds it."""
    domain = int(os.environ["ROS_DOMAIN_ID"])
    mine, other = ports_of_domains([domain]), ports_of_domains([domain + 1])
    assert mine(7000) and other(7000)  # shared
    assert mine(PORT) and not other(PORT)
    assert [mine(7400 + 250 * domain + offset) for offset in (-1, 0, 249, 250)] == \
        [domain == 0, True, True, False]
    assert lock not in release_stuck(wait_s=0.2, ports=other)
    assert value(lock) == 0
    assert lock in release_stuck(wait_s=0.2, ports=mine)


def test_a_lock_given_back_while_waited_for_is_only_busy(lock: str) -> None:
    holder = subprocess.Popen([sys.executable, "-c", f"""
import ctypes, ctypes.util, time
libc = ctypes.CDLL(ctypes.util.find_library("c"))
libc.sem_open.restype = ctypes.c_void_p
libc.sem_open.argtypes = [ctypes.c_char_p, ctypes.c_int]
libc.sem_post.argtypes = [ctypes.c_void_p]
handle = libc.sem_open({lock.encode()!r}, 0)
print("HOLDING", flush=True)
time.sleep(0.5)
libc.sem_post(handle)
"""], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "HOLDING"
        started = time.monotonic()
        assert lock not in stuck_port_locks(wait_s=10.0, ports=only_port)
        assert time.monotonic() - started < 10.0
        assert value(lock) == 1  # taken by the check for a moment, then given back
    finally:
        holder.wait(10)


def test_release_stuck_names_what_it_released(lock: str) -> None:
    assert lock in release_stuck(wait_s=0.2, ports=only_port)
    assert value(lock) == 1


def test_the_command_releases_them(lock: str) -> None:
    # The command looks at every lock, real ones too: it waits its full default time.
    dead, dead_lock = _segment(Path("/dev/shm"), "00000000000000d3", 60)
    done = subprocess.run([sys.executable, "-m", "bridge.console", "shm-unlock"],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert f"released {lock}" in done.stdout
    # A killed process's segment is anyone's to remove: another daemon of this host (another
    # test session's) may have removed it first, and then this command says nothing of it
    # (the unit tests above check who removes what, in a folder of their own).
    assert not dead.exists() and not dead_lock.exists()
    assert value(lock) == 1
    assert lock not in stuck_port_locks(wait_s=0.2, ports=only_port)


def test_a_port_segment_never_finished_is_removed_once_old(tmp_path: Path) -> None:
    """Zeroed (made, never marked initialized by Boost): every opener would wait forever.
    A finished one is kept, and so is a zeroed one still being made (too young)."""
    old_unfinished = tmp_path / "fastrtps_port99991"
    old_unfinished.write_bytes(b"\0" * 4096)
    os.utime(old_unfinished, (time.time() - 60, time.time() - 60))
    young = tmp_path / "fastrtps_port99993"
    young.write_bytes(b"\0" * 4096)
    finished = tmp_path / "fastrtps_port99995"
    finished.write_bytes(struct.pack("<I", 2) + b"\0" * 4092)
    os.utime(finished, (time.time() - 60, time.time() - 60))
    lock_file = tmp_path / "fastrtps_port99991_el"
    lock_file.write_bytes(b"")
    os.utime(lock_file, (time.time() - 60, time.time() - 60))
    assert unfinished_ports(shm_dir=tmp_path) == [old_unfinished]
    assert remove_unfinished(shm_dir=tmp_path) == [str(old_unfinished)]
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "fastrtps_port99991_el", "fastrtps_port99993", "fastrtps_port99995"]


@pytest.mark.parametrize("wait", ["0.5", "-1", "nan", "inf", "soon"])
def test_the_command_refuses_a_wait_short_enough_to_release_a_busy_lock(wait: str) -> None:
    done = subprocess.run([sys.executable, "-m", "bridge.console", "shm-unlock", "--wait",
                           wait], capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert f"expected seconds from 2 to 3600 (a lock taken for less may only be busy), " \
           f"got {wait!r}" in done.stderr


@pytest.mark.ros
def test_a_running_daemon_releases_one_and_says_so(lock: str, processes: Processes) -> None:
    """Taken before the daemon starts: released before ROS starts (or it could hang there);
    taken again while it runs: released by its watch, within its 5 s checks and 5 s wait."""
    unfinished = Path(f"/dev/shm/fastrtps_port{UNFINISHED_PORT}")  # and one never finished
    unfinished.write_bytes(b"\0" * 4096)
    os.utime(unfinished, (time.time() - 60, time.time() - 60))
    dead, _ = _segment(Path("/dev/shm"), "00000000000000d4", 60)  # and a killed one's
    try:
        running = start_daemon(processes)  # it printed its start-up lines: all are before
    finally:
        existed = unfinished.exists()
        unfinished.unlink(missing_ok=True)
    before_ros = running.child.output().split("(OpenIGTLink); ROS node")[0]
    # Gone before ROS starts: removed by this daemon (its log says so), or first by another
    # daemon of this host (a killed process's segment is anyone's to remove).
    assert not dead.exists()
    assert f"WARNING bridge.platform.shm_ports: released Fast DDS port lock {lock}" in before_ros
    assert value(lock) == 1
    assert f"removed Fast DDS port segment {unfinished}" in before_ros and not existed
    take(lock)
    running.child.wait_for_output(f"released Fast DDS port lock {lock}", timeout=60)
    assert value(lock) == 1


# ------------------------------------------------ participant segments of killed processes

def test_a_segment_whose_lock_nobody_holds_is_removed_and_a_held_or_young_one_kept(
        tmp_path: Path) -> None:
    dead, _ = _segment(tmp_path, "00000000000000d1", 60)
    held, held_lock = _segment(tmp_path, "00000000000000a1", 60)
    young, _ = _segment(tmp_path, "00000000000000b1", 0)  # its maker may lock it next
    other = tmp_path / "fastrtps_port99991_el"  # a port's lock: not a participant's
    other.write_bytes(b"")
    os.utime(other, (time.time() - 60, time.time() - 60))
    aside = tmp_path / "elsewhere"
    aside.write_bytes(b"")
    os.symlink(aside, tmp_path / "fastrtps_00000000000000c1_el")  # never followed
    holder = os.open(held_lock, os.O_RDONLY)  # another open file: as a live owner's flock
    try:
        fcntl.flock(holder, fcntl.LOCK_EX | fcntl.LOCK_NB)
        assert remove_dead_segments(shm_dir=tmp_path) == [(str(dead), 1000)]
    finally:
        os.close(holder)
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "elsewhere", "fastrtps_00000000000000a1", "fastrtps_00000000000000a1_el",
        "fastrtps_00000000000000b1", "fastrtps_00000000000000b1_el",
        "fastrtps_00000000000000c1_el", "fastrtps_port99991_el"]
    assert held.exists() and young.exists()


def _segments_of(pid: int) -> set[Path]:
    """The participant segments whose lock ``pid`` holds (/proc/locks names its inodes)."""
    inodes = {int(fields[5].split(":")[2]) for fields in
              (line.split() for line in Path("/proc/locks").read_text().splitlines())
              if fields[1] == "FLOCK" and fields[4] == str(pid)}
    return {path.with_name(path.name[:-len("_el")])
            for path in Path("/dev/shm").glob("fastrtps_" + "[0-9a-f]" * 16 + "_el")
            if path.exists() and path.stat().st_ino in inodes}


@pytest.mark.ros
def test_a_killed_ros_process_segment_is_removed_and_a_live_ones_kept(
        processes: Processes) -> None:
    killed = processes.python("killed", "stream_publisher.py", "/shm_dead", "10")
    live = processes.python("live", "stream_publisher.py", "/shm_live", "10")
    for child in (killed, live):
        child.wait_for_output("READY")
    theirs = {child.name: _segments_of(child.pid) for child in (killed, live)}
    assert all(len(found) == 1 for found in theirs.values()), theirs
    (dead,), (kept,) = theirs["killed"], theirs["live"]
    killed.stop(signal.SIGKILL)
    assert dead.exists()  # Fast DDS leaves it: nobody removes it after a kill
    removed = dict(remove_dead_segments(min_age_s=0))
    assert removed.get(str(dead), 0) > 0, removed
    assert not dead.exists() and not dead.with_name(dead.name + "_el").exists()
    assert kept.exists() and str(kept) not in removed

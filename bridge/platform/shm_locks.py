"""Finds and releases Fast DDS shared-memory port locks that a killed process left taken.

Fast DDS guards each shared-memory port (``/dev/shm/fastrtps_port<N>``) with a named
POSIX semaphore used as a mutex (``/dev/shm/sem.fastrtps_port<N>_mutex``), held while a
process opens the port, up to its one-second health check. It is not robust: a process
killed while holding it (kill -9, a crash) leaves it taken for good, and every later
process that opens that port waits forever: a ROS node, or the bridge, hangs at start-up
or the first time it writes to a peer on that port. With ROS_AUTOMATIC_DISCOVERY_RANGE=
LOCALHOST the discovery ports are shared by every domain of the host.

A lock is judged left behind when it stays taken for `STUCK_AFTER_S`, far longer than
Fast DDS holds one. Linux only (elsewhere nothing is found).

A process only opens the ports of its own ROS domain and those below every domain's
(`ports_of_domains`): a daemon looks after those alone, and leaves another domain's
ports to the processes on it (a test there may hold one on purpose).

A port segment can be left unfinished too: made, but its Boost header never marked
initialized (a process killed between the two, or any file put there). Every process that
opens it waits for that mark forever, holding the port's lock. One older than
`STUCK_AFTER_S` is removed; the next process to need the port makes it anew.

Each participant's own segment (``/dev/shm/fastrtps_<16 hex>``, 0.5 MB by default, what it
writes into) is removed by Fast DDS when the participant is destroyed, never after a kill:
on a host where ROS processes get killed they pile up in RAM (795, 440 MB, on the project's
test machine). Its owner holds an flock on ``<segment>_el`` while it lives, so one whose
lock can be taken is dead, as `fastdds shm clean` judges it.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import fcntl
import os
import re
import stat
import struct
import time
from pathlib import Path
from typing import Callable, Iterable, Optional

__all__ = ["MAX_STUCK_AFTER_S", "MIN_STUCK_AFTER_S", "PortFilter", "STUCK_AFTER_S",
           "every_port", "ports_of_domains", "release", "release_stuck",
           "remove_dead_segments", "remove_unfinished", "stuck_port_locks", "unfinished_ports"]

SHM_DIR = Path("/dev/shm")
STUCK_AFTER_S = 5.0
# Fast DDS holds a lock up to about a second (its health check): a shorter wait could
# release one that is only busy.
MIN_STUCK_AFTER_S = 2.0
MAX_STUCK_AFTER_S = 3600.0

PortFilter = Callable[[int], bool]
# The RTPS well-known ports (DDSI-RTPS 9.6.1.1): domain d's are PB + DG * d onwards, DG each.
_PORT_BASE = 7400
_DOMAIN_GAIN = 250


def every_port(port: int) -> bool:
    return True


def ports_of_domains(domains: Iterable[int]) -> PortFilter:
    """The ports a process on one of `domains` may open: theirs, and those below every
    domain's (shared by all of them)."""
    chosen = frozenset(domains)

    def opened_there(port: int) -> bool:
        return port < _PORT_BASE or (port - _PORT_BASE) // _DOMAIN_GAIN in chosen
    return opened_there


def _port_number(name: str, prefix: str, suffix: str = "") -> Optional[int]:
    """N of `<prefix>N<suffix>`, or None for another name (a segment's lock files)."""
    digits = name[len(prefix):len(name) - len(suffix)]
    return int(digits) if name.startswith(prefix) and name.endswith(suffix) \
        and digits.isdigit() else None


class _Timespec(ctypes.Structure):
    _fields_ = [("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long)]


def _libc() -> Optional[ctypes.CDLL]:
    name = ctypes.util.find_library("c")
    if name is None or not SHM_DIR.is_dir():
        return None
    libc = ctypes.CDLL(name, use_errno=True)
    libc.sem_open.restype = ctypes.c_void_p
    libc.sem_open.argtypes = [ctypes.c_char_p, ctypes.c_int]
    for function in (libc.sem_post, libc.sem_close):
        function.argtypes = [ctypes.c_void_p]
    libc.sem_timedwait.argtypes = [ctypes.c_void_p, ctypes.POINTER(_Timespec)]
    return libc


def _taken_now(path: Path) -> bool:
    """A glibc semaphore's value is its first 32-bit word: 0 is a taken mutex."""
    try:
        with path.open("rb") as file:
            head = file.read(4)
    except OSError:
        return False
    return len(head) == 4 and struct.unpack("<I", head)[0] == 0


def _semaphore_name(path: Path) -> bytes:
    return b"/" + path.name[len("sem."):].encode()


def _port_locks(shm_dir: Path, ports: PortFilter) -> list[Path]:
    found = []
    for path in sorted(shm_dir.glob("sem.fastrtps_port*_mutex")):
        number = _port_number(path.name, "sem.fastrtps_port", "_mutex")
        if number is not None and ports(number):
            found.append(path)
    return found


def stuck_port_locks(wait_s: float = STUCK_AFTER_S, shm_dir: Path = SHM_DIR,
                     ports: PortFilter = every_port) -> list[str]:
    """The port locks (semaphore names, as '/fastrtps_port7005_mutex') taken now and
    still taken after `wait_s` seconds, of the port numbers `ports` accepts.
    Each one that comes free is given back at once; several are waited for together."""
    libc = _libc()
    if libc is None:
        return []
    candidates = [path for path in _port_locks(shm_dir, ports) if _taken_now(path)]
    if not candidates:
        return []
    deadline = time.time() + wait_s
    stuck: list[str] = []
    for path in candidates:
        handle = libc.sem_open(_semaphore_name(path), 0)
        if not handle or handle == ctypes.c_void_p(-1).value:  # SEM_FAILED: gone meanwhile
            continue
        try:
            until = _Timespec(int(deadline), int((deadline % 1) * 1e9))
            if libc.sem_timedwait(handle, ctypes.byref(until)) == 0:
                libc.sem_post(handle)  # it was only busy: give it back
            else:
                stuck.append(_semaphore_name(path).decode())
        finally:
            libc.sem_close(handle)
    return stuck


def release(name: str, shm_dir: Path = SHM_DIR) -> bool:
    """Give back a lock `stuck_port_locks` named; False if it no longer exists or is no
    longer taken (another process released it meanwhile: giving it back twice would
    let two processes in at once)."""
    libc = _libc()
    if libc is None or not _taken_now(shm_dir / f"sem.{name.lstrip('/')}"):
        return False
    handle = libc.sem_open(name.encode(), 0)
    if not handle or handle == ctypes.c_void_p(-1).value:
        return False
    try:
        return bool(libc.sem_post(handle) == 0)
    finally:
        libc.sem_close(handle)


def release_stuck(wait_s: float = STUCK_AFTER_S, shm_dir: Path = SHM_DIR,
                  ports: PortFilter = every_port) -> list[str]:
    """Release every port lock left taken; the names released."""
    return [name for name in stuck_port_locks(wait_s, shm_dir, ports)
            if release(name, shm_dir)]


_INITIALIZED = 2  # Boost's mark in a managed segment's first word, once it is usable


def unfinished_ports(min_age_s: float = STUCK_AFTER_S, shm_dir: Path = SHM_DIR,
                     ports: PortFilter = every_port) -> list[Path]:
    """Port segments never marked initialized, last changed `min_age_s` or more ago."""
    found: list[Path] = []
    now = time.time()
    for path in sorted(shm_dir.glob("fastrtps_port*")):
        number = _port_number(path.name, "fastrtps_port")
        if number is None or not ports(number):
            continue  # its lock files (_el, _sl), or another domain's
        try:
            with path.open("rb") as file:
                head = file.read(4)
            changed = path.stat().st_mtime
        except OSError:
            continue
        mark = struct.unpack("<I", head)[0] if len(head) == 4 else 0
        if mark != _INITIALIZED and now - changed >= min_age_s:
            found.append(path)
    return found


def remove_unfinished(min_age_s: float = STUCK_AFTER_S, shm_dir: Path = SHM_DIR,
                      ports: PortFilter = every_port) -> list[str]:
    """Remove the unfinished port segments; the paths removed."""
    removed: list[str] = []
    for path in unfinished_ports(min_age_s, shm_dir, ports):
        try:
            path.unlink()
        except OSError:
            continue
        removed.append(str(path))
    return removed


_SEGMENT_LOCK = re.compile(r"fastrtps_[0-9a-f]{16}_el")  # a participant segment's lock file


def remove_dead_segments(min_age_s: float = STUCK_AFTER_S,
                         shm_dir: Path = SHM_DIR) -> list[tuple[str, int]]:
    """Remove the participant segments whose process is gone (their lock file can be
    locked), each with its lock file; (segment path, bytes) of each removed. A lock file
    younger than `min_age_s` is left: its maker may not have locked it yet. Our lock is
    held while both go, so a process that picks the same name meanwhile cannot take it."""
    removed: list[tuple[str, int]] = []
    now = time.time()
    try:
        names = os.listdir(shm_dir)
    except OSError:
        return removed
    for name in names:
        if not _SEGMENT_LOCK.fullmatch(name):
            continue
        segment = shm_dir / name[:-len("_el")]
        try:
            fd = os.open(shm_dir / name, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC)
        except OSError:
            continue
        try:
            info = os.fstat(fd)
            if not stat.S_ISREG(info.st_mode) or now - info.st_mtime < min_age_s:
                continue
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                continue  # held: its process lives
            try:
                size = segment.lstat().st_size
                segment.unlink()
            except FileNotFoundError:
                size = 0
            except OSError:
                continue  # not ours to remove (another user's, in the sticky /dev/shm)
            try:
                (shm_dir / name).unlink()
            except OSError:
                pass
            removed.append((str(segment), size))
        finally:
            os.close(fd)
    return removed

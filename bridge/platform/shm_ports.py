"""Says so when ROS data between the daemon and a process on this host is silently lost in
Fast DDS shared memory.

Fast DDS passes same-host ROS traffic through shared-memory "ports", one segment per
listening participant (``/dev/shm/fastrtps_port<N>``, N from the domain and participant
id). A process that dies while closing leaves its port behind; the next process given
that participant id finds it abandoned and makes the port anew. Fast DDS 2.14 in a
process that was writing to the old port can go on writing into it, unlinked, forever:
nothing it sends reaches the newcomer, nor any later process with that id
(eProsima/Fast-DDS#5053). The daemon lives long and talks to every ROS process of the
host, so it is the one left talking to a dead segment, and nothing in ROS says so.

It shows in the daemon's own memory map: a port segment mapped only in versions that are
no longer the file of that name, while the file exists. Fast DDS recovers from most such
swaps by itself within its health check (about a second), so a swap is reported only
when it outlasts `REPORT_AFTER_S`. The check runs every `CHECK_INTERVAL_S` on a thread
of its own (0.7 ms to read and sift the 1,161 lines of a running daemon's map).

The same thread releases the port locks a killed process left taken (`shm_locks`), which
would hang the daemon the first time it writes to a peer on that port.
"""

from __future__ import annotations

import logging
import os
import re
import threading
import time
from pathlib import Path
from typing import Callable, Optional

from bridge.core.threads import OnFailure, start_thread
from bridge.platform.shm_locks import (PortFilter, every_port, release_stuck, remove_dead_segments,
                                  remove_unfinished)

__all__ = ["CHECK_INTERVAL_S", "REPORT_AFTER_S", "ShmPortWatch", "file_inode",
           "release_left_locks", "replaced_ports"]

log = logging.getLogger(__name__)

MAPS = Path("/proc/self/maps")
CHECK_INTERVAL_S = 5.0
REPORT_AFTER_S = 10.0
# "address perms offset dev inode path": the path may end with " (deleted)".
_MAPPING = re.compile(r"^\S+ \S+ \S+ \S+ (\d+)\s+(.*?/(fastrtps_port\d+))(?: \(deleted\))?$")


def replaced_ports(maps: str, live_inode: Callable[[str], Optional[int]]) -> dict[str, int]:
    """The port segments `maps` (a /proc/<pid>/maps text) holds only in replaced versions:
    port name → the inode of the file that now bears its name (`live_inode` of the mapped
    path; None when there is no such file, and then nothing is lost)."""
    mapped: dict[str, set[int]] = {}
    paths: dict[str, str] = {}
    for line in maps.splitlines():
        if "fastrtps_port" not in line:  # most lines: a plain test, not the expression
            continue
        found = _MAPPING.match(line)
        if found:
            inode, path, name = int(found.group(1)), found.group(2), found.group(3)
            mapped.setdefault(name, set()).add(inode)
            paths[name] = path
    replaced: dict[str, int] = {}
    for name, inodes in mapped.items():
        live = live_inode(paths[name])
        if live is not None and live not in inodes:
            replaced[name] = live
    return replaced


def file_inode(path: str) -> Optional[int]:
    try:
        return os.stat(path).st_ino
    except OSError:
        return None


class ShmPortWatch:
    """Checks the daemon's map now and then, on a thread of its own (reading the map is
    kernel work the loop need not wait for); logs each lasting swap once (an error, with
    the port and what to do)."""

    def __init__(self, *, maps: Path = MAPS, clock: Callable[[], float] = time.monotonic,
                 check_interval_s: float = CHECK_INTERVAL_S,
                 report_after_s: float = REPORT_AFTER_S,
                 lock_ports: PortFilter = every_port) -> None:
        """`lock_ports`: the ports whose left locks and segments it clears (its domain's)."""
        self._maps = maps
        self._lock_ports = lock_ports
        self._clock = clock
        self._check_interval_s = check_interval_s
        self._report_after_s = report_after_s
        self._seen: dict[tuple[str, int], float] = {}  # (port, live inode) → first seen
        self._reported: set[tuple[str, int]] = set()
        self._closed = threading.Event()
        self._thread: Optional[threading.Thread] = None

    def start(self) -> None:
        if self._maps.exists():  # Linux; elsewhere there is nothing to read
            # A failure (out of descriptors while releasing a lock) is logged, and the
            # watch goes on at its next turn.
            self._thread = start_thread("shm-port-watch", self._run, OnFailure.RESTART)

    def close(self) -> None:
        self._closed.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None

    def _run(self) -> None:
        while not self._closed.wait(self._check_interval_s):
            try:
                self.check(self._maps.read_text(errors="replace"))
            except OSError as error:
                log.debug("cannot read %s: %s", self._maps, error)
            release_left_locks(self._lock_ports)  # this thread waits on a taken one

    def check(self, maps: str) -> list[str]:
        """Note what `maps` shows now; return the ports reported by this call."""
        now = self._clock()
        current = {(name, live) for name, live in replaced_ports(maps, file_inode).items()}
        self._seen = {key: self._seen.get(key, now) for key in current}
        self._reported &= current  # a swap that ended and comes back is said again
        reported: list[str] = []
        for key, since in self._seen.items():
            if now - since >= self._report_after_s and key not in self._reported:
                self._reported.add(key)
                reported.append(key[0])
                log.error(
                    "ROS data between this bridge and the process now using Fast DDS "
                    "shared-memory port %s is lost: that process made the port anew (an "
                    "earlier one with its participant id died while closing) and Fast DDS "
                    "here still uses the old one (eProsima/Fast-DDS#5053). Restart the "
                    "bridge to reach that process again; stopping ROS processes with one "
                    "signal and letting them finish avoids it.", key[0])
        return reported


def release_left_locks(ports: PortFilter) -> None:
    """Remove the unfinished Fast DDS port segments and release the port locks a killed
    process left taken (`shm_locks`), of `ports`: the daemon would hang on one the first
    time it writes to a peer on that port. Remove the segments of killed processes too
    (any: their owner is surely gone, and they hold RAM)."""
    for path in remove_unfinished(ports=ports):
        log.warning("removed Fast DDS port segment %s: it was never finished (a process "
                    "killed while making it), and every process opening it hung", path)
    for name in release_stuck(ports=ports):
        log.warning("released Fast DDS port lock %s: a ROS process killed while opening "
                    "that port had left it taken, and every process opening the port "
                    "hung on it", name)
    dead = remove_dead_segments()
    if dead:
        log.info("removed %d Fast DDS shared-memory segment(s) of killed processes (%.1f MB "
                 "of RAM)", len(dead), sum(size for _, size in dead) / 1e6)

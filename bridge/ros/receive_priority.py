"""Real-time priority for the daemon's DDS receive threads (`--receive-priority`).

Fast DDS hands a message to each reader on the same host through the publisher's own
shared-memory segment, 0.5 MB unless the publisher configures more. A larger message (a
VGA rgb8 image is 0.9 MB) overwrites its first fragments while the publisher writes the
last ones, so a reader whose receive thread is not on a CPU at that moment loses them and
gets the message only after a resend, about 10 ms later. Which reader that is, the daemon
or another subscriber, is a race the scheduler decides (bench/bench_daemon.py's image
phase: two plain subscribers lose it to each other too).

Under SCHED_FIFO the daemon's receive threads run the moment a fragment comes, ahead of
every ordinary thread of the host, so the daemon is not the reader that waits. The threads
block when nothing comes, but a ROS peer that floods the daemon then takes up to a core at
that priority (Linux keeps 5% of each second for ordinary threads). It needs CAP_SYS_NICE
or an rtprio limit (`ulimit -r`) at least that high.
"""

from __future__ import annotations

import os
import re
import resource
from pathlib import Path

__all__ = ["MAX_PRIORITY", "MIN_PRIORITY", "ReceivePriorityError", "allowed",
           "raise_receive_threads", "receive_threads"]

MIN_PRIORITY = 1
MAX_PRIORITY = 99
# Fast DDS 2.14 names a transport's receive thread after its port ("dds.shm.7002",
# "dds.udp.7412"); its shared-memory watchdog ("dds.shm.wdog") is not one.
_RECEIVE_THREAD = re.compile(r"dds\.(shm|udp|tcp)\.\d+")
_CAP_SYS_NICE = 23


class ReceivePriorityError(Exception):
    """The system refused the priority; says what it needs."""


def receive_threads() -> dict[int, str]:
    """This process's DDS receive threads: thread id → name."""
    found: dict[int, str] = {}
    for task in Path("/proc/self/task").iterdir():
        try:
            name = (task / "comm").read_text().strip()
        except OSError:  # ended meanwhile
            continue
        if _RECEIVE_THREAD.fullmatch(name):
            found[int(task.name)] = name
    return found


def raise_receive_threads(priority: int) -> list[str]:
    """Put every DDS receive thread of this process under SCHED_FIFO at ``priority``; the
    names of those set. ReceivePriorityError when the system does not allow it, or none
    is found (the middleware is not Fast DDS, or names its threads otherwise)."""
    if not MIN_PRIORITY <= priority <= MAX_PRIORITY:
        raise ValueError(f"priority: expected {MIN_PRIORITY} to {MAX_PRIORITY}, got {priority}")
    threads = receive_threads()
    if not threads:
        raise ReceivePriorityError("--receive-priority: no DDS receive thread found (expected "
                                   "Fast DDS's dds.shm.<port> and dds.udp.<port> threads)")
    done: list[str] = []
    for tid, name in sorted(threads.items()):
        try:
            os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(priority))
        except ProcessLookupError:
            continue
        except PermissionError:
            raise ReceivePriorityError(
                f"--receive-priority {priority}: the system refused SCHED_FIFO priority "
                f"{priority} (expected CAP_SYS_NICE, or an rtprio limit of at least {priority}"
                f": `ulimit -r` says {_rtprio_limit()}; see /etc/security/limits.conf, or "
                f"docker run --cap-add SYS_NICE)") from None
        done.append(name)
    return done


def allowed(priority: int) -> bool:
    """Whether this process may set SCHED_FIFO ``priority`` (CAP_SYS_NICE, or the rtprio
    limit), as the kernel judges it."""
    soft, _ = resource.getrlimit(resource.RLIMIT_RTPRIO)
    if soft == resource.RLIM_INFINITY or soft >= priority:
        return True
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("CapEff:"):
            return bool(int(line.split()[1], 16) >> _CAP_SYS_NICE & 1)
    return False


def _rtprio_limit() -> str:
    soft, _ = resource.getrlimit(resource.RLIMIT_RTPRIO)
    return "unlimited" if soft == resource.RLIM_INFINITY else str(soft)

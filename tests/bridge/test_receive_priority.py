"""How the daemon's DDS receive threads are scheduled (bridge/platform/receive_priority.py),
read back from the kernel: a short slice by default, SCHED_FIFO with `--receive-priority`,
which is refused in one line where the system does not allow it. What each buys (a pose on
a busy machine, a VGA image without Fast DDS's resend) is measured by
bench/bench_daemon.py (`--busy 2`, the image phase), not here."""

from __future__ import annotations

import os
import platform
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from bridge.platform.receive_priority import RECEIVE_SLICE_NS, allowed, thread_slice_ns
from support import REPO, Processes, assert_clean_exit, start_daemon

PRIORITY = 10
RECEIVE_THREAD = re.compile(r"dds\.(shm|udp)\.\d+")


def _kernel_at_least(major: int, minor: int) -> bool:
    found = re.match(r"(\d+)\.(\d+)", platform.release())
    return found is not None and (int(found.group(1)), int(found.group(2))) >= (major, minor)


# An ordinary thread's own scheduler slice (what the receive threads ask for).
OWN_SLICES = pytest.mark.skipif(
    not _kernel_at_least(6, 12),
    reason=f"an ordinary thread's own slice needs Linux 6.12 or later, this is "
           f"{platform.release()}")


def _threads(pid: int) -> dict[str, tuple[int, int]]:
    """Each thread's name → (scheduling policy, real-time priority)."""
    found = {}
    for task in Path(f"/proc/{pid}/task").iterdir():
        tid = int(task.name)
        found[(task / "comm").read_text().strip()] = (os.sched_getscheduler(tid),
                                                     os.sched_getparam(tid).sched_priority)
    return found


@pytest.mark.ros
@pytest.mark.skipif(not allowed(PRIORITY),
                    reason=f"SCHED_FIFO {PRIORITY} needs root, CAP_SYS_NICE or `ulimit -r` "
                           f">= {PRIORITY} here")
def test_the_receive_threads_run_under_sched_fifo_and_the_rest_as_before(
        processes: Processes) -> None:
    running = start_daemon(processes, "--receive-priority", str(PRIORITY))
    threads = _threads(running.child.pid)
    receive = {name: policy for name, policy in threads.items()
               if RECEIVE_THREAD.fullmatch(name)}
    assert any(name.startswith("dds.shm.") for name in receive), threads
    assert set(receive.values()) == {(os.SCHED_FIFO, PRIORITY)}, threads
    others = {policy for name, policy in threads.items() if name not in receive}
    assert others == {(os.SCHED_OTHER, 0)}, threads
    said = re.search(r"DDS receive threads under SCHED_FIFO at priority 10: (.*)",
                     running.child.output())
    assert said and set(said.group(1).split(", ")) == set(receive), running.child.output()
    assert_clean_exit(running)


@pytest.mark.ros
@OWN_SLICES
def test_by_default_the_receive_threads_ask_for_a_short_slice_and_the_rest_keep_theirs(
        processes: Processes) -> None:
    running = start_daemon(processes)
    slices = {}
    for task in Path(f"/proc/{running.child.pid}/task").iterdir():
        slices.setdefault((task / "comm").read_text().strip(), set()).add(
            thread_slice_ns(int(task.name)))
    receive = {name: got for name, got in slices.items() if RECEIVE_THREAD.fullmatch(name)}
    assert any(name.startswith("dds.shm.") for name in receive), slices
    assert set().union(*receive.values()) == {RECEIVE_SLICE_NS}, slices
    others = set().union(*(got for name, got in slices.items() if name not in receive))
    assert others and RECEIVE_SLICE_NS not in others, slices
    said = re.search(r"DDS receive threads on a 0\.1 ms scheduler slice: (.*)",
                     running.child.output())
    assert said and set(said.group(1).split(", ")) == set(receive), running.child.output()
    assert_clean_exit(running)


@pytest.mark.ros
@OWN_SLICES
def test_without_the_workarounds_the_threads_keep_the_kernels_slice_and_the_log_says_so(
        processes: Processes) -> None:
    """`--without`, to weigh a host workaround (bridge/platform/README.md): left out, the
    receive threads keep the usual slice, and the start-up log names what was left out."""
    running = start_daemon(processes, "--without", "receive-slice", "--without", "collector",
                           "--without", "gil-switch", "--without", "mmap-threshold")
    receive = {thread_slice_ns(int(task.name))
               for task in Path(f"/proc/{running.child.pid}/task").iterdir()
               if RECEIVE_THREAD.fullmatch((task / "comm").read_text().strip())}
    assert receive and RECEIVE_SLICE_NS not in receive, receive
    output = running.child.output()
    assert "DDS receive threads on the kernel's usual slice (--without receive-slice)" in output
    assert ("host workarounds left out (--without): collector, gil-switch, mmap-threshold, "
            "receive-slice") in output
    assert_clean_exit(running)


def test_a_workaround_the_daemon_does_not_have_is_refused_with_the_list() -> None:
    done = subprocess.run([sys.executable, "-m", "bridge.console", "run", "--without",
                           "turbo"], capture_output=True, text=True, timeout=60, cwd=REPO)
    assert done.returncode == 2
    assert ("argument --without: invalid choice: 'turbo' (choose from 'receive-slice', "
            "'gil-switch', 'collector', 'mmap-threshold')") in done.stderr


@pytest.mark.ros
@pytest.mark.skipif(not (shutil.which("setpriv") and shutil.which("prlimit")),
                    reason="needs util-linux's setpriv and prlimit to take the right away")
def test_where_the_system_refuses_the_daemon_says_what_it_needs_in_one_line() -> None:
    done = subprocess.run(["setpriv", "--bounding-set", "-sys_nice", "prlimit", "--rtprio=0",
                           "--", sys.executable, "-m", "bridge.console", "run", "--port", "0",
                           "--receive-priority", str(PRIORITY)],
                          capture_output=True, text=True, timeout=120, cwd=REPO)
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip().splitlines()[-1] == (
        f"slicer-ros2-bridge: --receive-priority {PRIORITY}: the system refused SCHED_FIFO "
        f"priority {PRIORITY} (expected CAP_SYS_NICE, or an rtprio limit of at least "
        f"{PRIORITY}: `ulimit -r` says 0; see /etc/security/limits.conf, or docker run "
        f"--cap-add SYS_NICE)")
    assert "Traceback" not in done.stderr


@pytest.mark.parametrize("given", ["0", "100", "-5", "ten", "1.5"])
def test_a_priority_out_of_range_is_refused(given: str) -> None:
    done = subprocess.run([sys.executable, "-m", "bridge.console", "run", "--receive-priority",
                           given], capture_output=True, text=True, timeout=60, cwd=REPO)
    assert done.returncode == 2
    assert (f"argument --receive-priority: expected a SCHED_FIFO priority from 1 to 99, got "
            f"{given!r}") in done.stderr

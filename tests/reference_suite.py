"""The `ros2` command as SlicerROS2's unit tests (its Testing/Python/ROS2Tests.py) run it:
their shell line around tools/reference_suite/ros2_cli.py, and their way of stopping a node
(SIGTERM to its process group). The suite's cases themselves run in a real Slicer scene
(tests/slicer_real/test_reference_in_slicer.py; the file as it is: tools/reference_suite/run.py)."""

from __future__ import annotations

import os
import shlex
import signal
import subprocess
from pathlib import Path

import pytest

from support import REPO, Child, scaled, wait_until

SUITE = REPO / "tools" / "reference_suite"
SYSTEM_PYTHON = Path("/usr/bin/python3")


def as_the_suite(command: str) -> str:
    """The shell line SlicerROS2's ROS2Tests.py builds around a ros2 command."""
    if not SYSTEM_PYTHON.exists():
        pytest.skip(f"needs {SYSTEM_PYTHON} (the suite's interpreter, without ROS)")
    return (f"unset PYTHONHOME ; unset PYTHONPATH ; . {shlex.quote(str(SUITE / 'setup.sh'))} ; "
            f"{SYSTEM_PYTHON} {shlex.quote(str(SUITE / 'ros2_cli.py'))} {command}")


def ros2(command: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(as_the_suite(command), shell=True, capture_output=True, text=True,
                          timeout=scaled(30), start_new_session=True)


def group_members(pgid: int) -> list[int]:
    """The live (not zombie) processes of process group `pgid`, read from /proc."""
    members = []
    for entry in filter(str.isdigit, os.listdir("/proc")):
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rfind(")") + 2:].split()
        if int(fields[2]) == pgid and fields[0] != "Z":
            members.append(int(entry))
    return members


def stop_group(child: Child) -> int:
    """SIGTERM to the process group, as the suite's kill_subprocess, then wait until every
    process of it has ended (the suite sleeps 1 s for that); the shell's exit code. The
    shell ends at once, the node it started on its own: until then `ros2 node list` still
    lists it (ci64)."""
    if child.popen.poll() is None:
        os.killpg(child.pid, signal.SIGTERM)
    code = child.popen.wait(scaled(10))
    try:
        wait_until(lambda: not group_members(child.pid), what="the process group to end")
    except AssertionError as error:
        raise AssertionError(f"{error}; still running: {group_members(child.pid)}; the "
                             f"node's output: {child.output()[-2000:]!r}") from None
    return code

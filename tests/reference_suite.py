"""What the reference suite's cases need, written for this project: a stand-in for 3D
Slicer's ``slicer`` module with the reference's two entry points installed
(`slicer_client.reference.entry_points`), and the suite's helpers, made to wait on what
they wait for instead of a fixed 100 ms (the suite must pass on a busy machine)."""

from __future__ import annotations

import os
import shlex
import signal
import subprocess
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any, Callable

import pytest

from slicer_client.reference.entry_points import install
from support import REPO, Child, scaled, wait_until


class _Scene:
    """3D Slicer's scene, as far as a script for the reference touches it."""

    def AddNewNodeByClass(self, class_name: str, *args: Any) -> Any:  # noqa: N802
        raise AssertionError(f"the stand-in scene makes no {class_name}")


class _Util:
    def getModuleLogic(self, module: str) -> Any:  # noqa: N802
        raise RuntimeError(f"Could not find module with name '{module}'")  # as Slicer's


def slicer_standin(logic: Any) -> SimpleNamespace:
    """A ``slicer`` module whose entry points lead to `logic`, as in 3D Slicer with the
    ROS2Bridge module and without SlicerROS2."""
    slicer = SimpleNamespace(util=_Util(), mrmlScene=_Scene(),
                             vtkMRMLTransformNode=SimpleNamespace(TransformModifiedEvent=15000))
    assert install(slicer, logic)
    return slicer


def spin_some(slicer: SimpleNamespace) -> None:
    """The reference's helper: ten spins, 10 ms apart."""
    ros2_logic = slicer.util.getModuleLogic("ROS2")
    for _ in range(10):
        time.sleep(0.01)
        ros2_logic.Spin()


def spin_until(slicer: SimpleNamespace, predicate: Callable[[], bool], what: str,
               timeout: float = 20.0) -> None:
    """Spin as the reference does until `predicate` holds (what it expects after its 100 ms
    of spins), then spin that much more: an extra notification would show up then."""
    deadline = time.monotonic() + scaled(timeout)
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"spun for {scaled(timeout)} s without {what}")
        spin_some(slicer)
    spin_some(slicer)


class TestObserverSubscriber:
    """The reference's subscriber observer: it reads the message in its callback."""

    __test__ = False  # a helper, not a pytest class


    def __init__(self) -> None:
        self.lastMessageYAML = ""
        self.counter = 0

    def Callback(self, caller: Any, event: Any) -> None:  # noqa: N802
        self.lastMessageYAML = caller.GetLastMessageYAML()
        self.counter += 1


class TestObserverTf2Lookup:
    __test__ = False

    def __init__(self, vtk: Any) -> None:
        self.vtk = vtk
        self.counter = 0
        self.lastTransform = None

    def Callback(self, caller: Any, event: Any) -> None:  # noqa: N802
        self.counter += 1
        self.lastTransform = self.vtk.vtkMatrix4x4()
        caller.GetMatrixTransformToParent(self.lastTransform)


# --- the ros2 command as the suite runs it (tools/reference_suite/ros2_cli.py) -----------
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

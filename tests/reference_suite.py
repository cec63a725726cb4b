"""What the reference suite's cases need, written for this project: a stand-in for 3D
Slicer's ``slicer`` module with the reference's two entry points installed
(`slicer_client.reference.entry_points`), and the suite's helpers, made to wait on what
they wait for instead of a fixed 100 ms (the suite must pass on a busy machine)."""

from __future__ import annotations

import time
from types import SimpleNamespace
from typing import Any, Callable

from slicer_client.reference.entry_points import install
from support import scaled


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

"""Helpers of the scene scripts (run in the real Slicer core's Python, never by pytest)."""

from __future__ import annotations

from typing import Any, Callable

import slicer
import vtk


def connect(session: Any, port: int) -> Any:
    """What the user does: Connect in the module (its logic), then wait for the client."""
    logic = session.logic
    logic.connect("127.0.0.1", int(port))
    session.pump(30, until=lambda: logic.client is not None, what="the module's client")
    return logic


def nodes(session: Any, cls: str, **attributes: str) -> list[Any]:
    """The scene's nodes of `cls` whose OpenIGTLink.ros2.<key> attributes match."""
    scene = session.scene
    found = [scene.GetNthNodeByClass(i, cls) for i in range(scene.GetNumberOfNodesByClass(cls))]
    return [n for n in found if all(n.GetAttribute(f"OpenIGTLink.ros2.{k}") == v
                                    for k, v in attributes.items())]


def matrix(node: Any) -> list[list[float]]:
    m = vtk.vtkMatrix4x4()
    node.GetMatrixTransformToParent(m)
    return [[m.GetElement(i, j) for j in range(4)] for i in range(4)]


def world_matrix(node: Any) -> list[list[float]]:
    m = vtk.vtkMatrix4x4()
    node.GetMatrixTransformToWorld(m)
    return [[m.GetElement(i, j) for j in range(4)] for i in range(4)]


def folder_path(node: Any) -> list[str]:
    """The subject-hierarchy folders above a node, innermost first."""
    sh = slicer.vtkMRMLSubjectHierarchyNode.GetSubjectHierarchyNode(node.GetScene())
    item = sh.GetItemByDataNode(node)
    names = []
    parent = sh.GetItemParent(item) if item else 0
    while parent and parent != sh.GetSceneItemID():
        names.append(sh.GetItemName(parent))
        parent = sh.GetItemParent(parent)
    return names


def repeat_until_told(session: Any, flag: str, action: Any, *, every: float = 0.5,
                      timeout: float = 60.0) -> int:
    """Run `action()` every `every` s (Slicer's event loop in between) until the test
    creates the file `flag` (it saw the result: ROS discovery makes the first sends miss);
    how many times it ran."""
    import os
    import time
    count = 0
    deadline = time.monotonic() + timeout * float(
        os.environ.get("SLICER_BRIDGE_TEST_TIME_SCALE", "1"))
    while not os.path.exists(flag):
        if time.monotonic() > deadline:
            raise AssertionError(f"the test did not say it saw the result ({flag})")
        action()
        count += 1
        session.pump(every)
    return count


def error_of(call: Callable[[], Any]) -> str:
    """What `call()` raised, as "TypeName: message" ("" if nothing): tests assert on it."""
    try:
        call()
    except Exception as error:  # noqa: BLE001 - returned for the test to judge
        return f"{type(error).__name__}: {error}"
    return ""

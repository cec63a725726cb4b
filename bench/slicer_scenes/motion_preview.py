"""The Motion section's preview while a target is dragged, in a real Slicer scene (run by
bench/bench_motion_preview.py with the Slicer peer's Python): the ROS2Bridge module
connected to the demo, its robot placed, a transform node as the target of the flange,
Follow on; the target is moved every display frame (60 Hz) on a 30 mm circle for the given
seconds, as a drag does, while Slicer's event loop runs in between. Returns how often the
preview was solved again, each solve's time (the daemon's IK and the preview's update, on
Slicer's main thread), and how far behind the newest target the preview was at each frame."""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
import vtk

FRAME_S = 1 / 60


def _world(node: Any) -> np.ndarray:
    m = vtk.vtkMatrix4x4()
    node.GetMatrixTransformToWorld(m)
    return np.array([[m.GetElement(i, j) for j in range(4)] for i in range(4)])


def main(session: Any, args: dict[str, Any]) -> dict[str, Any]:
    logic = session.logic
    logic.connect("127.0.0.1", int(args["port"]))
    session.pump(30, until=lambda: logic.client is not None, what="the module's client")
    logic.loadRobot("demo", "/robot_state_publisher", "robot_description")
    scene = session.scene
    session.pump(60, what="the robot placed", until=lambda: len(logic._planned) >= 25)
    tip = scene.GetFirstNode("demo:tool_flange", "vtkMRMLLinearTransformNode")
    start = _world(tip)  # where the flange is: reachable
    target = scene.AddNewNodeByClass("vtkMRMLLinearTransformNode", "drag target")
    matrix = vtk.vtkMatrix4x4()

    def place(pose: np.ndarray) -> None:
        for i in range(4):
            for j in range(4):
                matrix.SetElement(i, j, float(pose[i][j]))
        target.SetMatrixTransformToParent(matrix)

    place(start)
    logic.followTarget("demo", target, "tool_flange")
    solves: list[float] = []
    original = logic.solveIk

    def timed(*a: Any) -> Any:
        began = time.perf_counter()
        try:
            return original(*a)
        finally:
            solves.append(time.perf_counter() - began)
    logic.solveIk = timed
    preview = lambda: scene.GetFirstNode("demo:preview:tool_flange",  # noqa: E731
                                         "vtkMRMLLinearTransformNode")
    behind: list[float] = []
    frames = int(float(args["seconds"]) / FRAME_S)
    began = time.monotonic()
    for frame in range(frames):
        angle = 2 * math.pi * frame / 120  # one turn in 2 s
        pose = start.copy()
        pose[:3, 3] += (30.0 * math.cos(angle) - 30.0, 30.0 * math.sin(angle), 0.0)
        place(pose)
        while True:  # Slicer's loop until this frame's time is up
            session.pump(0)
            if time.monotonic() >= began + (frame + 1) * FRAME_S:
                break
            time.sleep(0.001)
        behind.append(float(np.linalg.norm(_world(preview())[:3, 3] - pose[:3, 3])))
    elapsed = time.monotonic() - began
    logic.stopFollowing()
    logic.solveIk = original
    return {"frames": frames, "seconds": elapsed, "solves": len(solves),
            "solve_ms": [1000 * s for s in solves], "behind_mm": behind,
            "status": logic.motionStatus}

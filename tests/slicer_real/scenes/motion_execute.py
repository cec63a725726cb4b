"""A model of the scene as an obstacle of a robot, executing around it (issue 46): the
module makes a 10 cm cube model an obstacle; executing the one-joint arm to a goal behind it
is refused naming the link and the obstacle; the cube's transform moved away, the module
sends it again by itself and the arm goes. The arm's joint states are read by a ROS peer in
the test's process, not here."""

from __future__ import annotations

import math
import time
from typing import Any

import slicer
import vtk

from scene_tools import connect
from slicer_client.actions import TERMINAL_STATUSES

def _placed(angle: float) -> Any:
    m = vtk.vtkMatrix4x4()
    m.SetElement(0, 3, 500.0 * math.cos(angle))
    m.SetElement(1, 3, 500.0 * math.sin(angle))
    return m


def main(session: Any, args: dict[str, Any]) -> dict[str, Any]:
    logic = connect(session, args["port"])
    client = logic.requireClient()
    robot = client.robot("swing", source={"kind": "file", "path": args["urdf"]},
                         namespace="swing")
    session.pump(60, until=lambda: _described(robot), what="the swing arm's URDF")
    # The robot's frame in tf, as its state publisher would put it there.
    frame = client.tf_broadcaster("base", "slicer_scene")
    action = args["action"]
    first = logic.executeMotion("swing", {"swing": -1.0}, action=action, durationS=1.0)
    # Results arrive as Slicer's spin hands them over: the module never blocks on one.
    session.pump(30, until=lambda: first.status in TERMINAL_STATUSES,
                 what="the first goal's end")
    out: dict[str, Any] = {"first": first.status}

    cube = vtk.vtkCubeSource()
    cube.SetXLength(100.0)
    cube.SetYLength(100.0)
    cube.SetZLength(100.0)
    cube.Update()
    scene = session.scene
    model = scene.AddNewNodeByClass("vtkMRMLModelNode", "block")
    model.SetAndObservePolyData(cube.GetOutput())
    place = scene.AddNewNodeByClass("vtkMRMLLinearTransformNode", "block place")
    place.SetMatrixTransformToParent(_placed(0.3))
    model.SetAndObserveTransformNodeID(place.GetID())
    out["obstacle"] = logic.addObstacle("swing", model, "base")

    last = [0.0]

    def plan_is(clear: bool) -> bool:
        if time.monotonic() - last[0] < 0.2:  # Slicer's loop runs in between
            return False
        last[0] = time.monotonic()
        frame.broadcast(vtk.vtkMatrix4x4())
        plan = robot.plan({"swing": args["goal"]}, resolution=0.01)
        out.setdefault("plans", []).append(plan["clear"])
        return plan["clear"] is clear and not plan["unplaced"]
    session.pump(60, until=lambda: plan_is(False), what="a plan through the block")
    # The tool's distance to the block, streamed to the scene (the daemon publishes it on
    # ROS, the module subscribes), while the arm holds at -1.0.
    out["watched"] = logic.watchDistances("swing", "tool")
    session.pump(60, until=lambda: logic.distanceMm("tool", "block") is not None,
                 what="a streamed distance")
    out["distance_mm"] = logic.distanceMm("tool", "block")
    out["distance_line"] = logic.distanceLine()
    try:
        logic.executeMotion("swing", {"swing": args["goal"]}, action=action)
        out["refused"] = ""
    except Exception as error:  # noqa: BLE001 - what the module shows
        out["refused"] = f"{type(error).__name__}: {error}"

    # The user drags the cube's transform away: the module sends the obstacle again.
    place.SetMatrixTransformToParent(_placed(-2.5))
    session.pump(60, until=lambda: plan_is(True), what="a clear plan once the block moved")
    handle = logic.executeMotion("swing", {"swing": args["goal"]}, action=action,
                                 durationS=2.0)
    session.pump(30, until=lambda: handle.status in TERMINAL_STATUSES,
                 what="the second goal's end")
    out["second"] = {"status": handle.status,
                     "error_code": handle.result(timeout=1)["error_code"]}

    # A segmentation as an obstacle: a 10 cm cube segment (closed surface as its source),
    # under a transform at -2.0 rad on the tool's circle; its distance from the tool.
    segmentation = scene.AddNewNodeByClass("vtkMRMLSegmentationNode", "organ")
    segmentation.GetSegmentation().SetSourceRepresentationName(
        slicer.vtkSegmentationConverter.GetSegmentationClosedSurfaceRepresentationName())
    segmentation.AddSegmentFromClosedSurfaceRepresentation(cube.GetOutput(), "cube",
                                                          [1.0, 0.0, 0.0])
    organ_place = scene.AddNewNodeByClass("vtkMRMLLinearTransformNode", "organ place")
    organ_place.SetMatrixTransformToParent(_placed(-2.0))
    segmentation.SetAndObserveTransformNodeID(organ_place.GetID())
    out["segmentation_obstacle"] = logic.addObstacle("swing", segmentation, "base")

    def organ_distance() -> Any:
        frame.broadcast(vtk.vtkMatrix4x4())
        found = [d for d in robot.obstacle_distances("tool")["distances"]
                 if d["obstacle"] == "organ"]
        return found[0]["distance_mm"] if found else None
    last[0] = 0.0

    def measured() -> bool:
        if time.monotonic() - last[0] < 0.2:
            return False
        last[0] = time.monotonic()
        out["organ_distance_mm"] = organ_distance()
        return out["organ_distance_mm"] is not None
    session.pump(60, until=measured, what="the segmentation's distance")
    return out


def _described(robot: Any) -> bool:
    try:
        robot.joints(refresh=True)
    except Exception:  # noqa: BLE001 - not loaded yet (UNAVAILABLE)
        return False
    return True

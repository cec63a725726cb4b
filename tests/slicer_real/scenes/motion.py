"""The module's Motion logic in a real scene (issue 46): a transform node and a markups point
as targets for the demo arm's tool flange, solved by the daemon, shown by the preview robot;
a dragged target followed at the display's rate; an unreachable one shown red."""

from __future__ import annotations

from typing import Any

import numpy as np
import vtk

from scene_tools import connect, nodes, world_matrix


def _vtk(rows: Any) -> Any:
    m = vtk.vtkMatrix4x4()
    for i in range(4):
        for j in range(4):
            m.SetElement(i, j, float(rows[i][j]))
    return m


def main(session: Any, args: dict[str, Any]) -> dict[str, Any]:
    logic = connect(session, args["port"])
    name, tip = args["robot"], args["tip"]
    logic.loadRobot(name, "/robot_state_publisher", "robot_description")

    def visuals() -> list[Any]:
        return nodes(session, "vtkMRMLModelNode", robot=name, role="robot_visual")
    session.pump(90, until=lambda: len(visuals()) == args["models"] and all(
        v.GetID() in logic._planned for v in visuals()), what="every visual placed")
    scene = session.scene
    root_node = scene.GetFirstNode(f"{name}:{args['root']}", "vtkMRMLLinearTransformNode")
    root_world = np.array(world_matrix(root_node))
    target_world = root_world @ np.array(args["target_in_root"])
    out: dict[str, Any] = {"target_world": target_world.tolist()}

    def preview_tip() -> list[list[float]]:
        return world_matrix(scene.GetFirstNode(f"{name}:preview:{tip}",
                                               "vtkMRMLLinearTransformNode"))

    def preview_colours() -> list[list[float]]:
        return [list(m.GetDisplayNode().GetColor()) for m in nodes(session, "vtkMRMLModelNode")
                if m.GetAttribute("ROS2Bridge.preview") == name]

    # 1. A transform node as the target.
    target = scene.AddNewNodeByClass("vtkMRMLLinearTransformNode", "target")
    target.SetMatrixTransformToParent(_vtk(target_world))
    result = logic.solveIk(name, target, tip)
    out["transform"] = {"solved": result.solved, "status": logic.motionStatus,
                        "preview_tip": preview_tip(), "colours": preview_colours(),
                        "preview_models": len(preview_colours())}

    # 1b. The path to that solution, scrubbed in Slicer's sequence browser.
    plan = logic.previewPath(name)
    browser = logic.pathBrowser
    items = browser.GetMasterSequenceNode().GetNumberOfDataNodes()
    scrubbed = []
    for number in (0, items // 2, items - 1):
        browser.SetSelectedItemNumber(number)
        session.pump(0.05)
        step = plan["preview"][number]["step"]
        scrubbed.append({"step": step, "time_s": plan["preview"][number]["time_s"],
                         "index_value": browser.GetMasterSequenceNode().GetNthIndexValue(number),
                         "positions": {**plan["start"], **dict(zip(plan["joints"],
                                                                   plan["path"][step]))},
                         "preview_tip": preview_tip()})
    out["path"] = {"clear": plan["clear"], "items": items, "checked": plan["checked"],
                   "status": logic.motionStatus, "scrubbed": scrubbed,
                   "root_world": root_world.tolist()}

    # 2. Dragged: many moves between two frames, solved at most once a frame, the newest.
    moved = target_world.copy()
    logic.followTarget(name, target, tip)
    solves = []
    original = logic.solveIk

    def counted(*a: Any) -> Any:
        solves.append(1)
        return original(*a)
    logic.solveIk = counted
    for step in range(1, 21):
        moved[:3, 3] = target_world[:3, 3] + np.array([0.0, 0.0, float(step)])  # up 20 mm
        target.SetMatrixTransformToParent(_vtk(moved))
    session.pump(20, until=lambda: solves and abs(preview_tip()[2][3] - moved[2][3]) < 0.1,
                 what="the preview at the dragged target")
    out["dragged"] = {"solves": len(solves), "moves": 20, "preview_tip": preview_tip(),
                      "target": moved.tolist(), "status": logic.motionStatus}
    logic.stopFollowing()
    logic.solveIk = original

    # 3. Unreachable: the preview shows the best attempt, red.
    far = target_world.copy()
    far[:3, 3] += np.array([5000.0, 0.0, 0.0])
    target.SetMatrixTransformToParent(_vtk(far))
    result = logic.solveIk(name, target, tip)
    out["unreachable"] = {"solved": result.solved, "status": logic.motionStatus,
                          "reason": (result.failure or {}).get("reason"),
                          "colours": preview_colours()}

    # 4. A markups point with its orientation as the target.
    point = scene.AddNewNodeByClass("vtkMRMLMarkupsFiducialNode", "point target")
    point.AddControlPoint(*target_world[:3, 3])
    rotation = vtk.vtkMatrix3x3()
    for i in range(3):
        for j in range(3):
            rotation.SetElement(i, j, float(target_world[i][j]))
    point.SetNthControlPointOrientationMatrix(0, rotation)
    result = logic.solveIk(name, point, tip)
    out["markups"] = {"solved": result.solved, "preview_tip": preview_tip()}

    logic.removePreview(name)
    out["previews_left"] = sum(1 for cls in ("vtkMRMLModelNode", "vtkMRMLLinearTransformNode")
                               for n in nodes(session, cls)
                               if n.GetAttribute("ROS2Bridge.preview") == name)
    return out

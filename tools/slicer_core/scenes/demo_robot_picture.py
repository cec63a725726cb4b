"""The demo robot as the ROS2Bridge module shows it in a real Slicer scene, rendered by
Slicer's own displayable managers (tools/render_scene_picture.py runs it)."""

from __future__ import annotations

from typing import Any

import numpy as np
import vtk

from tools.slicer_core.render import SceneView


def main(session: Any, args: dict[str, Any]) -> dict[str, Any]:
    logic = session.logic
    logic.connect("127.0.0.1", int(args["port"]))
    session.pump(30, until=lambda: logic.client is not None, what="the module's client")
    logic.loadRobot("demo", "/robot_state_publisher", "robot_description")
    scene = session.scene

    def visuals() -> list[Any]:
        found = [scene.GetNthNodeByClass(i, "vtkMRMLModelNode")
                 for i in range(scene.GetNumberOfNodesByClass("vtkMRMLModelNode"))]
        return [m for m in found if m.GetAttribute("OpenIGTLink.ros2.robot") == "demo"]
    session.pump(60, until=lambda: len(visuals()) == args["models"] and all(
        m.GetID() in logic._planned for m in visuals()), what="every visual placed")
    # Watch the arm swing for a while; keep the moment it reaches furthest out with every
    # link above the floor (a picture that shows its joints), then render that pose.
    flange = scene.GetFirstNode("demo:tool_flange", "vtkMRMLLinearTransformNode")
    links = [scene.GetFirstNode(f"demo:{m.GetAttribute('OpenIGTLink.ros2.link')}",
                                "vtkMRMLLinearTransformNode") for m in visuals()]
    best, best_reach = None, -1.0
    for _ in range(int(args["settle"] / 0.05)):
        session.pump(0.05)
        poses = [_matrix(n) for n in links]
        if min(p[2, 3] for p in poses) > 60.0:
            reach = float(np.hypot(*_matrix(flange)[:2, 3]))
            if reach > best_reach:
                best, best_reach = [(n, p) for n, p in zip(links, poses)], reach
    logic.disconnect()  # the pose stays as it was
    for node, pose in best or []:
        m = vtk.vtkMatrix4x4()
        m.DeepCopy(pose.ravel())
        node.SetMatrixTransformToParent(m)
    view = SceneView(session.app, tuple(args["size"]))
    view.look((1400, -1100, 800), (0, 0, 300), zoom=1.15)
    view.caption(f"3D Slicer (slicer-core) with the ROS2Bridge module: the demo robot, "
                 f"{len(visuals())} models under {len(set(links))} link transforms")
    view.png(args["out"])
    return {"models": len(visuals()), "links": len(set(n.GetID() for n in links))}


def _matrix(node: Any) -> np.ndarray:
    m = vtk.vtkMatrix4x4()
    node.GetMatrixTransformToParent(m)
    return np.array([[m.GetElement(i, j) for j in range(4)] for i in range(4)])

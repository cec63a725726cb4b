"""Slicer -> ROS through the module in a real scene: a textured model (a vtkCubeSource,
as Slicer's Create Models makes), a point list, a curve and a transform node, each as
Slicer's own connector (or the reference API) pushes it; resent until the test has seen
each in ROS (args["flag"])."""

from __future__ import annotations

from typing import Any

import slicer
import vtk

from scene_tools import connect, repeat_until_told


def main(session: Any, args: dict[str, Any]) -> dict[str, Any]:
    logic = connect(session, args["port"])
    scene = session.scene
    cube = vtk.vtkCubeSource()
    cube.SetXLength(20.0), cube.SetYLength(20.0), cube.SetZLength(20.0)
    cube.Update()
    model = scene.AddNewNodeByClass("vtkMRMLModelNode", "cube")
    model.SetAndObservePolyData(cube.GetOutput())
    shift = scene.AddNewNodeByClass("vtkMRMLLinearTransformNode", "shift")
    m = vtk.vtkMatrix4x4()
    m.SetElement(0, 3, 100.0)
    shift.SetMatrixTransformToParent(m)
    model.SetAndObserveTransformNodeID(shift.GetID())
    points = scene.AddNewNodeByClass("vtkMRMLMarkupsFiducialNode", "targets")
    points.AddControlPoint(10.0, 20.0, 30.0, "entry")
    points.AddControlPoint(40.0, 50.0, 60.0, "target")
    curve = scene.AddNewNodeByClass("vtkMRMLMarkupsCurveNode", "path")
    for xyz in ((0.0, 0.0, 0.0), (10.0, 0.0, 0.0), (20.0, 10.0, 0.0)):
        curve.AddControlPoint(*xyz)
    needle = scene.AddNewNodeByClass("vtkMRMLLinearTransformNode", "needle")
    broadcaster = logic.GetDefaultROS2Node().CreateAndAddTf2BroadcasterNode("base_link",
                                                                           "needle")
    broadcaster.ObserveTransformNode(needle)
    moves = [0]

    def send() -> None:
        logic.sendToROS(model, "/slicer_model", "base_link")
        logic.sendToROS(points, "/slicer_points", "base_link")
        logic.sendToROS(curve, "/slicer_curve", "base_link")
        moves[0] += 1
        t = vtk.vtkMatrix4x4()
        t.SetElement(0, 3, 5.0)
        t.SetElement(1, 3, 6.0)
        t.SetElement(2, 3, 7.0 + 1e-3 * moves[0])  # a change: the node is pushed again
        needle.SetMatrixTransformToParent(t)
    sends = repeat_until_told(session, args["flag"], send)
    return {"sends": sends, "cube_points": cube.GetOutput().GetNumberOfPoints(),
            "has_tcoords": cube.GetOutput().GetPointData().GetTCoords() is not None,
            "problems": logic.problems, "errors": list(logic.client.errors)}


_ = slicer

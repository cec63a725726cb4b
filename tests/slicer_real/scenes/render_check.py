"""Slicer's own displayable managers render a model of the real scene offscreen: a red
sphere in a white view, what fraction of the picture is red."""

from __future__ import annotations

from typing import Any

import vtk
from vtk.util.numpy_support import vtk_to_numpy

from tools.slicer_core.render import SceneView


def main(session: Any, args: dict[str, Any]) -> dict[str, Any]:
    sphere = vtk.vtkSphereSource()
    sphere.SetRadius(50.0)
    sphere.Update()
    model = session.scene.AddNewNodeByClass("vtkMRMLModelNode", "ball")
    model.SetAndObservePolyData(sphere.GetOutput())
    model.CreateDefaultDisplayNodes()
    model.GetDisplayNode().SetColor(1.0, 0.0, 0.0)
    view = SceneView(session.app, (200, 200))
    view.view.SetBackgroundColor(1, 1, 1)
    view.view.SetBackgroundColor2(1, 1, 1)
    view.look((0, -500, 0), (0, 0, 0))
    view.png(args["out"])
    reader = vtk.vtkPNGReader()
    reader.SetFileName(args["out"])
    reader.Update()
    pixels = vtk_to_numpy(reader.GetOutput().GetPointData().GetScalars())
    red = ((pixels[:, 0] > 100) & (pixels[:, 1] < 60) & (pixels[:, 2] < 60)).mean()
    white = (pixels[:, :3] > 240).all(axis=1).mean()
    return {"red": float(red), "white": float(white), "count": int(len(pixels))}

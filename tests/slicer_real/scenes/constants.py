"""The numbers slicer-core and Slicer's OpenIGTLinkIF connector give the names in
tests/slicer_constants.py, and how a Python observer receives events."""

from __future__ import annotations

from typing import Any

import slicer
import vtk


def main(session: Any, args: dict[str, Any]) -> dict[str, Any]:
    values = {}
    for key in args["keys"]:
        cls, name = key.split(".")
        owner = vtk if cls == "vtkCommand" else slicer
        values[key] = getattr(getattr(owner, cls), name)
    node = session.scene.AddNewNodeByClass("vtkMRMLLinearTransformNode")
    seen: list[Any] = []
    for event in (vtk.vtkCommand.ModifiedEvent, slicer.vtkMRMLTransformNode.TransformModifiedEvent):
        node.AddObserver(event, lambda caller, e: seen.append(e))
        node.InvokeEvent(event)
    return {"values": values, "observed": seen}

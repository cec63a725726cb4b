"""What ROS publishes, shown by the module in the real scene: a tf lookup as a transform
node, an image as a volume, a point cloud as a model, markers as models and a labelled
point, text as a text node; every node made by Slicer's own connector."""

from __future__ import annotations

from typing import Any

import numpy as np
import slicer
import vtk
from vtk.util.numpy_support import vtk_to_numpy

from scene_tools import connect, matrix


def main(session: Any, args: dict[str, Any]) -> dict[str, Any]:
    logic = connect(session, args["port"])
    client = logic.client
    subs = {kind: client.subscribe(topic, kind) for kind, topic in (
        ("Image", "/scene_image"), ("PointCloud2", "/scene_cloud"), ("String", "/scene_text"))}
    lookup = client.tf_lookup("world", "tool")
    logic.addMarkers("/scene_markers", "MarkerArray", "world")
    scene = session.scene

    def node(device: str, cls: str) -> Any:
        return scene.GetFirstNode(device, cls) if device else None

    def markers() -> list[Any]:
        return [n for n in (scene.GetNthNodeByClass(i, "vtkMRMLNode")
                            for i in range(scene.GetNumberOfNodesByClass("vtkMRMLNode")))
                if n.GetAttribute("OpenIGTLink.ros2.role") == "marker"]

    def label() -> Any:
        return next((scene.GetFirstNode(f"{m.GetName()} label", "vtkMRMLMarkupsFiducialNode")
                     for m in markers() if m.IsA("vtkMRMLTextNode")), None)

    session.pump(60, what="every node made", until=lambda: all((
        node(subs["Image"].device, "vtkMRMLVolumeNode"),
        node(subs["PointCloud2"].device, "vtkMRMLModelNode"),
        node(subs["String"].device, "vtkMRMLTextNode"),
        node(lookup.device, "vtkMRMLLinearTransformNode"),
        len(markers()) >= 3, label() is not None and label().GetNumberOfControlPoints())))
    session.pump(1.0)  # a few more messages: what is shown is the latest
    volume = node(subs["Image"].device, "vtkMRMLVolumeNode")
    cloud = node(subs["PointCloud2"].device, "vtkMRMLModelNode")
    text = node(subs["String"].device, "vtkMRMLTextNode")
    tf = node(lookup.device, "vtkMRMLLinearTransformNode")
    pixels = slicer.util.arrayFromVolume(volume)
    poly = cloud.GetPolyData()
    colours = poly.GetPointData().GetArray("RGBA")
    marker_info = []
    for m in markers():
        entry = {"name": m.GetName(), "class": m.GetClassName(),
                 "type": m.GetAttribute("OpenIGTLink.ros2.marker_type"),
                 "parent": m.GetParentTransformNode().GetName()
                 if m.IsA("vtkMRMLTransformableNode") and m.GetParentTransformNode() else None}
        if m.IsA("vtkMRMLModelNode"):
            entry["bounds"] = list(m.GetPolyData().GetBounds())
            entry["colour"] = list(m.GetDisplayNode().GetColor())
            entry["vertices"] = _vertices(m.GetPolyData())
        marker_info.append(entry)
    point = [0.0, 0.0, 0.0]
    lab = label()
    lab.GetNthControlPointPositionWorld(0, point)
    return {
        "volume": {"class": volume.GetClassName(), "shape": list(pixels.shape),
                   "pixels": pixels.tolist()},
        "cloud": {"points": vtk_to_numpy(poly.GetPoints().GetData()).tolist(),
                  "vertices": _vertices(poly),
                  "colours": vtk_to_numpy(colours).tolist() if colours is not None else None},
        "text": text.GetText(),
        "tf": matrix(tf),
        "markers": marker_info,
        "label": {"text": lab.GetNthControlPointLabel(0), "world": point},
    }


def _vertices(poly: Any) -> list[int]:
    """A model's vertex cells, legacy layout [1, i, 1, j, ...]."""
    out = vtk.vtkIdTypeArray()
    poly.GetVerts().ExportLegacyFormat(out)
    return [int(v) for v in vtk_to_numpy(out)] if out.GetNumberOfTuples() else []


_ = np

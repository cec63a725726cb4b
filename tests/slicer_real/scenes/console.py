"""A README block for 3D Slicer's Python console, run as a user runs it: a plain
OpenIGTLinkIF connector (the README's steps 3-4: '+', Client, host, port, Active) brings the
demo robot, then the block runs with Slicer's `slicer` in its namespace. What it changed in
the robot's nodes is returned."""

from __future__ import annotations

from typing import Any

import slicer

from scene_tools import nodes


def main(session: Any, args: dict[str, Any]) -> dict[str, Any]:
    connector = session.scene.AddNewNodeByClass("vtkMRMLIGTLConnectorNode")
    connector.SetTypeClient("127.0.0.1", int(args["port"]))
    connector.Start()

    def arrived() -> bool:
        # The link transforms: the nodes the connector makes of the robot's TDATA elements.
        bundle = session.scene.GetFirstNode("poses:demo", "vtkMRMLIGTLTrackingDataBundleNode")
        return (len(nodes(session, "vtkMRMLModelNode", role="robot_visual")) == args["models"]
                and bundle is not None and bundle.GetNumberOfTransformNodes() == args["links"])
    session.pump(60, until=arrived, what="the demo robot's nodes")
    exec(compile(args["code"], "README block", "exec"), {"slicer": slicer})
    models = {}
    for model in nodes(session, "vtkMRMLModelNode", role="robot_visual"):
        display = model.GetDisplayNode()
        models[model.GetName()] = {
            "parent": model.GetParentTransformNode().GetName()
            if model.GetParentTransformNode() else None,
            "expected_parent": model.GetAttribute("OpenIGTLink.ros2.parent_device"),
            "scalars": bool(display.GetScalarVisibility()),
            "active": display.GetActiveScalarName() or ""}
    connector.Stop()
    return {"models": models}

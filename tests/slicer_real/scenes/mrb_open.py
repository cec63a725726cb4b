"""A saved .mrb (or .mrml) reopened in a new scene, then Connect: the module re-creates its bridges
(the robot, the subscriber) on the daemon it connects to, and the robot's nodes come back
under their links."""

from __future__ import annotations

import os
import tempfile
from typing import Any

from scene_tools import nodes


def main(session: Any, args: dict[str, Any]) -> dict[str, Any]:
    unpack = tempfile.mkdtemp()
    if args["mrb"].endswith(".mrml"):
        session.scene.SetURL(args["mrb"])
        opened = session.scene.Connect()
    else:
        opened = session.app.app_logic.OpenSlicerDataBundle(args["mrb"], unpack)
    logic = session.logic
    parameters = logic.getParameterNode()
    saved_state = parameters.bridgeState
    logic.connect("127.0.0.1", int(args["port"]))
    session.pump(30, until=lambda: logic.client is not None, what="the module's client")

    def placed() -> list[Any]:
        return [m for m in nodes(session, "vtkMRMLModelNode", robot="arm",
                                 role="robot_visual") if m.GetID() in logic._planned]
    # Nothing publishes tf here: the base link's model is placed, the upper link's waits.
    session.pump(60, what="the restored robot's meshes and its base placed",
                 until=lambda: logic.robotLines() == ["arm: 2 of 2 meshes received"]
                 and len(placed()) == 1)
    return {"opened": bool(opened), "saved_state": saved_state,
            "bridges": logic.bridgeLines(), "robots": logic.robotNames(),
            "robot_lines": logic.robotLines(),
            "models": sorted(m.GetName() for m in placed()),
            "parents": sorted(m.GetParentTransformNode().GetName() for m in placed()),
            "files": sorted(os.listdir(unpack))}

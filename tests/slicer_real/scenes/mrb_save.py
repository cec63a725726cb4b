"""A user's session saved as a Slicer data bundle (.mrb) or scene file (.mrml), as
Slicer's scene writers save them: the module connected, a robot loaded and a subscriber
made, then the bundle written (the module keeps its bridges in its parameter node on the
scene's StartSaveEvent)."""

from __future__ import annotations

import os
import tempfile
from typing import Any

from scene_tools import connect, nodes


def main(session: Any, args: dict[str, Any]) -> dict[str, Any]:
    logic = connect(session, args["port"])
    logic.loadRobot("arm", args["robot_node"], "robot_description")
    logic.client.subscribe("/mrb_text", "String")
    session.pump(60, until=lambda: len(nodes(session, "vtkMRMLModelNode", robot="arm")) == 2,
                 what="the robot's models")
    scene = session.scene
    scene.InvokeEvent(scene.StartSaveEvent)  # what Slicer's scene writer does first
    if args["mrb"].endswith(".mrml"):  # the scene file alone, as Slicer's .mrml writer
        scene.SetRootDirectory(os.path.dirname(args["mrb"]))
        scene.SetURL(args["mrb"])
        return {"saved": bool(scene.Commit()), "zipped": True, "files": []}
    bundle = os.path.join(tempfile.mkdtemp(), "session")
    os.makedirs(bundle)
    saved = session.app.app_logic.SaveSceneToSlicerDataBundleDirectory(bundle)
    zipped = session.app.app_logic.Zip(args["mrb"], os.path.dirname(bundle))
    return {"saved": bool(saved), "zipped": bool(zipped),
            "files": sorted(os.listdir(os.path.join(bundle, "Data")))}

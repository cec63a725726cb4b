"""A played bag into Slicer's Sequences through the module (issue 45): connected to a
player, the robot loaded, `bagToSequences` records the bag every 0.25 s; then the test's
items are browsed and the flange's transform read at each."""

from __future__ import annotations

from typing import Any

import slicer
import vtk

from scene_tools import connect, matrix


def main(session: Any, args: dict[str, Any]) -> dict[str, Any]:
    logic = connect(session, args["port"])
    logic.loadRobot("demo", "/robot_state_publisher", "robot_description")
    scene = session.scene

    def flange() -> Any:
        return scene.GetFirstNode("demo:tool_flange", "vtkMRMLLinearTransformNode")
    logic.requireClient().subscribe("/camera/image", "Image")  # a volume in the scene

    def image() -> Any:
        found = [n for n in (logic.connector.GetIncomingMRMLNode(i)
                             for i in range(logic.connector.GetNumberOfIncomingMRMLNodes()))
                 if n is not None and n.IsA("vtkMRMLVolumeNode")]
        return found[0] if found else None
    logic.seekPlayback(float(args["start"]))  # where the bag has joint states
    session.pump(60, until=lambda: flange() is not None and image() is not None,
                 what="the robot placed and the image shown")
    browser = logic.bagToSequences(float(args["start"]), None, float(args["step"]))
    master = browser.GetMasterSequenceNode()
    items = master.GetNumberOfDataNodes()
    found = vtk.vtkCollection()
    browser.GetSynchronizedSequenceNodes(found, True)  # the master too
    sequences = [found.GetItemAsObject(i).GetName() for i in range(found.GetNumberOfItems())]
    shown = {}
    for number in args["items"]:
        browser.SetSelectedItemNumber(number)
        session.pump(0.05)
        pixels = slicer.util.arrayFromVolume(image())
        shown[master.GetNthIndexValue(number)] = {"flange": matrix(flange()),
                                                  "image_sum": int(pixels.sum())}
    return {"items": items, "sequences": sequences, "shown": shown,
            "models_under_links": sum(
                1 for n in session.scene.GetNodesByClass("vtkMRMLModelNode")
                if n.GetAttribute("OpenIGTLink.ros2.role") == "robot_visual"
                and n.GetTransformNodeID())}

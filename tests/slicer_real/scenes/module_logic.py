"""The module's logic as a script or the GUI's buttons drive it, in a real scene against a
daemon: what fails before Connect and after it, the reference's first call connecting by
itself, markers listed and removed, a robot loaded then removed with its nodes and folder,
and a scene close disconnecting."""

from __future__ import annotations

import json
from typing import Any

import slicer

from scene_tools import error_of, nodes


def main(session: Any, args: dict[str, Any]) -> dict[str, Any]:
    logic, scene = session.logic, session.scene
    out: dict[str, Any] = {"before_connect": {
        "robots": logic.robotNames(), "stale": logic.staleLines(), "lines": logic.robotLines(),
        "load": error_of(lambda: logic.loadRobot("demo", "/robot_state_publisher",
                                                 "robot_description")),
        "bridges": error_of(logic.bridgeLines),
        "key": error_of(lambda: logic.connect("127.0.0.1", int(args["port"]),
                                              args["missing_key"]))}}
    logic.disconnect()

    # A script's first reference call connects to the settings' host and port.
    logic.getParameterNode().port = int(args["port"])
    ros_node = logic.GetDefaultROS2Node()
    out["first_call"] = {"client": logic.client is not None, "connected": logic.isConnected(),
                         "second": logic.CreateROS2Node("second") is not None,
                         "reference_logic_same_node": slicer.util.getModuleLogic(
                             "ROS2").GetDefaultROS2Node() is ros_node}

    text = scene.AddNewNodeByClass("vtkMRMLTextNode", "notes")
    out["send_text"] = error_of(lambda: logic.sendToROS(text, "/notes", "base_link"))
    out["send_none"] = error_of(lambda: logic.sendToROS(None, "/notes", "base_link"))
    out["no_such_node"] = error_of(lambda: logic.loadRobot("ghost", "/no_such_node",
                                                           "robot_description"))
    out["robots_after_failure"] = logic.robotNames()

    markers = logic.addMarkers("/module_markers", "MarkerArray", "base_link")
    out["markers"] = {"topic": markers.resolved_topic,
                      "listed": [ln for ln in logic.bridgeLines() if "/module_markers" in ln]}
    logic.removeMarkers("/module_markers")  # as it was added
    out["markers"]["after_remove"] = [ln for ln in logic.bridgeLines()
                                      if "/module_markers" in ln]
    out["remove_absent_robot"] = logic.RemoveRobot("absent")

    # A robot loaded, then removed: its nodes and folder go, its saved bridge too.
    logic.loadRobot("arm", args["robot_node"], "robot_description")
    session.pump(60, until=lambda: len(nodes(session, "vtkMRMLModelNode", robot="arm")) == 2,
                 what="the arm's models")
    # The robot's load holds the daemon's session for seconds, its heartbeat too: the module
    # may call the link silent meanwhile; the next heartbeat restores it.
    session.pump(30, until=logic.isConnected, what="the link live again")
    sh = slicer.vtkMRMLSubjectHierarchyNode.GetSubjectHierarchyNode(scene)
    loaded = {"robots": logic.robotNames(), "folder": bool(sh.GetItemByName("robot arm")),
              "saved": [b["op"] for b in json.loads(
                  logic.getParameterNode().bridgeState)["bridges"]]}
    logic.removeRobot("arm")
    out["robot"] = {"loaded": loaded, "robots_after": logic.robotNames(),
                    "nodes_after": len(nodes(session, "vtkMRMLNode", robot="arm")),
                    "folder_after": bool(sh.GetItemByName("robot arm")),
                    "saved_after": json.loads(logic.getParameterNode().bridgeState)["bridges"],
                    "sliders_of_none": error_of(lambda: logic.jointSliders(""))}

    # Closing the scene disconnects.
    scene.Clear(0)
    out["after_close"] = {"client": logic.client is None, "connector": logic.connector is None,
                          "active": logic.isActive()}
    return out

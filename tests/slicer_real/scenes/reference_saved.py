"""The reference's nodes saved with the scene and reopened (issue 42): `save` makes a ROS
node with a publisher, a subscriber, a tf2 lookup, a service client and a robot, and writes
the scene as an .mrb (Slicer's application logic) or an .mrml (the scene's Commit); `reopen`,
in a new Slicer process, opens it into an empty scene, connects the module, and reports what
came back."""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path
from typing import Any

import slicer

from scene_tools import connect




def scene_nodes() -> Any:
    """The module's ROS2BridgeLib.scene_nodes (importable once the session put the module's
    folder on sys.path, as Slicer does)."""
    import ROS2BridgeLib.scene_nodes
    return ROS2BridgeLib.scene_nodes


SCALE = float(os.environ.get("SLICER_BRIDGE_TEST_TIME_SCALE", "1"))


def reference_nodes(scene: Any) -> dict[str, dict[str, Any]]:
    found = scene.GetNodesByClass("vtkMRMLNode")
    nodes = [found.GetItemAsObject(i) for i in range(found.GetNumberOfItems())]
    return {n.GetID(): {"name": n.GetName(), "class": n.GetAttribute(scene_nodes().CLASS_ATTRIBUTE),
                        "python": type(n).__name__}
            for n in nodes if n.GetAttribute(scene_nodes().CLASS_ATTRIBUTE)}


def ids_by_class(scene: Any) -> dict[str, list[str]]:
    """The scene's own GetNodesByClass for each reference class the library has."""
    found: dict[str, list[str]] = {}
    for class_name in ("vtkMRMLROS2NodeNode", "vtkMRMLROS2PublisherStringNode",
                       "vtkMRMLROS2SubscriberStringNode", "vtkMRMLROS2Tf2LookupNode",
                       "vtkMRMLROS2RobotNode"):
        nodes = scene.GetNodesByClass(class_name)
        found[class_name] = [nodes.GetItemAsObject(i).GetID()
                             for i in range(nodes.GetNumberOfItems())]
    return found


def spin_until(session: Any, condition: Any, what: str, seconds: float = 60.0) -> None:
    ros2Logic = slicer.util.getModuleLogic("ROS2")  # noqa: N806
    deadline = time.monotonic() + seconds * SCALE
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"not within {seconds * SCALE} s: {what}")
        time.sleep(0.01)
        ros2Logic.Spin()


def save(session: Any, args: dict[str, Any]) -> dict[str, Any]:
    connect(session, args["port"])
    scene = slicer.mrmlScene
    ros2Node = scene.AddNewNodeByClass("vtkMRMLROS2NodeNode")  # noqa: N806
    ros2Node.Create("kept")
    ros2Node.CreateAndAddPublisherNode("String", "/saved_string")
    sub = ros2Node.CreateAndAddSubscriberNode("String", "/saved_string")
    ros2Node.CreateAndAddTf2LookupNode("world", "saved_frame")
    ros2Node.CreateAndAddServiceClientNode("SetBool", "/saved_service")
    robot = ros2Node.CreateAndAddRobotNode(args["robot"], args["node"])
    spin_until(session, lambda: robot.GetNumberOfLinks() > 0, "the robot's links")
    before = reference_nodes(scene)
    path = Path(args["file"])
    if path.suffix == ".mrml":  # Commit invokes StartSaveEvent itself
        scene.SetURL(str(path))
        assert scene.Commit()
    else:
        bundle = Path(tempfile.mkdtemp(prefix="mrb-save-"))
        logic = session.app.app_logic
        scene.InvokeEvent(scene.StartSaveEvent)  # what Slicer's save does first: state saved
        assert logic.SaveSceneToSlicerDataBundleDirectory(str(bundle), None)
        assert logic.Zip(str(path), str(bundle))
    return {"nodes": before, "sub_id": sub.GetID(), "links": robot.GetNumberOfLinks(),
            "file_bytes": path.stat().st_size}


def reopen(session: Any, args: dict[str, Any]) -> dict[str, Any]:
    scene = slicer.mrmlScene
    if args["file"].endswith(".mrml"):
        scene.SetURL(args["file"])
        assert scene.Import()
    else:
        temp = Path(tempfile.mkdtemp(prefix="mrb-open-"))
        assert session.app.app_logic.OpenSlicerDataBundle(args["file"], str(temp))
    opened = reference_nodes(scene)  # nodes of the C++ classes until the module is connected
    opened_by_class = ids_by_class(scene)
    # A scene file is input: a recipe that is no reference node's call is refused.
    tampered = scene.AddNewNodeByClassWithID("vtkMRMLScriptedModuleNode", "tampered",
                                             "vtkMRMLROS2NodeNode9")
    tampered.SetAttribute("ROS2.Class", "vtkMRMLROS2NodeNode")
    tampered.SetAttribute("ROS2.Recipe", '["Destroy"]')
    module = connect(session, args["port"])
    spin_until(session, lambda: all(v["python"].endswith("MRML")  # the facade's classes
                                    for k, v in reference_nodes(scene).items()
                                    if k != tampered.GetID()),
               "every saved reference node made again")
    problems = list(module.problems)
    scene.RemoveNode(tampered)
    robot = scene_nodes().nodes_of_class(scene, "vtkMRMLROS2RobotNode")[0]
    spin_until(session, lambda: robot.GetNumberOfLinks() > 0, "the robot's links")
    ros2Node = scene_nodes().nodes_of_class(scene, "vtkMRMLROS2NodeNode")[0]  # noqa: N806
    return {
        "opened": opened, "adopted": reference_nodes(scene),
        "opened_by_class": opened_by_class, "adopted_by_class": ids_by_class(scene),
        "problems": problems,
        "sub_by_topic": ros2Node.GetSubscriberNodeByTopic("/saved_string").GetID(),
        "ros_node_name": ros2Node.GetROS2NodeName(),
        "links": robot.GetNumberOfLinks(),
        "bridges": module.client.list_bridges(),
    }


def main(session: Any, args: dict[str, Any]) -> dict[str, Any]:
    return save(session, args) if args["step"] == "save" else reopen(session, args)

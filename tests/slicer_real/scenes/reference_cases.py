"""SlicerROS2's own test cases (its Testing/Python/ROS2Tests.py: pub/sub, parameters, tf2,
the async service client), with the same calls, in a real scene where the ROS2Bridge module
answers its entry points; plus what issue 42 asks of its nodes there: found by ID, name and
class, observed with VTK's AddObserver, a tf2 lookup node a transform node models follow.
Waits where the suite spins a fixed 100 ms, except for the service reply, read after one
spin (GetLastResponse waits for a request in flight)."""

from __future__ import annotations

import os
import subprocess
import time
from typing import Any, Callable

import slicer
import vtk

from scene_tools import connect, world_matrix




def scene_nodes() -> Any:
    """The module's ROS2BridgeLib.scene_nodes (importable once the session put the module's
    folder on sys.path, as Slicer does)."""
    import ROS2BridgeLib.scene_nodes
    return ROS2BridgeLib.scene_nodes


SCALE = float(os.environ.get("SLICER_BRIDGE_TEST_TIME_SCALE", "1"))


def spin_some() -> None:
    """The suite's spin_some: ten spins, 10 ms apart."""
    ros2Logic = slicer.util.getModuleLogic("ROS2")  # noqa: N806
    for _ in range(10):
        time.sleep(0.01)
        ros2Logic.Spin()


def spin_until(condition: Callable[[], bool], what: str, seconds: float = 20.0) -> None:
    deadline = time.monotonic() + seconds * SCALE
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"not within {seconds * SCALE} s: {what}")
        spin_some()


class Observer:
    """The suite's TestObserverSubscriber."""

    def __init__(self) -> None:
        self.lastMessageYAML = ""
        self.counter = 0
        self.events: list[str] = []

    def Callback(self, caller: Any, event: Any) -> None:  # noqa: N802
        self.lastMessageYAML = caller.GetLastMessageYAML()
        self.counter += 1
        self.events.append(event)


def pub_sub(ros2Node: Any, type_name: str, sent: Any) -> dict[str, Any]:  # noqa: N803
    topic = "slicer_test_" + type_name.lower()
    pub = ros2Node.CreateAndAddPublisherNode(type_name, topic)
    sub = ros2Node.CreateAndAddSubscriberNode(type_name, topic)
    observer = Observer()
    tag = sub.AddObserver("ModifiedEvent", observer.Callback)
    spin_some()
    before = sub.GetNumberOfMessages()
    pub.Publish(sent)
    spin_until(lambda: sub.GetNumberOfMessages() > before, f"the {type_name} message")
    spin_some()
    received = sub.GetLastMessage()
    if isinstance(received, vtk.vtkMatrix4x4):
        value: Any = received.GetElement(2, 3)
    elif isinstance(received, vtk.vtkIntArray):
        value = [received.GetValue(i) for i in range(received.GetNumberOfValues())]
    else:
        value = received
    found = {"pub_id": pub.GetID(), "sub_id": sub.GetID(), "sub_name": sub.GetName(),
             "by_id": slicer.mrmlScene.GetNodeByID(sub.GetID()) is sub,
             "by_class": [ids_of_class(slicer.mrmlScene, f"vtkMRMLROS2Subscriber{type_name}Node"),
                          ids_of_class(slicer.mrmlScene, "vtkMRMLROS2PublisherNode")],
             "sub_class": sub.GetClassName(),
             "delta": sub.GetNumberOfMessages() - before,
             "observer_yaml_same": sub.GetLastMessageYAML() == observer.lastMessageYAML,
             "observer_calls": observer.counter, "events": observer.events,
             "value": value, "value_class": type(received).__name__}
    sub.RemoveObserver(tag)
    found["removed"] = [ros2Node.RemoveAndDeletePublisherNode(topic),
                        ros2Node.RemoveAndDeleteSubscriberNode(topic),
                        ros2Node.RemoveAndDeletePublisherNode(topic)]
    found["gone_from_scene"] = slicer.mrmlScene.GetNodeByID(found["sub_id"]) is None
    return found


def ids_of_class(scene: Any, class_name: str) -> list[str]:
    """What the scene's own GetNodesByClass finds (the C++ classes' IsA)."""
    found = scene.GetNodesByClass(class_name)
    return [found.GetItemAsObject(i).GetID() for i in range(found.GetNumberOfItems())]


def main(session: Any, args: dict[str, Any]) -> dict[str, Any]:
    connect(session, args["port"])
    scene = slicer.mrmlScene
    # Blocked longer than the link's silence bound before any spin (the suite's `ros2 node
    # list` blocks Slicer's thread for seconds): the link must still be up afterwards.
    time.sleep(args.get("block_s", 0.0))
    spin_some()
    out: dict[str, Any] = {"connected_after_block": session.logic.isConnected()}

    ros2Node = scene.AddNewNodeByClass("vtkMRMLROS2NodeNode")  # noqa: N806
    ros2Node.Create("testNode")
    ros_events: list[str] = []
    ros2Node.AddObserver("ModifiedEvent", lambda caller, event: ros_events.append(event))
    ros2Node.Modified()
    out["node"] = {
        "id": ros2Node.GetID(), "name": ros2Node.GetName(),
        "by_id": scene.GetNodeByID(ros2Node.GetID()) is ros2Node,
        "by_name": scene.GetFirstNodeByName("ros2:node:testNode") is ros2Node,
        "by_class": [n.GetID() for n in scene_nodes().nodes_of_class(
            scene, "vtkMRMLROS2NodeNode")],
        "by_scene_class": ids_of_class(scene, "vtkMRMLROS2NodeNode"),
        "is_a": ros2Node.IsA("vtkMRMLROS2NodeNode"),
        "cpp_class": ros2Node.GetClassName(),
        "class_attribute": ros2Node.GetAttribute("ROS2.Class"),
        "events": ros_events}

    sent_matrix = vtk.vtkMatrix4x4()
    sent_matrix.SetElement(2, 3, 3.1415)
    ints = vtk.vtkIntArray()
    ints.SetNumberOfValues(5)
    for i in range(5):
        ints.SetValue(i, i + 1)
    out["pubsub"] = {name: pub_sub(ros2Node, name, sent) for name, sent in (
        ("String", "xkcd"), ("Pose", sent_matrix), ("Double", 3.1415), ("IntArray", ints))}

    # TestParameterNode, on turtlesim (started by the test).
    param = ros2Node.CreateAndAddParameterNode("/turtlesim")
    spin_some()
    out["param_type_before"] = param.GetParameterType("background_r")
    param.AddParameter("background_r")
    param.AddParameter("background_y")
    spin_until(lambda: param.IsParameterSet("background_r"), "background_r fetched")
    set_cmd = subprocess.run([args["python"], args["ros2_cli"], "param", "set", "/turtlesim",
                              "background_g", "150"], capture_output=True, text=True,
                             timeout=60 * SCALE)
    spin_until(lambda: param.IsParameterSet("background_g", True), "background_g changed")
    out["param"] = {"id": param.GetID(), "r_type": param.GetParameterType("background_r"),
                    "y_set": param.IsParameterSet("background_y", True),
                    "g": param.GetParameterAsInteger("background_g"),
                    "set_output": set_cmd.stdout.strip(),
                    "removed": [ros2Node.RemoveAndDeleteParameterNode("/turtlesim"),
                                ros2Node.RemoveAndDeleteParameterNode("/turtlesim")]}

    # TestTf2BroadcasterAndLookupNode, and the lookup node as a transform node.
    broadcaster = ros2Node.CreateAndAddTf2BroadcasterNode("Parent", "Child")
    lookup = ros2Node.CreateAndAddTf2LookupNode("Parent", "Child")
    lookup_events: list[str] = []
    lookup.AddObserver(slicer.vtkMRMLTransformNode.TransformModifiedEvent,
                       lambda caller, event: lookup_events.append(event))
    model = scene.AddNewNodeByClass("vtkMRMLLinearTransformNode", "under the lookup")
    model.SetAndObserveTransformNodeID(lookup.GetID())
    broadcast = vtk.vtkMatrix4x4()
    broadcast.SetElement(0, 3, 66)
    broadcaster.Broadcast(broadcast)
    looked_up = vtk.vtkMatrix4x4()

    def arrived() -> bool:
        lookup.GetMatrixTransformToParent(looked_up)
        return looked_up.GetElement(0, 3) == 66 and len(lookup_events) > 1
    spin_until(arrived, "the broadcast transform at the lookup")
    out["tf"] = {"lookup_id": lookup.GetID(), "broadcaster_id": broadcaster.GetID(),
                 "lookup_is_transform": lookup.IsA("vtkMRMLLinearTransformNode"),
                 "x": looked_up.GetElement(0, 3), "events": len(lookup_events),
                 "model_world_x": world_matrix(model)[0][3],
                 "removed": [ros2Node.RemoveAndDeleteTf2LookupNode("Parent", "Child"),
                             ros2Node.RemoveAndDeleteTf2LookupNode("Parent", "Child"),
                             ros2Node.RemoveAndDeleteTf2BroadcasterNode("Parent", "Child")]}

    # TestServiceClient: one spin, then the response is read.
    spawn = ros2Node.CreateAndAddServiceClientNode("vtkMRMLROS2ServiceClientSpawnNode", "/spawn")
    request = spawn.CreateBlankRequest()
    request.SetX(4.0)
    request.SetY(4.0)
    spawn.SendAsyncRequest(request)
    slicer.util.getModuleLogic("ROS2").Spin()
    response = spawn.GetLastResponse()
    out["service"] = {"id": spawn.GetID(), "name": None if response is None else response.GetName(),
                      "status": spawn.GetLastResponseStatus(),
                      # the request's worker thread did not drive Slicer's connector: the
                      # main thread ran its command
                      "handed_off": session.logic.transport.commands_handed_off}
    ros2Node.Destroy()
    out["after_destroy"] = sorted(n.GetID() for n in scene_nodes().nodes_of_class(
        scene, "vtkMRMLROS2ServiceClientSpawnNode"))
    return out

"""SlicerROS2's own test cases (its Testing/Python/ROS2Tests.py: turtlesim, pub/sub of every
type it tests, parameters, tf2, the service client), with the same calls, in a real scene
where the ROS2Bridge module answers its entry points; plus what issue 42 asks of its nodes
there: found by ID, name and class, observed with VTK's AddObserver, a tf2 lookup node a
transform node models follow. Waits where the suite spins a fixed 100 ms, except for the
service replies, read after one spin or none (GetLastResponse waits for a request in
flight). Last, turtlesim is stopped as the suite stops it (SIGTERM to its process group)
and a request nobody answers ends at its timeout.
"""

from __future__ import annotations

import os
import signal
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


def as_json(received: Any) -> Any:
    """A received message as the test compares it: a matrix's 16 values, an array's values,
    a table's columns, a pose array's header and poses, a wrench's values."""
    if isinstance(received, vtk.vtkMatrix4x4):
        return [received.GetElement(i, j) for i in range(4) for j in range(4)]
    if isinstance(received, vtk.vtkDataArray):
        return [received.GetValue(i) for i in range(received.GetNumberOfValues())]
    if isinstance(received, vtk.vtkTable):
        return [[received.GetValue(row, col).ToDouble()
                 for row in range(received.GetNumberOfRows())]
                for col in range(received.GetNumberOfColumns())]
    if hasattr(received, "GetPoses"):
        header = received.GetHeader()
        return {"frame": header.GetFrameId(), "sec": header.GetStamp().GetSec(),
                "nanosec": header.GetStamp().GetNanosec(),
                "poses": [as_json(pose) for pose in received.GetPoses()]}
    if hasattr(received, "GetWrench"):
        return as_json(received.GetWrench())
    return received


def filled(array: Any, values: list[Any]) -> Any:
    array.SetNumberOfValues(len(values))
    for i, value in enumerate(values):
        array.SetValue(i, value)
    return array


def pose(tx: float, ty: float, tz: float, r00: float, r01: float, r10: float,
         r11: float) -> Any:
    matrix = vtk.vtkMatrix4x4()
    for (row, col), value in {(0, 3): tx, (1, 3): ty, (2, 3): tz, (0, 0): r00, (0, 1): r01,
                              (1, 0): r10, (1, 1): r11}.items():
        matrix.SetElement(row, col, value)
    return matrix


def sent_messages(ros2Node: Any) -> list[tuple[str, Any]]:  # noqa: N803
    """What the suite's TestCreateAndAddPubSub publishes, type by type, built as it does."""
    sent_matrix = vtk.vtkMatrix4x4()
    sent_matrix.SetElement(2, 3, 3.1415)
    tables = []
    for array_type, columns in ((vtk.vtkIntArray, [[3 * i for i in range(3)],
                                                   [4 * i + 1 for i in range(3)]]),
                                (vtk.vtkDoubleArray, [[3.3 * i for i in range(3)],
                                                      [4.4 * i + 1.1 for i in range(3)]])):
        table = vtk.vtkTable()
        for values in columns:
            table.AddColumn(filled(array_type(), values))
        tables.append(table)
    return [("Empty", ""), ("String", "xkcd"), ("Pose", sent_matrix), ("Double", 3.1415),
            ("IntArray", filled(vtk.vtkIntArray(), [1, 2, 3, 4, 5])),
            ("DoubleArray", filled(vtk.vtkDoubleArray(), [1.1, 2.2, 3.3, 4.4, 5.5])),
            ("WrenchStamped", None), ("PoseArray", None),
            ("IntTable", tables[0]), ("DoubleTable", tables[1])]


def blank_message(type_name: str, pub: Any) -> Any:
    """The suite's WrenchStamped and PoseArray messages, filled from GetBlankMessage."""
    message = pub.GetBlankMessage()
    if type_name == "WrenchStamped":
        filled(message.GetWrench(), [1.1, 2.2, 3.3, 4.4, 5.5, 6.6])
        return message
    header = message.GetHeader()
    header.SetFrameId("test_frame")
    header.GetStamp().SetSec(123)
    header.GetStamp().SetNanosec(456)
    message.SetPoses((pose(1.0, 2.0, 3.0, 0, -1, 1, 0),
                      pose(4.0, 5.0, 6.0, 0.707, -0.707, 0.707, 0.707),
                      pose(7.0, 8.0, 9.0, 0.866, -0.5, 0.5, 0.866)))
    return message


def pub_sub(ros2Node: Any, type_name: str, sent: Any) -> dict[str, Any]:  # noqa: N803
    topic = "slicer_test_" + type_name.lower()
    pub = ros2Node.CreateAndAddPublisherNode(type_name, topic)
    sub = ros2Node.CreateAndAddSubscriberNode(type_name, topic)
    if sent is None:
        sent = blank_message(type_name, pub)
    observer = Observer()
    tag = sub.AddObserver("ModifiedEvent", observer.Callback)
    spin_some()
    before = sub.GetNumberOfMessages()
    pub.Publish(sent)
    spin_until(lambda: sub.GetNumberOfMessages() > before, f"the {type_name} message")
    spin_some()
    received = sub.GetLastMessage()
    value = as_json(received)
    found = {"pub_id": pub.GetID(), "sub_id": sub.GetID(), "sub_name": sub.GetName(),
             "sent": as_json(sent),
             "by_id": slicer.mrmlScene.GetNodeByID(sub.GetID()) is sub,
             "by_class": [ids_of_class(slicer.mrmlScene, f"vtkMRMLROS2Subscriber{type_name}Node"),
                          ids_of_class(slicer.mrmlScene, "vtkMRMLROS2PublisherNode")],
             "sub_class": sub.GetClassName(),
             "delta": sub.GetNumberOfMessages() - before,
             "observer_yaml_same": sub.GetLastMessageYAML() == observer.lastMessageYAML,
             "observer_calls": observer.counter, "events": observer.events,
             "value": value, "value_class": type(received).__name__,
             "yaml": sub.GetLastMessageYAML()}
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

    def ros2(*command: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([args["python"], args["ros2_cli"], *command],
                              capture_output=True, text=True, timeout=60 * SCALE)

    def turtlesim_listed() -> bool:  # the suite's check_ros2_node_running
        return "/turtlesim" in ros2("node", "list").stdout.split("\n")
    out["turtlesim_listed"] = turtlesim_listed()  # TestTurtlesimNode, before it is stopped

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

    out["pubsub"] = {name: pub_sub(ros2Node, name, sent)
                     for name, sent in sent_messages(ros2Node)}
    # test_pub_sub_deletion: by the class names, then again (gone), then a name never made.
    ros2Node.CreateAndAddPublisherNode("vtkMRMLROS2PublisherStringNode", "test_string_xkcd")
    ros2Node.CreateAndAddSubscriberNode("vtkMRMLROS2SubscriberStringNode", "test_string_xkcd")
    out["deletion"] = [remove("test_string_xkcd") for remove in (
        ros2Node.RemoveAndDeletePublisherNode, ros2Node.RemoveAndDeletePublisherNode)] + [
        ros2Node.RemoveAndDeletePublisherNode("random_name")] + [
        remove("test_string_xkcd") for remove in (
            ros2Node.RemoveAndDeleteSubscriberNode, ros2Node.RemoveAndDeleteSubscriberNode)] + [
        ros2Node.RemoveAndDeleteSubscriberNode("random_name")]

    # TestParameterNode, on turtlesim (started by the test).
    param = ros2Node.CreateAndAddParameterNode("/turtlesim")
    spin_some()
    # Not added yet, absent, and present but not added: no type.
    out["param_types_before"] = [param.GetParameterType(name) for name in (
        "background_r", "background_y", "background_g")]
    param.AddParameter("background_r")
    param.AddParameter("background_y")
    spin_until(lambda: param.IsParameterSet("background_r"), "background_r fetched")
    set_cmd = ros2("param", "set", "/turtlesim", "background_g", "150")
    spin_until(lambda: param.IsParameterSet("background_g", True), "background_g changed")
    out["param"] = {"id": param.GetID(), "r_type": param.GetParameterType("background_r"),
                    "y_set": param.IsParameterSet("background_y", True),
                    "y_type": param.GetParameterType("background_y"),
                    "g_set": param.IsParameterSet("background_g"),
                    "g_type": param.GetParameterType("background_g"),
                    "g": param.GetParameterAsInteger("background_g"),
                    "set_output": set_cmd.stdout.strip(),
                    "removed": [ros2Node.RemoveAndDeleteParameterNode("/turtlesim"),
                                ros2Node.RemoveAndDeleteParameterNode("/turtlesim")]}
    # The suite's deletion checks: made again, removed, then gone; a name never made.
    ros2Node.CreateAndAddParameterNode("/turtlesim")
    spin_some()
    out["param"]["removed_again"] = [ros2Node.RemoveAndDeleteParameterNode(name) for name in (
        "/turtlesim", "/turtlesim", "/random_name")]

    # TestTf2BroadcasterAndLookupNode, and the lookup node as a transform node.
    broadcaster = ros2Node.CreateAndAddTf2BroadcasterNode("Parent", "Child")
    lookup = ros2Node.CreateAndAddTf2LookupNode("Parent", "Child")
    lookup_events: list[str] = []
    observed_x: list[float] = []  # the suite's TestObserverTf2Lookup reads the matrix

    def on_lookup(caller: Any, event: Any) -> None:
        lookup_events.append(event)
        seen = vtk.vtkMatrix4x4()
        caller.GetMatrixTransformToParent(seen)
        observed_x.append(seen.GetElement(0, 3))
    lookup.AddObserver(slicer.vtkMRMLTransformNode.TransformModifiedEvent, on_lookup)
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
                 "observer_x": observed_x[-1],
                 "model_world_x": world_matrix(model)[0][3],
                 "removed": [ros2Node.RemoveAndDeleteTf2LookupNode("Parent", "Child"),
                             ros2Node.RemoveAndDeleteTf2LookupNode("Parent", "Child"),
                             ros2Node.RemoveAndDeleteTf2BroadcasterNode("Parent", "Child"),
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
                      "class": type(response).__name__,
                      "status": spawn.GetLastResponseStatus(),
                      "pre_request_check": spawn.PreRequestCheck(),
                      # the request's worker thread did not drive Slicer's connector: the
                      # main thread ran its command
                      "handed_off": session.logic.transport.commands_handed_off}
    # Read at once, no spin: each reply is the request's just sent, not the last one.
    in_flight = []
    for name in ("first", "second"):
        request = spawn.CreateBlankRequest()
        request.SetX(2.0)
        request.SetName(name)
        spawn.SendAsyncRequest(request, 4.0 * SCALE)
        response = spawn.GetLastResponse()
        in_flight.append([None if response is None else response.GetName(),
                          spawn.GetLastResponseStatus()])
    out["in_flight"] = in_flight
    # The suite's kill_subprocess: SIGTERM to turtlesim's group; then it is not listed.
    answered = spawn.GetLastResponse()
    os.killpg(int(args["turtlesim_pgid"]), signal.SIGTERM)
    deadline = time.monotonic() + 30 * SCALE
    while turtlesim_listed():
        if time.monotonic() > deadline:
            raise AssertionError("turtlesim still listed 30 s after SIGTERM")
    out["turtlesim_listed_after_kill"] = False
    # A request nobody answers: the wait ends at its timeout, the status says so.
    spawn.SendAsyncRequest(spawn.CreateBlankRequest(), 0.5)
    out["unanswered"] = {"same_response": spawn.GetLastResponse() is answered,
                         "status": spawn.GetLastResponseStatus()}
    ros2Node.Destroy()
    out["after_destroy"] = sorted(n.GetID() for n in scene_nodes().nodes_of_class(
        scene, "vtkMRMLROS2ServiceClientSpawnNode"))
    return out

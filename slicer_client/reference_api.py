"""The reference SlicerROS2's CamelCase API on top of a `Client`, so its documented
examples run with only the logic line changed:

    import slicer_client
    rosLogic = slicer_client.connect("127.0.0.1", 18944)  # was slicer.util.getModuleLogic('ROS2')
    rosNode = rosLogic.GetDefaultROS2Node()
    pub = rosNode.CreateAndAddPublisherNode('String', '/my_string')
    pub.Publish('hello')

Every facade node wraps one resource of the Pythonic API (`.resource`), so both styles can
be mixed. Matrices come back as 4x4 numpy arrays in mm; pass a vtkMatrix4x4 to a getter
(or set ``rosNode.matrix_type = "vtk"``) to get VTK ones. Observers are called as VTK
calls them, ``callback(caller, event)``, in the thread the client delivers events in
(the receive thread unless the client was made with ``callbacks="queue"``).

Deliberate differences from the reference: creating something that exists returns the
existing node (the reference returns None); getters of unknown parameters raise
`KeyError`/`TypeError` naming the parameter instead of returning garbage; there is one
ROS node (the daemon's), so ``Create``/``Destroy`` of extra nodes are not offered.
"""

from __future__ import annotations

import itertools
from typing import Any, Callable, Dict, List, Mapping, Optional, Protocol, Tuple

import numpy as np

from protocol import commands as c
from slicer_client.actions import Action, GoalHandle
from slicer_client.matrices import blank_matrix, fill_vtk, is_vtk_matrix, to_vtk
from slicer_client.resources import (MarkerSubscriber, ParameterClient, Publisher, Resource,
                                     Robot, Service, Subscriber, TfBroadcaster, TfLookup,
                                     parameter_to_python)


class FacadeClient(Protocol):
    """What the facade uses of a `slicer_client.Client` (a protocol, so this module does
    not import the client, which hands the facade out)."""

    daemon_info: Dict[str, Any]

    @property
    def connected(self) -> bool: ...

    def find(self, op: str, *identity: str) -> Optional[Resource]: ...

    def remove_bridge(self, op: str, *identity: str) -> bool: ...

    def subscribe(self, topic: str, type: str, *, qos: Optional[Mapping[str, Any]] = None,
                  rate_hz: Optional[float] = None,
                  callback: Optional[Callable[[Any], None]] = None) -> Subscriber: ...

    def publisher(self, topic: str, type: str, *,
                  qos: Optional[Mapping[str, Any]] = None, frame: Optional[str] = None,
                  labels_topic: Optional[str] = None) -> Publisher: ...

    def parameters(self, node: str) -> ParameterClient: ...

    def tf_lookup(self, parent: str, child: str, *, rate_hz: Optional[float] = None,
                  callback: Optional[Callable[[Any], None]] = None) -> TfLookup: ...

    def tf_broadcaster(self, parent: str, child: str, *,
                       static: bool = False) -> TfBroadcaster: ...

    def service(self, service: str, type: str) -> Service: ...

    def robot(self, name: str, **options: Any) -> Robot: ...

    def markers(self, topic: str, type: str, fixed_frame: str, *,
                qos: Optional[Mapping[str, Any]] = None,
                callback: Optional[Callable[..., None]] = None) -> MarkerSubscriber: ...

    def action(self, name: str, type: str) -> Action: ...

__all__ = ["ActionClientNode", "MarkerSubscriberNode", "ParameterNode", "PublisherNode",
           "ROS2Node", "RobotNode", "ServiceClientNode", "SubscriberNode", "Tf2BroadcasterNode",
           "Tf2LookupNode", "short_type_name"]

# Slicer's integer event ids: vtkCommand::ModifiedEvent, vtkMRMLTransformNode::
# TransformModifiedEvent, and the reference's vtkMRMLROS2ParameterNode::ParameterModifiedEvent
# (vtkCommand::UserEvent + 54).
_VTK_EVENT_NAMES = {33: "ModifiedEvent", 15000: "TransformModifiedEvent",
                    1054: "ParameterModifiedEvent"}
_tags = itertools.count(1)


def short_type_name(class_or_short: str) -> str:
    """'vtkMRMLROS2PublisherStringNode' or 'String' or 'std_msgs/msg/String' -> as the
    daemon takes it (the schema accepts all three; validated here for an early error)."""
    c.resolve_message_type(class_or_short, "className")
    return class_or_short


class _Observable:
    """VTK-style observers: AddObserver(event, callback) -> tag, RemoveObserver(tag)."""

    _events: Tuple[str, ...] = ("ModifiedEvent",)

    def __init__(self) -> None:
        self._observers: Dict[int, Tuple[str, Callable[..., None]]] = {}

    def AddObserver(self, event: Any, callback: Callable[..., None],  # noqa: N802
                    priority: float = 0.0) -> int:
        name = _VTK_EVENT_NAMES.get(event, event) if isinstance(event, int) else str(event)
        if name not in self._events:
            raise ValueError(f"{type(self).__name__}.AddObserver: expected one of "
                             f"{', '.join(self._events)}, got {event!r}")
        tag = next(_tags)
        self._observers[tag] = (name, callback)
        return tag

    def RemoveObserver(self, tag: int) -> None:  # noqa: N802
        self._observers.pop(tag, None)

    def RemoveAllObservers(self) -> None:  # noqa: N802
        self._observers.clear()

    def HasObserver(self, event: Any) -> bool:  # noqa: N802
        name = _VTK_EVENT_NAMES.get(event, event) if isinstance(event, int) else str(event)
        return any(n == name for n, _ in self._observers.values())

    def InvokeEvent(self, event: str) -> None:  # noqa: N802
        for name, callback in list(self._observers.values()):
            if name == event:
                callback(self, event)


class _Node(_Observable):
    def __init__(self, ros_node: ROS2Node, resource: Any) -> None:
        super().__init__()
        self._ros_node = ros_node
        self.resource = resource

    def _matrix_out(self, matrix: Optional[np.ndarray], target: Any) -> Any:
        if matrix is None:
            return None
        if target is not None and is_vtk_matrix(target):
            return fill_vtk(matrix, target)
        if self._ros_node.matrix_type == "vtk":
            return to_vtk(matrix)
        return matrix.copy()


# What GetBlankMessage gives per ROS type: the reference returns a new Slicer object of the
# publisher's Slicer type; these are the same kinds of value that Publish takes here.
_BLANK_SCALARS: Dict[str, Any] = {
    "std_msgs/msg/String": "", "std_msgs/msg/Bool": False, "std_msgs/msg/Int64": 0,
    "std_msgs/msg/Int32": 0, "std_msgs/msg/Float64": 0.0, "std_msgs/msg/Float32": 0.0,
}
_MATRIX_TYPES = frozenset({"geometry_msgs/msg/Pose", "geometry_msgs/msg/PoseStamped",
                           "geometry_msgs/msg/Transform", "geometry_msgs/msg/TransformStamped"})
_LIST_TYPES = frozenset({"std_msgs/msg/Int64MultiArray", "std_msgs/msg/Float64MultiArray",
                         "geometry_msgs/msg/PoseArray"})


def blank_message(ros_type: str) -> Any:
    """A new, empty value for `ros_type`: an identity matrix (vtkMatrix4x4 in Slicer) for
    poses, "" / False / 0 / 0.0 for scalars, [] for arrays and pose arrays, and {} (every
    field at its default) for any other type."""
    full = c.resolve_message_type(ros_type, "type")
    if full in _MATRIX_TYPES:
        return blank_matrix()
    if full in _BLANK_SCALARS:
        return _BLANK_SCALARS[full]
    if full in _LIST_TYPES:
        return []
    if full == "geometry_msgs/msg/WrenchStamped":
        return [0.0] * 6
    return {}


class SubscriberNode(_Node):
    resource: Subscriber

    def __init__(self, ros_node: ROS2Node, resource: Subscriber) -> None:
        super().__init__(ros_node, resource)
        resource.add_callback(lambda value: self.InvokeEvent("ModifiedEvent"))

    def GetName(self) -> str:  # noqa: N802
        return f"ros2:sub:{self.resource.topic}"

    def GetTopic(self) -> str:  # noqa: N802
        return self.resource.topic

    def GetROSType(self) -> str:  # noqa: N802
        return self.resource.ros_type

    def GetNumberOfMessages(self) -> int:  # noqa: N802
        """Messages the daemon's subscription received (exact even when the stream to this
        client is rate-capped or coalesced)."""
        return self.resource.daemon_count()

    def GetLastMessage(self, target: Any = None) -> Any:  # noqa: N802
        """The last message as a Slicer value (str, bool, int, float, list, 4x4 matrix in
        mm...); None before the first one."""
        value = self.resource.last_value
        if isinstance(value, np.ndarray) and value.shape == (4, 4):
            return self._matrix_out(value, target)
        return value

    def GetLastMessageYAML(self) -> str:  # noqa: N802
        return self.resource.last_message_yaml()

    def GetBlankMessage(self) -> Any:  # noqa: N802
        return blank_message(self.GetROSType())


class PublisherNode(_Node):
    resource: Publisher

    def GetName(self) -> str:  # noqa: N802
        return f"ros2:pub:{self.resource.topic}"

    def GetTopic(self) -> str:  # noqa: N802
        return self.resource.topic

    def GetROSType(self) -> str:  # noqa: N802
        return str(self.resource.info.get("type", c.resolve_message_type(self.resource.type)))

    def GetNumberOfMessages(self) -> int:  # noqa: N802
        return self.resource.sent

    def GetBlankMessage(self) -> Any:  # noqa: N802
        """A new value to fill and publish, of the kind this publisher takes."""
        return blank_message(self.GetROSType())

    def SendModel(self, model: Any) -> None:  # noqa: N802
        """Stream a model (PolyData in mm, or (points, polygons)) to a Mesh or Marker
        publisher."""
        self.resource.send_model(model)

    def SendMarkups(self, points: Any, labels: Optional[List[str]] = None) -> None:  # noqa: N802
        """Stream markups points ((N, 3) mm, labels) to a PoseArray, PointStamped or Path
        publisher."""
        self.resource.send_points(points, labels)

    def Publish(self, value: Any) -> int:  # noqa: N802
        """Publish; returns the number of ROS subscribers (as the reference)."""
        if hasattr(value, "GetMatrixTransformToParent") and not is_vtk_matrix(value):
            value = _transform_node_matrix(value)
        return self.resource.publish(value)


class ParameterNode(_Node):
    """The reference's parameter node: tracks some parameters of one ROS node."""

    resource: ParameterClient
    _events = ("ParameterModifiedEvent", "ModifiedEvent")

    def __init__(self, ros_node: ROS2Node, resource: ParameterClient) -> None:
        super().__init__(ros_node, resource)
        self._tracked: List[str] = list(resource.observed)
        resource.add_callback(self._changed)

    def _changed(self, name: str, value: Any) -> None:
        self.InvokeEvent("ParameterModifiedEvent")
        self.InvokeEvent("ModifiedEvent")

    def GetName(self) -> str:  # noqa: N802
        return f"ros2:param:{self.resource.node}"

    def GetMonitoredNodeName(self) -> str:  # noqa: N802
        return self.resource.node

    def AddParameter(self, name: str) -> bool:  # noqa: N802
        """Track (and observe) one parameter. Returns at once, as the reference does: the
        value is fetched now if the node is there, else pushed when it appears
        (`IsParameterSet` is False until then)."""
        if name not in self._tracked:
            ready = self.resource.observe([*self._tracked, name])
            self._tracked.append(name)
        else:
            ready = self.resource.ready
        if ready and name not in self.resource.values:
            self.resource.get_typed([name])
        return True

    def RemoveParameter(self, name: str) -> bool:  # noqa: N802
        if name not in self._tracked:
            return False
        self._tracked.remove(name)
        self.resource.observe(self._tracked)
        self.resource.values.pop(name, None)
        return True

    def GetParameterNames(self) -> List[str]:  # noqa: N802
        return list(self._tracked)

    GetTrackedParametersList = GetParameterNames

    def ListTrackedParameters(self) -> str:  # noqa: N802
        return "\n".join(self._tracked)

    def _typed(self, name: str) -> c.ParameterValue:
        if name not in self._tracked:
            raise KeyError(f"parameter {name!r} of {self.resource.node} is not tracked: "
                           f"call AddParameter({name!r}) first")
        # Never blocks: the daemon pushes observed values when they change or the node
        # appears; until then the parameter is not set.
        value = self.resource.values.get(name)
        return c.ParameterValue("not_set", None) if value is None else value

    def IsParameterSet(self, name: str) -> bool:  # noqa: N802
        return name in self._tracked and self._typed(name).type != "not_set"

    def GetParameterType(self, name: str) -> str:  # noqa: N802
        """"bool", "integer", "double", "string", "bool_array", "integer_array",
        "double_array", "string_array", "byte_array", "not_set"; "" if not tracked."""
        return self._typed(name).type if name in self._tracked else ""

    def _as(self, name: str, *types: str) -> Any:
        value = self._typed(name)
        if value.type not in types:
            raise TypeError(f"parameter {name!r} of {self.resource.node} is "
                            f"{value.type}, not {' or '.join(types)}")
        return parameter_to_python(value)

    def GetParameterAsBool(self, name: str) -> bool:  # noqa: N802
        return bool(self._as(name, "bool"))

    def GetParameterAsInteger(self, name: str) -> int:  # noqa: N802
        return int(self._as(name, "integer"))

    def GetParameterAsDouble(self, name: str) -> float:  # noqa: N802
        return float(self._as(name, "double", "integer"))

    def GetParameterAsString(self, name: str) -> str:  # noqa: N802
        return str(self._as(name, "string"))

    def GetParameterAsVectorOfBools(self, name: str) -> List[bool]:  # noqa: N802
        return [bool(v) for v in self._as(name, "bool_array")]

    def GetParameterAsVectorOfIntegers(self, name: str) -> List[int]:  # noqa: N802
        return [int(v) for v in self._as(name, "integer_array", "byte_array")]

    def GetParameterAsVectorOfDoubles(self, name: str) -> List[float]:  # noqa: N802
        return [float(v) for v in self._as(name, "double_array", "integer_array")]

    def GetParameterAsVectorOfStrings(self, name: str) -> List[str]:  # noqa: N802
        return [str(v) for v in self._as(name, "string_array")]

    def PrintParameter(self, name: str) -> str:  # noqa: N802
        """The value as text, as the reference's PrintParameterValue."""
        value = self._typed(name)
        raw = parameter_to_python(value)
        if value.type == "bool":
            return "true" if raw else "false"
        if value.type.endswith("_array"):
            return "[" + ", ".join(str(v).lower() if isinstance(v, bool) else str(v)
                                   for v in raw) + "]"
        return "" if raw is None else str(raw)

    PrintParameterValue = PrintParameter

    def SetParameter(self, name: str, value: Any, type: Optional[str] = None) -> bool:  # noqa: N802
        """Not in the reference (its parameter node is read-only); offered for symmetry."""
        self.resource.set(name, value, type=type)
        return True


class Tf2BroadcasterNode(_Node):
    resource: TfBroadcaster

    def GetName(self) -> str:  # noqa: N802
        return f"ros2:tf2broadcaster:{self.resource.parent}To{self.resource.child}"

    def GetParentID(self) -> str:  # noqa: N802
        return self.resource.parent

    def GetChildID(self) -> str:  # noqa: N802
        return self.resource.child

    def GetNumberOfBroadcasts(self) -> int:  # noqa: N802
        return self.resource.count

    def Broadcast(self, matrix: Any) -> bool:  # noqa: N802
        """A 4x4 in mm (numpy, lists, vtkMatrix4x4) or a Slicer transform node."""
        if hasattr(matrix, "GetMatrixTransformToParent") and not is_vtk_matrix(matrix):
            matrix = _transform_node_matrix(matrix)
        self.resource.broadcast(matrix)
        return True

    def ObserveTransformNode(self, transform_node: Any) -> int:  # noqa: N802
        """Broadcast whenever a Slicer transform node changes (inside 3D Slicer)."""
        event = getattr(transform_node, "TransformModifiedEvent", 15000)
        return int(transform_node.AddObserver(
            event, lambda caller, _event: self.Broadcast(caller)))


class Tf2LookupNode(_Node):
    resource: TfLookup
    _events = ("ModifiedEvent", "TransformModifiedEvent")

    def __init__(self, ros_node: ROS2Node, resource: TfLookup) -> None:
        super().__init__(ros_node, resource)
        resource.add_callback(self._changed)

    def _changed(self, matrix: np.ndarray) -> None:
        self.InvokeEvent("TransformModifiedEvent")
        self.InvokeEvent("ModifiedEvent")

    def GetName(self) -> str:  # noqa: N802
        return f"ros2:tf2lookup:{self.resource.parent}To{self.resource.child}"

    def GetParentID(self) -> str:  # noqa: N802
        return self.resource.parent

    def GetChildID(self) -> str:  # noqa: N802
        return self.resource.child

    def IsParentAndChildSet(self) -> bool:  # noqa: N802
        return bool(self.resource.parent and self.resource.child)

    def GetMatrixTransformToParent(self, target: Any = None) -> Any:  # noqa: N802
        """The latest parent -> child (4x4, mm); the identity until tf connects them, as
        the reference's lookup node (a transform node) gives."""
        matrix = self.resource.matrix
        return self._matrix_out(np.eye(4) if matrix is None else matrix, target)


class RobotNode(_Node):
    resource: Robot

    def __init__(self, ros_node: ROS2Node, resource: Robot) -> None:
        super().__init__(ros_node, resource)
        resource.add_callback(lambda *args: self.InvokeEvent("ModifiedEvent"))

    def GetName(self) -> str:  # noqa: N802
        return f"ros2:robot:{self.resource.name}"

    def GetRobotName(self) -> str:  # noqa: N802
        return self.resource.name

    def GetNumberOfLinks(self) -> int:  # noqa: N802
        return len(self.resource.links)

    def GetLinkNames(self) -> List[str]:  # noqa: N802
        return sorted(self.resource.links)

    def GetLinkTransform(self, link: str, target: Any = None) -> Any:  # noqa: N802
        entry = self.resource.links.get(link)
        return None if entry is None else self._matrix_out(entry.matrix, target)

    def GetJointNames(self) -> List[str]:  # noqa: N802
        """The joints a client sets (actuated: moving, not mimic), in URDF order."""
        return [str(j["name"]) for j in self.resource.joints()["joints"] if j["actuated"]]

    def GetJointLimits(self, joint: str) -> Optional[Tuple[float, float]]:  # noqa: N802
        """(lower, upper) in radians or metres; None for a continuous joint."""
        for j in self.resource.joints()["joints"]:
            if j["name"] == joint:
                return None if j["lower"] is None else (float(j["lower"]), float(j["upper"]))
        raise KeyError(f"robot {self.resource.name} has no joint {joint!r}")

    def SetJointPositions(self, positions: Dict[str, float]) -> Dict[str, float]:  # noqa: N802
        """Publish a sensor_msgs/JointState (radians, metres); the daemon refuses values
        outside the URDF limits naming the joint and adds the mimic joints."""
        result = self.resource.set_joints(positions)
        self.InvokeEvent("ModifiedEvent")
        return result


class MarkerSubscriberNode(_Node):
    """A marker topic (not in the reference, which has no markers): named in its style.
    ModifiedEvent fires when a marker arrives, changes or is deleted."""

    resource: MarkerSubscriber

    def __init__(self, ros_node: ROS2Node, resource: MarkerSubscriber) -> None:
        super().__init__(ros_node, resource)
        resource.add_callback(lambda kind, *args: self.InvokeEvent("ModifiedEvent")
                              if kind != "frame" else None)

    def GetName(self) -> str:  # noqa: N802
        return f"ros2:markers:{self.resource.topic}"

    def GetTopic(self) -> str:  # noqa: N802
        return self.resource.topic

    def GetFixedFrame(self) -> str:  # noqa: N802
        return self.resource.fixed_frame

    def GetNumberOfMarkers(self) -> int:  # noqa: N802
        return len(self.resource.markers)

    def GetMarkerDeviceNames(self) -> List[str]:  # noqa: N802
        return sorted(self.resource.markers)


class ServiceClientNode(_Node):
    """A service client; the reference generates one class per service type, here any
    installed service type works."""

    resource: Service

    def __init__(self, ros_node: ROS2Node, resource: Service) -> None:
        super().__init__(ros_node, resource)
        self._last: Optional[Dict[str, Any]] = None

    def GetTopic(self) -> str:  # noqa: N802
        return self.resource.service

    def SendBlockingRequest(self, request: Optional[Dict[str, Any]] = None,  # noqa: N802
                            timeout: float = 4.0) -> Dict[str, Any]:
        self._last = self.resource.call(request, timeout)
        self.InvokeEvent("ModifiedEvent")
        return self._last

    def SendAsyncRequest(self, request: Optional[Dict[str, Any]] = None,  # noqa: N802
                         timeout: float = 4.0) -> None:
        def done(response: Optional[Dict[str, Any]], error: Optional[Exception]) -> None:
            if error is None:
                self._last = response
                self.InvokeEvent("ModifiedEvent")
        self.resource.call_async(request, done, timeout)

    def GetLastResponse(self) -> Optional[Dict[str, Any]]:  # noqa: N802
        return self._last


class ActionClientNode(_Node):
    """An action client in the reference's style (the reference has none; named like its
    service client node): `SendGoal` returns the goal id at once, feedback and the result
    arrive as ModifiedEvent, read with `GetLastFeedback` / `GetLastResult`."""

    resource: Action

    def __init__(self, ros_node: ROS2Node, resource: Action) -> None:
        super().__init__(ros_node, resource)
        self._goal: Optional[GoalHandle] = None

    def GetName(self) -> str:  # noqa: N802
        return f"ros2:action:{self.resource.name}"

    def GetAction(self) -> str:  # noqa: N802
        return self.resource.name

    GetTopic = GetAction

    def GetROSType(self) -> str:  # noqa: N802
        return self.resource.type

    def SendGoal(self, goal: Optional[Dict[str, Any]] = None,  # noqa: N802
                 timeout: float = 4.0) -> str:
        """Send a goal (the latest one is the one the getters read); returns its id."""
        self._goal = self.resource.send_goal(
            goal, feedback=lambda fields: self.InvokeEvent("ModifiedEvent"), timeout=timeout)
        # Observers hear of the end as of each feedback (a thread waits for it).
        _wait_then(self._goal, lambda: self.InvokeEvent("ModifiedEvent")).start()
        return self._goal.goal_id

    def CancelGoal(self, timeout: float = 4.0) -> bool:  # noqa: N802
        return self._goal is not None and not self._goal.done and self._goal.cancel(timeout)

    def GetGoalStatus(self) -> str:  # noqa: N802
        """"sending", "accepted", "executing", then how it ended: "succeeded",
        "canceled", "aborted", "lost", "timeout"; "" before any goal."""
        return "" if self._goal is None else self._goal.status

    def GetNumberOfFeedbacks(self) -> int:  # noqa: N802
        return 0 if self._goal is None else len(self._goal.feedback)

    def GetLastFeedback(self) -> Optional[Dict[str, Any]]:  # noqa: N802
        if self._goal is None or not self._goal.feedback:
            return None
        return dict(self._goal.feedback[-1])

    def GetLastResult(self) -> Optional[Dict[str, Any]]:  # noqa: N802
        """The result of the latest goal once it ended (None before, or if it ended
        without one: see GetGoalStatus)."""
        if self._goal is None or not self._goal.done:
            return None
        try:
            return self._goal.result(0)
        except Exception:  # noqa: BLE001 - no result: the status says why
            return None

    def WaitForResult(self, timeout: float = 10.0) -> Dict[str, Any]:  # noqa: N802
        if self._goal is None:
            raise RuntimeError(f"no goal sent to {self.resource.name} yet")
        return self._goal.result(timeout)


def _wait_then(goal: GoalHandle, then: Callable[[], None]) -> Any:
    import threading

    def run() -> None:
        try:
            goal.result(None)
        except Exception:  # noqa: BLE001 - an end without a result is an end too
            pass
        then()
    return threading.Thread(target=run, name=f"goal {goal.goal_id}", daemon=True)


def _transform_node_matrix(node: Any) -> Any:
    import vtk  # only Slicer transform nodes get here, so vtk is there
    matrix = vtk.vtkMatrix4x4()
    node.GetMatrixTransformToParent(matrix)
    return matrix


class ROS2Node:
    """The reference's ``vtkMRMLROS2NodeNode``: the daemon's ROS node, seen from here."""

    def __init__(self, client: FacadeClient) -> None:
        self.client = client
        self.matrix_type = "numpy"  # or "vtk"
        self._nodes: Dict[Tuple[str, ...], _Node] = {}
        self._services: Dict[str, ServiceClientNode] = {}
        self._actions: Dict[str, ActionClientNode] = {}

    def _wrap(self, resource: Resource, cls: Any) -> Any:
        node = self._nodes.get(resource.spec.key)
        if node is None or node.resource is not resource:
            node = cls(self, resource)
            self._nodes[resource.spec.key] = node
        return node

    def _get(self, *key: str) -> Any:
        resource = self.client.find(*key)
        return None if resource is None else self._nodes.get(resource.spec.key)

    def _drop(self, *key: str) -> bool:
        """Remove a bridge: one this connection made, or one the daemon keeps from another
        (an earlier connection's, another client's) if its rules allow; False if there is
        none. A refusal (an operator's bridge, a --read-only daemon) raises."""
        resource = self.client.find(*key)
        removed = self.client.remove_bridge(*key)
        node = self._nodes.pop(resource.spec.key, None) if resource is not None else None
        if node is not None:
            node.RemoveAllObservers()
        return removed

    def GetROS2NodeName(self) -> str:  # noqa: N802
        return str(self.client.daemon_info.get("node", "/slicer_bridge"))

    GetName = GetROS2NodeName

    def Spin(self) -> None:  # noqa: N802
        """The daemon spins its node itself; kept so reference scripts run unchanged."""

    def GetSpinning(self) -> bool:  # noqa: N802
        return self.client.connected

    def RegisteredROS2SubscriberNodes(self) -> str:  # noqa: N802
        return " ".join(f"vtkMRMLROS2Subscriber{n}Node" for n in c.REFERENCE_TYPE_NAMES)

    def RegisteredROS2PublisherNodes(self) -> str:  # noqa: N802
        return " ".join(f"vtkMRMLROS2Publisher{n}Node" for n in c.REFERENCE_TYPE_NAMES)

    # topics
    def CreateAndAddSubscriberNode(self, className: str, topic: str) -> SubscriberNode:  # noqa: N802,N803
        sub = self.client.subscribe(topic, short_type_name(className))
        return self._wrap(sub, SubscriberNode)

    def CreateAndAddPublisherNode(self, className: str, topic: str,  # noqa: N802,N803
                                  frame: str = "",
                                  labelsTopic: str = "") -> PublisherNode:  # noqa: N803
        """``frame`` / ``labelsTopic``: this bridge's additions for models and markups
        sent to ROS (not in the reference)."""
        pub = self.client.publisher(topic, short_type_name(className), frame=frame or None,
                                    labels_topic=labelsTopic or None)
        return self._wrap(pub, PublisherNode)

    def GetSubscriberNodeByTopic(self, topic: str) -> Optional[SubscriberNode]:  # noqa: N802
        return self._get("create_subscriber", topic)

    def GetPublisherNodeByTopic(self, topic: str) -> Optional[PublisherNode]:  # noqa: N802
        return self._get("create_publisher", topic)

    def RemoveAndDeleteSubscriberNode(self, topic: str) -> bool:  # noqa: N802
        return self._drop("create_subscriber", topic)

    def RemoveAndDeletePublisherNode(self, topic: str) -> bool:  # noqa: N802
        return self._drop("create_publisher", topic)

    # parameters
    def CreateAndAddParameterNode(self, nodeName: str) -> ParameterNode:  # noqa: N802,N803
        return self._wrap(self.client.parameters(nodeName), ParameterNode)

    def GetParameterNodeByNode(self, nodeName: str) -> Optional[ParameterNode]:  # noqa: N802,N803
        return self._get("create_parameter_client", nodeName)

    def RemoveAndDeleteParameterNode(self, nodeName: str) -> bool:  # noqa: N802,N803
        return self._drop("create_parameter_client", nodeName)

    # tf2
    def CreateAndAddTf2BroadcasterNode(self, parent_id: str, child_id: str  # noqa: N802
                                       ) -> Tf2BroadcasterNode:
        return self._wrap(self.client.tf_broadcaster(parent_id, child_id), Tf2BroadcasterNode)

    def CreateAndAddTf2LookupNode(self, parent_id: str, child_id: str  # noqa: N802
                                  ) -> Tf2LookupNode:
        return self._wrap(self.client.tf_lookup(parent_id, child_id), Tf2LookupNode)

    def GetTf2BroadcasterNodeByParentChild(self, parent_id: str, child_id: str  # noqa: N802
                                           ) -> Optional[Tf2BroadcasterNode]:
        return self._get("create_tf_broadcaster", parent_id, child_id)

    def GetTf2LookupNodeByParentChild(self, parent_id: str, child_id: str  # noqa: N802
                                      ) -> Optional[Tf2LookupNode]:
        return self._get("create_tf_lookup", parent_id, child_id)

    def RemoveAndDeleteTf2BroadcasterNode(self, parent_id: str, child_id: str) -> bool:  # noqa: N802
        return self._drop("create_tf_broadcaster", parent_id, child_id)

    def RemoveAndDeleteTf2LookupNode(self, parent_id: str, child_id: str) -> bool:  # noqa: N802
        return self._drop("create_tf_lookup", parent_id, child_id)

    # robots
    def CreateAndAddRobotNode(self, robotName: str,  # noqa: N802,N803
                              parameterNodeName: str = "/robot_state_publisher",  # noqa: N803
                              parameterName: str = "robot_description",  # noqa: N803
                              fixedFrame: str = "", tfPrefix: str = "") -> RobotNode:  # noqa: N803
        robot = self.client.robot(robotName, node=parameterNodeName, parameter=parameterName,
                                  fixed_frame=fixedFrame or None, tf_prefix=tfPrefix)
        return self._wrap(robot, RobotNode)

    def GetRobotNodeByName(self, robotName: str) -> Optional[RobotNode]:  # noqa: N802,N803
        return self._get("create_robot", robotName)

    def RemoveAndDeleteRobotNode(self, robotName: str) -> bool:  # noqa: N802,N803
        return self._drop("create_robot", robotName)

    # markers (not in the reference)
    def CreateAndAddMarkerSubscriberNode(self, className: str, topic: str,  # noqa: N802,N803
                                         fixedFrame: str) -> MarkerSubscriberNode:  # noqa: N803
        """`className`: Marker, MarkerArray, Path, PolygonStamped or PointStamped."""
        markers = self.client.markers(topic, className, fixedFrame)
        return self._wrap(markers, MarkerSubscriberNode)

    def GetMarkerSubscriberNodeByTopic(self, topic: str  # noqa: N802
                                       ) -> Optional[MarkerSubscriberNode]:
        return self._get("create_marker_subscriber", topic)

    def RemoveAndDeleteMarkerSubscriberNode(self, topic: str) -> bool:  # noqa: N802
        return self._drop("create_marker_subscriber", topic)

    # services
    def CreateAndAddServiceClientNode(self, className: str, service: str  # noqa: N802,N803
                                      ) -> ServiceClientNode:
        node = self._services.get(service)
        if node is None:
            node = ServiceClientNode(self, self.client.service(service, className))
            self._services[service] = node
        return node

    def GetServiceClientNodeByTopic(self, service: str) -> Optional[ServiceClientNode]:  # noqa: N802
        return self._services.get(service)

    def RemoveAndDeleteServiceClientNode(self, service: str) -> bool:  # noqa: N802
        return self._services.pop(service, None) is not None

    # actions (the reference has none: named like its service client nodes)
    def CreateAndAddActionClientNode(self, className: str, action: str  # noqa: N802,N803
                                     ) -> ActionClientNode:
        node = self._actions.get(action)
        if node is None:
            node = ActionClientNode(self, self.client.action(action, className))
            self._actions[action] = node
        return node

    def GetActionClientNodeByName(self, action: str) -> Optional[ActionClientNode]:  # noqa: N802
        return self._actions.get(action)

    def RemoveAndDeleteActionClientNode(self, action: str) -> bool:  # noqa: N802
        node = self._actions.pop(action, None)
        if node is not None:
            node.RemoveAllObservers()
        return node is not None

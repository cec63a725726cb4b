"""The reference SlicerROS2's node classes (``vtkMRMLROS2...Node``) over a `Client`.

Each facade node wraps one resource of the Pythonic API (`.resource`), so both styles mix.
What the reference returns as VTK objects comes back as VTK objects where vtk imports (3D
Slicer), else as plain objects with the same methods (vtk_values.py); message types get
message objects (messages.py); the table of which is in slicer_types.py.

Reads are local: a subscriber keeps its last message whole (the daemon's message stream,
whose newest comes at most once a display frame: ModifiedEvent fires as often), so
``GetLastMessage``, ``GetLastMessageYAML`` and ``GetNumberOfMessages`` never ask the
daemon, and an observer may call them, or anything else, from its callback. Observers are
called as VTK calls them, ``callback(caller, event)``, where the client runs callbacks:
in ``Spin()`` or on its dispatcher thread, never on the receive thread (events.py).

Deliberate differences from the reference are listed, with their reasons, in
slicer_client/README.md ("The reference's API, method by method").
"""

from __future__ import annotations

import itertools
import json
import logging
import threading
import time
from typing import (Any, Callable, Dict, Hashable, List, Mapping, Optional, Protocol, Tuple, Type,
                    TypeVar)

import numpy as np

from protocol import commands as c
from protocol.messages import Message
from protocol.yaml_text import to_yaml
from slicer_client.actions import Action, GoalHandle
from slicer_client.matrices import fill_vtk, is_vtk_matrix
from slicer_client.reference.messages import MessageObject, MessageTypes, MessageValueError
from slicer_client.reference.slicer_types import SlicerType, slicer_type_for
from slicer_client.reference.vtk_values import SlicerValues
from slicer_client.resources import (MarkerSubscriber, ParameterClient, Publisher, Resource,
                                     Robot, Service, Subscriber, TfBroadcaster, TfLookup,
                                     parameter_to_python)

__all__ = ["ActionClientNode", "EVENT_IDS", "MarkerSubscriberNode", "NodeFactory",
           "ParameterNode", "PlainNodes", "PublisherNode", "ROS2Node", "Recipe", "RobotNode",
           "ServiceClientNode", "SubscriberNode", "Tf2BroadcasterNode", "Tf2LookupNode",
           "reference_base_class", "reference_class"]

log = logging.getLogger("slicer_client")

# Slicer's integer event ids: vtkCommand::ModifiedEvent, vtkMRMLTransformNode::
# TransformModifiedEvent, and the reference's vtkMRMLROS2ParameterNode::ParameterModifiedEvent
# (vtkCommand::UserEvent + 54).
_VTK_EVENT_NAMES = {33: "ModifiedEvent", 15000: "TransformModifiedEvent",
                    1054: "ParameterModifiedEvent"}
EVENT_IDS = {name: number for number, name in _VTK_EVENT_NAMES.items()}
_tags = itertools.count(1)
_N = TypeVar("_N")
# How long past a request's timeout a read waits for its end: the call's own timeout ends
# on the worker thread a moment after (a failure is noted then).
REPLY_GRACE_S = 1.0

# How a facade node was made: the logic's or its ROS node's method and its arguments
# (("CreateAndAddSubscriberNode", "String", "/chatter")); a saved scene's nodes are made
# again by calling it (the ROS2Bridge module, ROS2BridgeLib/scene_nodes.py).
Recipe = Tuple[str, ...]

# The reference's class of the node each method makes ("{}": its type's name).
_REFERENCE_CLASSES = {
    "GetDefaultROS2Node": "Node", "CreateROS2Node": "Node",
    "CreateAndAddSubscriberNode": "Subscriber{}", "CreateAndAddPublisherNode": "Publisher{}",
    "CreateAndAddParameterNode": "Parameter", "CreateAndAddTf2BroadcasterNode": "Tf2Broadcaster",
    "CreateAndAddTf2LookupNode": "Tf2Lookup", "CreateAndAddRobotNode": "Robot",
    "CreateAndAddMarkerSubscriberNode": "MarkerSubscriber",
    "CreateAndAddServiceClientNode": "ServiceClient{}",
    "CreateAndAddActionClientNode": "ActionClient{}"}


def reference_class(recipe: Recipe) -> str:
    """The reference's class name of the node `recipe` makes: ``vtkMRMLROS2NodeNode``,
    ``vtkMRMLROS2SubscriberStringNode`` (from "String", "std_msgs/msg/String" or the class
    name itself), ``vtkMRMLROS2ServiceClientSpawnNode``..."""
    pattern = _REFERENCE_CLASSES.get(recipe[0]) if recipe else None
    if pattern is None:
        raise ValueError(f"expected a recipe starting with one of "
                         f"{', '.join(_REFERENCE_CLASSES)}, got {recipe!r}")
    stem = ""
    if "{}" in pattern:
        if len(recipe) < 2:
            raise ValueError(f"expected {recipe[0]}'s class name after it, got {recipe!r}")
        kind = pattern.replace("{}", "")
        stem = recipe[1].strip().rsplit("/", 1)[-1]
        if stem.startswith(f"vtkMRMLROS2{kind}") and stem.endswith("Node"):
            stem = stem[len(f"vtkMRMLROS2{kind}"):-len("Node")]
        stem = "".join(ch for ch in stem if ch.isalnum())
    return f"vtkMRMLROS2{pattern.format(stem)}Node"


def reference_base_class(recipe: Recipe) -> str:
    """The reference's base class of the node `recipe` makes: ``vtkMRMLROS2SubscriberNode``
    for any subscriber, ``vtkMRMLROS2NodeNode`` for a ROS node (its own class)."""
    reference_class(recipe)  # the same checks
    return f"vtkMRMLROS2{_REFERENCE_CLASSES[recipe[0]].format('')}Node"


class NodeFactory(Protocol):
    """Makes the facade's nodes: plain Python objects (`PlainNodes`), or MRML nodes in 3D
    Slicer's scene (the ROS2Bridge module's factory)."""

    def make(self, cls: type, recipe: Recipe, owner: Optional[ROS2Node], *args: Any) -> Any:
        """A new `cls(*args)`, made by `owner` (None: by the logic) with `recipe`."""

    def changed(self, node: Any) -> None:
        """`node`'s name or recipe changed (a ROS node's Create, a tf2 node's frames)."""

    def discard(self, node: Any) -> None:
        """`node` was removed by its ROS node (RemoveAndDelete..., Destroy)."""


class PlainNodes:
    """Facade nodes as plain Python objects: the client outside Slicer."""

    def make(self, cls: type, recipe: Recipe, owner: Optional[ROS2Node], *args: Any) -> Any:
        node = cls(*args)
        node.recipe = tuple(recipe)
        return node

    def changed(self, node: Any) -> None:
        pass

    def discard(self, node: Any) -> None:
        pass


class FacadeClient(Protocol):
    """What the facade uses of a `slicer_client.Client`."""

    daemon_info: Dict[str, Any]

    @property
    def connected(self) -> bool: ...

    @property
    def events(self) -> Any: ...

    def serve_other_threads(self) -> None: ...

    def find(self, op: str, *identity: str) -> Optional[Resource]: ...

    def remove_bridge(self, op: str, *identity: str) -> bool: ...

    def subscribe(self, topic: str, type: str, *, qos: Optional[Mapping[str, Any]] = None,
                  rate_hz: Optional[float] = None,
                  callback: Optional[Callable[[Any], None]] = None,
                  messages: bool = False, native: bool = True) -> Subscriber: ...

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

    def describe_type(self, type_name: str, kind: str = "message") -> c.TypeDescription: ...

    def list_services(self) -> List[Dict[str, Any]]: ...

    def emit(self, callback: Callable[..., None], *args: Any) -> None: ...

    def emit_newest(self, key: Hashable, callback: Callable[..., None], *args: Any) -> None: ...


class Logic(Protocol):
    """What nodes need of the logic that made them (logic.py)."""

    client: FacadeClient
    types: MessageTypes
    values: SlicerValues
    nodes: NodeFactory

    def Spin(self) -> None: ...  # noqa: N802

    def add_tick(self, hook: Callable[[], None]) -> None: ...

    def remove_tick(self, hook: Callable[[], None]) -> None: ...

    def spinning_here(self) -> bool: ...

    def hold(self, key: Tuple[str, ...], owner: Any) -> None: ...

    def release(self, key: Tuple[str, ...], owner: Any) -> bool: ...


class _Observable:
    """VTK-style observers: AddObserver(event, callback) -> tag, RemoveObserver(tag)."""

    _events: Tuple[str, ...] = ("ModifiedEvent",)

    def __init__(self) -> None:
        self._observers: Dict[int, Tuple[str, Callable[..., None]]] = {}

    def _event_name(self, event: Any) -> str:
        return _VTK_EVENT_NAMES.get(event, str(event)) if isinstance(event, int) else str(event)

    def AddObserver(self, event: Any, callback: Callable[..., None],  # noqa: N802
                    priority: float = 0.0) -> int:
        name = self._event_name(event)
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
        name = self._event_name(event)
        return any(n == name for n, _ in self._observers.values())

    def InvokeEvent(self, event: str) -> None:  # noqa: N802
        for name, callback in list(self._observers.values()):
            if name == event:
                callback(self, event)


class _Node(_Observable):
    recipe: Recipe = ()  # how it was made (its factory sets it)

    def __init__(self, ros_node: ROS2Node, resource: Any) -> None:
        super().__init__()
        self._ros_node = ros_node
        self.resource = resource

    @property
    def _values(self) -> SlicerValues:
        return self._ros_node.logic.values

    def _matrix_out(self, matrix: Optional[np.ndarray], target: Any) -> Any:
        """A matrix as the reference gives it: filled into `target` if one is passed,
        else a new vtkMatrix4x4 (or its plain stand-in)."""
        if matrix is None:
            return None
        out = target if target is not None and is_vtk_matrix(target) else self._values.matrix()
        return fill_vtk(matrix, out)

    def IsAddedToROS2Node(self) -> bool:  # noqa: N802
        return not getattr(self.resource, "removed", False)

    def GetName(self) -> str:  # noqa: N802
        raise NotImplementedError  # each kind names its nodes as the reference does


def _matrix_of(value: Any) -> Any:
    """A Slicer transform node's matrix, or the value itself."""
    if hasattr(value, "GetMatrixTransformToParent") and not is_vtk_matrix(value):
        import vtk  # only Slicer transform nodes get here, so vtk is there
        matrix = vtk.vtkMatrix4x4()
        value.GetMatrixTransformToParent(matrix)
        return matrix
    return value


class SubscriberNode(_Node):
    """``vtkMRMLROS2Subscriber<Name>Node``: the last message, its YAML, the count."""

    resource: Subscriber

    def __init__(self, ros_node: ROS2Node, resource: Subscriber, slicer_type: SlicerType
                 ) -> None:
        super().__init__(ros_node, resource)
        self._slicer_type = slicer_type
        self._parsed: Tuple[Optional[Message], Any] = (None, None)
        if resource.message_device:
            resource.add_whole_callback(lambda message: self.InvokeEvent("ModifiedEvent"))
        else:
            resource.add_callback(lambda value: self.InvokeEvent("ModifiedEvent"))

    def GetName(self) -> str:  # noqa: N802
        return f"ros2:sub:{self.resource.topic}"

    def GetTopic(self) -> str:  # noqa: N802
        return self.resource.topic

    def GetROSType(self) -> str:  # noqa: N802
        return self.resource.ros_type

    def GetSlicerType(self) -> str:  # noqa: N802
        return _type_name(self._slicer_type.blank())

    def GetNumberOfMessages(self) -> int:  # noqa: N802
        """Messages the daemon's subscription received (exact even when this client's
        stream was coalesced); a local read."""
        if self.resource.message_device:
            return self.resource.received_by_daemon
        return self.resource.count

    def _whole(self) -> Optional[Dict[str, Any]]:
        message = self.resource.last_whole
        if message is None:
            return None
        cached, data = self._parsed
        if cached is not message:
            data = json.loads(getattr(message.body, "text", "{}"))
            self._parsed = (message, data)
        return data  # type: ignore[no-any-return]

    def GetLastMessage(self, target: Any = None) -> Any:  # noqa: N802
        """The last message as the reference's Slicer value (a new object each call; or
        copied into `target`, a vtkMatrix4x4 or an object of the same class); None before
        the first."""
        if self.resource.message_device:
            data = self._whole()
            value = None if data is None else self._slicer_type.from_ros(data)
        else:
            native = self.resource.last_message
            value = None if native is None else self._slicer_type.from_native(native)
        if value is not None and target is not None:
            return _copy_into(value, target)
        return value

    def GetLastMessageVariant(self) -> Any:  # noqa: N802
        """The last message in a vtkVariant, where vtk imports (else the value itself)."""
        value = self.GetLastMessage()
        vtk = self._values.vtk
        return vtk.vtkVariant(value) if vtk is not None and value is not None else value

    def GetLastMessageYAML(self) -> str:  # noqa: N802
        """The last message as YAML (``ros2 topic echo`` style); "" before the first."""
        data = self._whole()
        if data is not None:
            return to_yaml(self._ros_node.logic.types.for_yaml(self.GetROSType(), data))
        if self.resource.message_device:
            return ""  # none yet
        value = self.resource.last_value
        return "" if value is None else to_yaml(_native_for_yaml(self.resource.last_message))

    def GetBlankMessage(self) -> Any:  # noqa: N802
        return self._slicer_type.blank()


class PublisherNode(_Node):
    """``vtkMRMLROS2Publisher<Name>Node``: ``Publish(value)`` returns the subscriber count."""

    resource: Publisher

    def __init__(self, ros_node: ROS2Node, resource: Publisher, slicer_type: SlicerType
                 ) -> None:
        super().__init__(ros_node, resource)
        self._slicer_type = slicer_type
        self.calls = 0

    def GetName(self) -> str:  # noqa: N802
        return f"ros2:pub:{self.resource.topic}"

    def GetTopic(self) -> str:  # noqa: N802
        return self.resource.topic

    def GetROSType(self) -> str:  # noqa: N802
        return str(self.resource.info.get("type") or c.resolve_message_type(self.resource.type))

    def GetSlicerType(self) -> str:  # noqa: N802
        return _type_name(self._slicer_type.blank())

    def GetNumberOfCalls(self) -> int:  # noqa: N802
        return self.calls

    def GetNumberOfMessagesSent(self) -> int:  # noqa: N802
        return self.resource.sent

    GetNumberOfMessages = GetNumberOfMessagesSent

    def GetBlankMessage(self) -> Any:  # noqa: N802
        """A new value to fill and publish, of the kind this publisher takes."""
        return self._slicer_type.blank()

    def Publish(self, value: Any) -> int:  # noqa: N802
        """Publish; returns the number of ROS subscribers (as the reference). Raises
        `MessageValueError` naming what is wrong with `value`."""
        self.calls += 1
        kind, payload = self._slicer_type.to_publish(_matrix_of(value))
        if kind == "message":
            return self.resource.publish_message(payload)
        return self.resource.publish(payload)

    def SendModel(self, model: Any) -> None:  # noqa: N802
        """Stream a model (PolyData in mm, or (points, polygons)) to a Mesh or Marker
        publisher (not in the reference)."""
        self.resource.send_model(model)

    def SendMarkups(self, points: Any, labels: Optional[List[str]] = None) -> None:  # noqa: N802
        """Stream markups points ((N, 3) mm, labels) to a PoseArray, PointStamped or Path
        publisher (not in the reference)."""
        self.resource.send_points(points, labels)


class ParameterNode(_Node):
    """``vtkMRMLROS2ParameterNode``: some parameters of one ROS node. As the reference's, it
    keeps every parameter the node declares or changes once it is watched, not only the
    ones added with `AddParameter` (those are fetched at once)."""

    resource: ParameterClient
    _events = ("ParameterModifiedEvent", "ModifiedEvent")

    def __init__(self, ros_node: ROS2Node, resource: ParameterClient) -> None:
        super().__init__(ros_node, resource)
        self._tracked: List[str] = list(resource.observed)
        resource.add_callback(self._changed)
        if not resource.all_changes:
            resource.observe(self._tracked, all_changes=True)

    def _changed(self, name: str, value: Any) -> None:
        self.InvokeEvent("ParameterModifiedEvent")
        self.InvokeEvent("ModifiedEvent")

    def GetName(self) -> str:  # noqa: N802
        return f"ros2:param:{self.resource.node}"

    def GetMonitoredNodeName(self) -> str:  # noqa: N802
        return self.resource.node

    def IsMonitoredNodeReady(self) -> bool:  # noqa: N802
        return bool(self.resource.ready)

    def Spin(self) -> bool:  # noqa: N802
        """The reference spins each parameter node; the daemon watches the node itself.
        True once the node's parameter services answered."""
        return bool(self.resource.ready)

    def AddParameter(self, name: str) -> bool:  # noqa: N802
        """Track one parameter: its value is fetched now if the node is there, else when
        it appears (`IsParameterSet` is False until then). False if already tracked."""
        if name in self._tracked:
            log.warning("AddParameter: parameter %s of %s is already tracked", name,
                        self.resource.node)
            return False
        self._tracked.append(name)
        self.resource.observe(self._tracked, all_changes=True)
        return True

    def RemoveParameter(self, name: str) -> bool:  # noqa: N802
        if name not in self._tracked and name not in self.resource.values:
            log.warning("RemoveParameter: parameter %s of %s is not monitored", name,
                        self.resource.node)
            return False
        if name in self._tracked:
            self._tracked.remove(name)
            self.resource.observe(self._tracked, all_changes=True)
        self.resource.values.pop(name, None)
        return True

    def GetParameterNames(self) -> List[str]:  # noqa: N802
        return list(self._tracked)

    GetTrackedParametersList = GetParameterNames
    GetMonitoredParameterNamesCache = GetParameterNames

    def ListTrackedParameters(self) -> str:  # noqa: N802
        return "\n".join(self._tracked)

    def _value(self, name: str) -> Optional[c.ParameterValue]:
        value = self.resource.values.get(name)
        return None if value is None or value.type == "not_set" else value

    def IsParameterSet(self, name: str, noWarning: bool = False) -> bool:  # noqa: N802,N803
        """Is the parameter known with a value (added and fetched, or changed since the
        node is watched)? `noWarning`: as the reference's, skip the warning when not."""
        if self._value(name) is not None:
            return True
        if not noWarning and name not in self._tracked:
            log.warning("IsParameterSet: parameter %s of %s is not monitored", name,
                        self.resource.node)
        return False

    def GetParameterType(self, name: str, result: Any = None) -> Any:  # noqa: N802
        """"bool", "integer", "double", "string", "bool_array", "integer_array",
        "double_array", "string_array", "byte_array"; "" when it is not set. With
        `result` (a ``vtk.reference``), as the reference's other overload: it gets the type
        and the call returns whether the parameter is set."""
        value = self._value(name)
        text = "" if value is None else value.type
        return text if result is None else _out(result, text, value is not None)

    def _as(self, name: str, *types: str) -> Any:
        value = self._value(name)
        if value is None:
            raise KeyError(f"parameter {name!r} of {self.resource.node} is not set (not "
                           f"added with AddParameter, or not fetched yet: see "
                           f"IsParameterSet)")
        if value.type not in types:
            raise TypeError(f"parameter {name!r} of {self.resource.node} is "
                            f"{value.type}, not {' or '.join(types)}")
        return parameter_to_python(value)

    def GetParameterAsBool(self, name: str, result: Any = None) -> Any:  # noqa: N802
        if result is not None:  # the reference's out-argument overload
            return self._into(result, lambda: bool(self._as(name, "bool")), bool())
        return bool(self._as(name, "bool"))

    def GetParameterAsInteger(self, name: str, result: Any = None) -> Any:  # noqa: N802
        if result is not None:  # the reference's out-argument overload
            return self._into(result, lambda: int(self._as(name, "integer")), int())
        return int(self._as(name, "integer"))

    def GetParameterAsDouble(self, name: str, result: Any = None) -> Any:  # noqa: N802
        if result is not None:  # the reference's out-argument overload
            return self._into(result, lambda: float(self._as(name, "double", "integer")), float())
        return float(self._as(name, "double", "integer"))

    def GetParameterAsString(self, name: str, result: Any = None) -> Any:  # noqa: N802
        if result is not None:  # the reference's out-argument overload
            return self._into(result, lambda: str(self._as(name, "string")), str())
        return str(self._as(name, "string"))

    def _into(self, result: Any, read: Callable[[], Any], empty: Any) -> bool:
        try:
            return bool(_out(result, read(), True))
        except (KeyError, TypeError) as error:
            log.warning("%s", error)
            return bool(_out(result, empty, False))

    def GetParameterAsVectorOfBools(self, name: str) -> List[bool]:  # noqa: N802
        return [bool(v) for v in self._as(name, "bool_array")]

    def GetParameterAsVectorOfIntegers(self, name: str) -> List[int]:  # noqa: N802
        return [int(v) for v in self._as(name, "integer_array", "byte_array")]

    def GetParameterAsVectorOfDoubles(self, name: str) -> List[float]:  # noqa: N802
        return [float(v) for v in self._as(name, "double_array", "integer_array")]

    def GetParameterAsVectorOfStrings(self, name: str) -> List[str]:  # noqa: N802
        return [str(v) for v in self._as(name, "string_array")]

    def PrintParameter(self, name: str) -> str:  # noqa: N802
        """The value as text, as the reference's PrintParameter ("parameter not found"
        when it is not set)."""
        value = self._value(name)
        if value is None:
            return "parameter not found"
        raw = parameter_to_python(value)
        if value.type == "bool":
            return "true" if raw else "false"
        if value.type.endswith("_array"):
            return "[" + ", ".join(str(v).lower() if isinstance(v, bool) else str(v)
                                   for v in raw) + "]"
        return str(raw)

    PrintParameterValue = PrintParameter

    def SetParameter(self, name: str, value: Any, type: Optional[str] = None) -> bool:  # noqa: N802
        """Not in the reference (its parameter node is read-only); offered for symmetry."""
        self.resource.set(name, value, type=type)
        return True


class _ParentChild(_Node):
    """A tf2 node: named by its parent and child frames, fixed when it is made."""

    _kind = ""

    def GetName(self) -> str:  # noqa: N802
        return f"ros2:{self._kind}:{self.resource.parent}To{self.resource.child}"

    def GetParentID(self) -> str:  # noqa: N802
        return str(self.resource.parent)

    def GetChildID(self) -> str:  # noqa: N802
        return str(self.resource.child)

    def IsParentAndChildSet(self) -> bool:  # noqa: N802
        return bool(self.resource.parent and self.resource.child)

    def SetParentID(self, parent_id: str) -> bool:  # noqa: N802
        """Use another parent frame, as the reference's next spin does: the daemon-side
        bridge of the new pair replaces this node's (False, logged, for an empty id or a
        pair another node of this ROS node already has)."""
        return bool(self._ros_node._retarget(self, parent_id, self.GetChildID()))

    def SetChildID(self, child_id: str) -> bool:  # noqa: N802
        """Use another child frame (see `SetParentID`)."""
        return bool(self._ros_node._retarget(self, self.GetParentID(), child_id))

    def _attach(self, resource: Any) -> None:
        """Take `resource` (the bridge of the pair now named) as this node's."""
        self.resource = resource


class Tf2BroadcasterNode(_ParentChild):
    resource: TfBroadcaster
    _kind = "tf2broadcaster"

    def GetNumberOfBroadcasts(self) -> int:  # noqa: N802
        return self.resource.count

    def Broadcast(self, matrix: Any) -> bool:  # noqa: N802
        """A 4x4 in mm (numpy, lists, vtkMatrix4x4) or a Slicer transform node."""
        self.resource.broadcast(_matrix_of(matrix))
        return True

    def ObserveTransformNode(self, transform_node: Any) -> int:  # noqa: N802
        """Broadcast whenever a Slicer transform node changes (inside 3D Slicer)."""
        event = getattr(transform_node, "TransformModifiedEvent", 15000)
        return int(transform_node.AddObserver(
            event, lambda caller, _event: self.Broadcast(caller)))


class Tf2LookupNode(_ParentChild):
    """``vtkMRMLROS2Tf2LookupNode``: parent -> child as tf2 has it. As the reference's, it
    is modified (TransformModifiedEvent, ModifiedEvent) on every spin once the transform is
    known (``SetModifiedOnLookup(False)``: only when it changes), and whenever it changes
    while nobody spins."""

    resource: TfLookup
    _events = ("ModifiedEvent", "TransformModifiedEvent")
    _kind = "tf2lookup"

    def __init__(self, ros_node: ROS2Node, resource: TfLookup) -> None:
        super().__init__(ros_node, resource)
        self._modified_on_lookup = True
        self._changed_since_spin = False
        self._attach(resource)
        ros_node.logic.add_tick(self._tick)

    def _attach(self, resource: Any) -> None:
        super()._attach(resource)
        self._changed_since_spin = False
        resource.add_callback(self._changed)

    def _changed(self, matrix: np.ndarray) -> None:
        if self._ros_node.logic.spinning_here():
            self._changed_since_spin = True  # this spin's tick tells the observers
        else:
            self._modify()

    def _tick(self) -> None:
        if self.resource.matrix is None or self.resource.removed:
            return
        if self._modified_on_lookup or self._changed_since_spin:
            self._changed_since_spin = False
            self._modify()

    def _modify(self) -> None:
        self.InvokeEvent("TransformModifiedEvent")
        self.InvokeEvent("ModifiedEvent")

    def forget(self) -> None:
        self._ros_node.logic.remove_tick(self._tick)

    def SetModifiedOnLookup(self, value: bool) -> None:  # noqa: N802
        self._modified_on_lookup = bool(value)

    def GetModifiedOnLookup(self) -> bool:  # noqa: N802
        return self._modified_on_lookup

    def GetMatrixTransformToParent(self, target: Any = None) -> Any:  # noqa: N802
        """The latest parent -> child (4x4, mm), filled into `target` if given; the
        identity until tf connects them, as the reference's lookup node (a transform node)
        gives."""
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
    """``vtkMRMLROS2ServiceClient<Name>Node``: requests and responses are message objects
    of the service's types (``CreateBlankRequest()``, ``GetLastResponse()``); any installed
    service type works, by the reference's class name or ``pkg/srv/Type``."""

    resource: Service

    def __init__(self, ros_node: ROS2Node, resource: Service,
                 description: c.TypeDescription, adapter: Optional[_Adapter] = None) -> None:
        super().__init__(ros_node, resource)
        self._description = description
        self._adapter = adapter
        self._last: Any = None
        self._last_ok = False
        self.calls = 0
        self.sent = 0
        self._lock = threading.Lock()
        # The latest async request while it is in flight: (its end, when it times out).
        self._in_flight: Optional[Tuple[threading.Event, float]] = None

    @property
    def _types(self) -> MessageTypes:
        return self._ros_node.logic.types

    def GetName(self) -> str:  # noqa: N802
        return f"ros2:srv:client:{self.resource.service}"

    def GetService(self) -> str:  # noqa: N802
        return self.resource.service

    GetTopic = GetService

    def GetROSType(self) -> str:  # noqa: N802
        return self._description.type

    def GetNumberOfCalls(self) -> int:  # noqa: N802
        return self.calls

    def GetNumberOfRequestsSent(self) -> int:  # noqa: N802
        return self.sent

    def GetSlicerTypeIn(self) -> str:  # noqa: N802
        return _type_name(self.CreateBlankRequest())

    def GetSlicerTypeOut(self) -> str:  # noqa: N802
        return str(self._types.message_class(self._description.parts["response"]).__name__)

    def PreRequestCheck(self) -> bool:  # noqa: N802
        """Is the service in the ROS graph with this type (what the reference checks
        before sending)?"""
        listed = self._ros_node.client.list_services()
        found = [s for s in listed if s.get("service") == self.resource.service]
        ok = bool(found) and self._description.type in found[0].get("types", [])
        if not ok:
            log.warning("PreRequestCheck: service %s (%s) is not in the ROS graph",
                        self.resource.service, self._description.type)
        return ok

    def CreateBlankRequest(self) -> Any:  # noqa: N802
        request = self._types.new(self._description.parts["request"])
        return request if self._adapter is None else self._adapter.request(request)

    def _request_json(self, request: Any) -> Dict[str, Any]:
        if request is None:
            return {}
        if self._adapter is not None and isinstance(request, _Wrapped):
            request = request.message
        if isinstance(request, MessageObject):
            if request.GetROSType() != self._description.parts["request"]:
                raise MessageValueError(f"expected a {self._description.parts['request']} "
                                        f"request, got a {request.GetROSType()}")
            return request.to_ros()
        if isinstance(request, Mapping):
            return dict(request)
        raise MessageValueError(f"expected a request from CreateBlankRequest(), got "
                                f"{type(request).__name__}")

    def _received(self, response: Dict[str, Any]) -> Any:
        message = self._types.from_ros(self._description.parts["response"], response)
        obj = message if self._adapter is None else self._adapter.response(message)
        with self._lock:
            self._last, self._last_ok = obj, True
        return obj

    def SendBlockingRequest(self, request: Any = None, timeout: float = 4.0) -> Any:  # noqa: N802
        """Call and wait (a service call from 3D Slicer's main thread blocks the GUI for
        as long: prefer SendAsyncRequest); returns the response object."""
        self.calls += 1
        body = self._request_json(request)
        self.sent += 1
        obj = self._received(self.resource.call(body, timeout))
        self.InvokeEvent("ModifiedEvent")
        return obj

    def SendAsyncRequest(self, request: Any = None, timeout: float = 4.0) -> int:  # noqa: N802
        """Send and return at once; observers get ModifiedEvent when the response comes.
        `GetLastResponse()` and `GetLastResponseStatus()` called while this request is in
        flight wait for its end: at most `timeout` seconds after this call (the request's
        own deadline), plus REPLY_GRACE_S for a failure to be noted, so a script that reads
        after spinning gets this request's response, however loaded the machine. Returns
        the number of requests sent (1)."""
        self.calls += 1
        body = self._request_json(request)
        ended = threading.Event()
        with self._lock:
            self._in_flight = (ended, time.monotonic() + float(timeout) + REPLY_GRACE_S)

        def run() -> None:
            try:
                self._received(self.resource.call(body, timeout))
            except Exception as error:  # noqa: BLE001 - the status says it; logged too
                with self._lock:
                    self._last_ok = False
                log.warning("service %s: %s", self.resource.service, error)
                return
            finally:
                ended.set()  # after the response is stored (or the failure noted)
            self._ros_node.logic.client.emit(self.InvokeEvent, "ModifiedEvent")

        threading.Thread(target=run, name=f"service {self.resource.service}",
                         daemon=True).start()
        self.sent += 1
        return 1

    def _await_in_flight(self) -> None:
        """Wait for the latest async request's end, bounded by its timeout."""
        with self._lock:
            in_flight = self._in_flight
        if in_flight is not None:
            ended, deadline = in_flight
            # The request's worker may need this thread to send it (3D Slicer's connector
            # is the main thread's): let the transport serve it between short waits.
            client = self._ros_node.logic.client
            while not ended.wait(0.005) and time.monotonic() < deadline:
                client.serve_other_threads()

    def GetLastResponse(self) -> Any:  # noqa: N802
        """The latest response; waits for a request in flight (see SendAsyncRequest)."""
        self._await_in_flight()
        with self._lock:
            return self._last

    def GetLastResponseStatus(self) -> bool:  # noqa: N802
        self._await_in_flight()
        with self._lock:
            return self._last_ok


class _Wrapped:
    """A message object seen through other accessor names (the reference's hand-written
    SetBoolString service: a vtkBool request, a vtkBoolString response)."""

    def __init__(self, message: MessageObject, names: Mapping[str, str]) -> None:
        self.message = message
        for ours, theirs in names.items():
            setattr(self, f"Get{ours}", getattr(message, f"Get{theirs}"))
            setattr(self, f"Set{ours}", getattr(message, f"Set{theirs}"))


class _Adapter:
    def __init__(self, request_names: Mapping[str, str],
                 response_names: Mapping[str, str]) -> None:
        self._request_names = request_names
        self._response_names = response_names

    def request(self, message: MessageObject) -> _Wrapped:
        return _Wrapped(message, self._request_names)

    def response(self, message: MessageObject) -> _Wrapped:
        return _Wrapped(message, self._response_names)


# The reference's hand-written service client classes (vtkCustomTypes.h).
_ADAPTERS = {"SetBoolString": _Adapter({"Value": "Data"},
                                       {"Result": "Success", "Message": "Message"})}


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
        client = self._ros_node.logic.client
        # Observers hear of the end as of each feedback (a thread waits for it).
        _wait_then(self._goal, lambda: client.emit(self.InvokeEvent, "ModifiedEvent")).start()
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


def _wait_then(goal: GoalHandle, then: Callable[[], None]) -> threading.Thread:
    def run() -> None:
        try:
            goal.result(None)
        except Exception:  # noqa: BLE001 - an end without a result is an end too
            pass
        then()
    return threading.Thread(target=run, name=f"goal {goal.goal_id}", daemon=True)


class ROS2Node:
    """The reference's ``vtkMRMLROS2NodeNode``. Every facade node lives on the daemon's one
    ROS node; a node made with ``Create(name)`` is a named group of bridges that
    ``Destroy()`` removes (bridges another node of this client also made stay)."""

    recipe: Recipe = ()  # how it was made (its factory sets it)

    def __init__(self, logic: Logic, name: str = "") -> None:
        self.logic = logic
        self.client = logic.client
        self._name = name
        self._destroyed = False
        self._nodes: Dict[Tuple[str, ...], _Node] = {}
        self._services: Dict[str, ServiceClientNode] = {}
        self._actions: Dict[str, ActionClientNode] = {}

    # --- the node itself ------------------------------------------------------------------
    def Create(self, nodeName: str) -> None:  # noqa: N802,N803
        """Name this node (the reference creates a ROS node of that name: here bridges stay
        on the daemon's node, which `GetROS2NodeName` of the default node names)."""
        self._name = nodeName
        self._destroyed = False
        if self.recipe[:1] == ("CreateROS2Node",):
            self.recipe = ("CreateROS2Node", nodeName)
        self.logic.nodes.changed(self)

    def Destroy(self) -> None:  # noqa: N802
        """Remove every bridge this node made (one another node also holds stays)."""
        for key, node in list(self._nodes.items()):
            self._forget(key, node)
        for client in [*self._services.values(), *self._actions.values()]:
            self._let_go(client)
        self._services.clear()
        self._actions.clear()
        self._destroyed = True

    def GetROS2NodeName(self) -> str:  # noqa: N802
        if self._name:
            return self._name
        return str(self.client.daemon_info.get("node", "/slicer_bridge"))

    def GetName(self) -> str:  # noqa: N802
        return f"ros2:node:{self.GetROS2NodeName().lstrip('/')}"

    def Spin(self) -> None:  # noqa: N802
        self.logic.Spin()

    def GetSpinning(self) -> bool:  # noqa: N802
        return self.client.connected and not self._destroyed

    def WarnIfNotSpinning(self, contextMessage: str) -> None:  # noqa: N802,N803
        if not self.GetSpinning():
            log.warning("Node %s is not spinning (not connected to the daemon) when %s",
                        self.GetROS2NodeName(), contextMessage)

    def RegisteredROS2SubscriberNodes(self) -> str:  # noqa: N802
        return " ".join(f"vtkMRMLROS2Subscriber{n}Node" for n in c.REFERENCE_TYPE_NAMES)

    def RegisteredROS2PublisherNodes(self) -> str:  # noqa: N802
        return " ".join(f"vtkMRMLROS2Publisher{n}Node" for n in c.REFERENCE_TYPE_NAMES)

    def RegisteredROS2ServiceClientNodes(self) -> str:  # noqa: N802
        return " ".join(f"vtkMRMLROS2ServiceClient{n}Node" for n in c.REFERENCE_SERVICE_NAMES)

    # --- bookkeeping ----------------------------------------------------------------------
    def _keep(self, resource: Resource, make: Callable[[], _Node]) -> Any:
        key = resource.spec.key
        node = self._nodes.get(key)
        if node is None or node.resource is not resource:
            node = make()
            self._nodes[key] = node
            self.logic.hold(key, self)
        return node

    def _get(self, *key: str) -> Any:
        return self._nodes.get(key)

    def _new(self, cls: Type[_N], recipe: Recipe, *args: Any) -> _N:
        """A node of `cls` made by this ROS node, through the logic's node factory."""
        node: _N = self.logic.nodes.make(cls, recipe, self, self, *args)
        return node

    def _let_go(self, node: _Node) -> None:
        self.logic.nodes.discard(node)
        node.RemoveAllObservers()

    def _forget(self, key: Tuple[str, ...], node: _Node) -> bool:
        self._nodes.pop(key, None)
        self._let_go(node)
        if isinstance(node, Tf2LookupNode):
            node.forget()
        if self.logic.release(key, self):
            return self.client.remove_bridge(*key)
        return True

    def _retarget(self, node: _ParentChild, parent: str, child: str) -> bool:
        """`node` names parent -> child from now on: the new pair's bridge is made first,
        then the old one let go (removed if no other node holds it)."""
        if not (isinstance(parent, str) and parent and isinstance(child, str) and child):
            log.error("%s: the parent and child frame ids must be non-empty strings, got "
                      "%r and %r", node.GetName(), parent, child)
            return False
        old_key = node.resource.spec.key
        lookup = isinstance(node, Tf2LookupNode)
        new_key = (c.CreateTfLookup.op if lookup else c.CreateTfBroadcaster.op, parent, child)
        if new_key == old_key:
            return True
        if new_key in self._nodes:
            log.error("%s: %s -> %s is already %s of this ROS node; use that one",
                      node.GetName(), parent, child, self._nodes[new_key].GetName())
            return False
        resource = (self.client.tf_lookup(parent, child) if lookup
                    else self.client.tf_broadcaster(parent, child))
        node._attach(resource)
        node.recipe = (node.recipe[0], parent, child)
        self.logic.nodes.changed(node)
        self._nodes.pop(old_key, None)
        self._nodes[new_key] = node
        self.logic.hold(new_key, self)
        if self.logic.release(old_key, self):
            self.client.remove_bridge(*old_key)
        return True

    def _drop(self, *key: str) -> bool:
        """Remove a bridge: one this node made, or one the daemon keeps from another
        client if its rules allow; False if there is none. A refusal (an operator's
        bridge, a --read-only daemon) raises."""
        node = self._nodes.get(key)
        if node is not None:
            return self._forget(key, node)
        return self.client.remove_bridge(*key)

    def _slicer_type(self, class_name: str, ros_type: str, native_type: str = "") -> SlicerType:
        return slicer_type_for(class_name, ros_type, self.logic.types, self.logic.values,
                               native_type=native_type)

    # --- topics -----------------------------------------------------------------------------
    def CreateAndAddSubscriberNode(self, className: str, topic: str) -> SubscriberNode:  # noqa: N802,N803
        c.check_message_type(className, "className")  # an early, named error
        # Its reads are of the whole message: the native values would come for nothing.
        sub = self.client.subscribe(topic, className, messages=True, native=False)

        def make() -> SubscriberNode:
            slicer_type = self._slicer_type(className, sub.ros_type,
                                            str(sub.info.get("igtl_type", "")))
            return self._new(SubscriberNode, ("CreateAndAddSubscriberNode", className, topic),
                             sub, slicer_type)
        return self._keep(sub, make)  # type: ignore[no-any-return]

    def CreateAndAddPublisherNode(self, className: str, topic: str,  # noqa: N802,N803
                                  frame: str = "",
                                  labelsTopic: str = "") -> PublisherNode:  # noqa: N803
        """``frame`` / ``labelsTopic``: this bridge's additions for models and markups
        sent to ROS (not in the reference)."""
        c.check_message_type(className, "className")
        pub = self.client.publisher(topic, className, frame=frame or None,
                                    labels_topic=labelsTopic or None)

        def make() -> PublisherNode:
            ros_type = str(pub.info.get("type") or c.resolve_message_type(className))
            # As the subscriber of the same name: Publish takes what GetLastMessage gives.
            return self._new(PublisherNode, ("CreateAndAddPublisherNode", className, topic,
                                             frame, labelsTopic),
                             pub, self._slicer_type(className, ros_type,
                                                    str(pub.info.get("igtl_type", ""))))
        return self._keep(pub, make)  # type: ignore[no-any-return]

    def GetSubscriberNodeByTopic(self, topic: str) -> Optional[SubscriberNode]:  # noqa: N802
        return self._get(c.CreateSubscriber.op, topic)  # type: ignore[no-any-return]

    def GetPublisherNodeByTopic(self, topic: str) -> Optional[PublisherNode]:  # noqa: N802
        return self._get(c.CreatePublisher.op, topic)  # type: ignore[no-any-return]

    def RemoveAndDeleteSubscriberNode(self, topic: str) -> bool:  # noqa: N802
        return self._drop(c.CreateSubscriber.op, topic)

    def RemoveAndDeletePublisherNode(self, topic: str) -> bool:  # noqa: N802
        return self._drop(c.CreatePublisher.op, topic)

    # --- parameters ---------------------------------------------------------------------------
    def CreateAndAddParameterNode(self, nodeName: str) -> ParameterNode:  # noqa: N802,N803
        params = self.client.parameters(nodeName)
        return self._keep(params, lambda: self._new(  # type: ignore[no-any-return]
            ParameterNode, ("CreateAndAddParameterNode", nodeName), params))

    def GetParameterNodeByNode(self, nodeName: str) -> Optional[ParameterNode]:  # noqa: N802,N803
        return self._get(c.CreateParameterClient.op, nodeName)  # type: ignore[no-any-return]

    def RemoveAndDeleteParameterNode(self, nodeName: str) -> bool:  # noqa: N802,N803
        return self._drop(c.CreateParameterClient.op, nodeName)

    # --- tf2 ----------------------------------------------------------------------------------
    def CreateAndAddTf2BroadcasterNode(self, parent_id: str, child_id: str  # noqa: N802
                                       ) -> Tf2BroadcasterNode:
        broadcaster = self.client.tf_broadcaster(parent_id, child_id)
        return self._keep(broadcaster, lambda: self._new(  # type: ignore[no-any-return]
            Tf2BroadcasterNode, ("CreateAndAddTf2BroadcasterNode", parent_id, child_id),
            broadcaster))

    def CreateAndAddTf2LookupNode(self, parent_id: str, child_id: str  # noqa: N802
                                  ) -> Tf2LookupNode:
        lookup = self.client.tf_lookup(parent_id, child_id)
        return self._keep(lookup, lambda: self._new(  # type: ignore[no-any-return]
            Tf2LookupNode, ("CreateAndAddTf2LookupNode", parent_id, child_id), lookup))

    def GetTf2BroadcasterNodeByParentChild(self, parent_id: str, child_id: str  # noqa: N802
                                           ) -> Optional[Tf2BroadcasterNode]:
        return self._get(c.CreateTfBroadcaster.op, parent_id, child_id)  # type: ignore[no-any-return]

    def GetTf2LookupNodeByParentChild(self, parent_id: str, child_id: str  # noqa: N802
                                      ) -> Optional[Tf2LookupNode]:
        return self._get(c.CreateTfLookup.op, parent_id, child_id)  # type: ignore[no-any-return]

    def RemoveAndDeleteTf2BroadcasterNode(self, parent_id: str, child_id: str) -> bool:  # noqa: N802
        return self._drop(c.CreateTfBroadcaster.op, parent_id, child_id)

    def RemoveAndDeleteTf2LookupNode(self, parent_id: str, child_id: str) -> bool:  # noqa: N802
        return self._drop(c.CreateTfLookup.op, parent_id, child_id)

    # --- robots -------------------------------------------------------------------------------
    def CreateAndAddRobotNode(self, robotName: str,  # noqa: N802,N803
                              parameterNodeName: str = "/robot_state_publisher",  # noqa: N803
                              parameterName: str = "robot_description",  # noqa: N803
                              fixedFrame: str = "", tfPrefix: str = "") -> RobotNode:  # noqa: N803
        robot = self.client.robot(robotName, node=parameterNodeName, parameter=parameterName,
                                  fixed_frame=fixedFrame or None, tf_prefix=tfPrefix)
        return self._keep(robot, lambda: self._new(  # type: ignore[no-any-return]
            RobotNode, ("CreateAndAddRobotNode", robotName, parameterNodeName, parameterName,
                        fixedFrame, tfPrefix), robot))

    def GetRobotNodeByName(self, robotName: str) -> Optional[RobotNode]:  # noqa: N802,N803
        return self._get(c.CreateRobot.op, robotName)  # type: ignore[no-any-return]

    def RemoveAndDeleteRobotNode(self, robotName: str) -> bool:  # noqa: N802,N803
        return self._drop(c.CreateRobot.op, robotName)

    # --- markers (not in the reference) -------------------------------------------------------
    def CreateAndAddMarkerSubscriberNode(self, className: str, topic: str,  # noqa: N802,N803
                                         fixedFrame: str) -> MarkerSubscriberNode:  # noqa: N803
        """`className`: Marker, MarkerArray, Path, PolygonStamped or PointStamped."""
        markers = self.client.markers(topic, className, fixedFrame)
        return self._keep(markers, lambda: self._new(  # type: ignore[no-any-return]
            MarkerSubscriberNode, ("CreateAndAddMarkerSubscriberNode", className, topic,
                                   fixedFrame), markers))

    def GetMarkerSubscriberNodeByTopic(self, topic: str  # noqa: N802
                                       ) -> Optional[MarkerSubscriberNode]:
        return self._get(c.CreateMarkerSubscriber.op, topic)  # type: ignore[no-any-return]

    def RemoveAndDeleteMarkerSubscriberNode(self, topic: str) -> bool:  # noqa: N802
        return self._drop(c.CreateMarkerSubscriber.op, topic)

    # --- services -----------------------------------------------------------------------------
    def CreateAndAddServiceClientNode(self, className: str, service: str  # noqa: N802,N803
                                      ) -> ServiceClientNode:
        """`className`: the reference's ``vtkMRMLROS2ServiceClient<Name>Node`` (``Spawn``,
        ``GetPositionIK``, ``SetBoolString``...), or any ``pkg/srv/Type`` installed in the
        daemon's environment."""
        node = self._services.get(service)
        if node is None:
            description = self.logic.types.description(className, "service")
            stem = className.strip()
            if stem.startswith("vtkMRMLROS2ServiceClient") and stem.endswith("Node"):
                stem = stem[len("vtkMRMLROS2ServiceClient"):-len("Node")]
            node = self._new(ServiceClientNode,
                             ("CreateAndAddServiceClientNode", className, service),
                             self.client.service(service, description.type), description,
                             _ADAPTERS.get(stem))
            self._services[service] = node
        return node

    def GetServiceClientNodeByService(self, service: str  # noqa: N802
                                      ) -> Optional[ServiceClientNode]:
        return self._services.get(service)

    GetServiceClientNodeByTopic = GetServiceClientNodeByService

    def RemoveAndDeleteServiceClientNode(self, service: str) -> bool:  # noqa: N802
        node = self._services.pop(service, None)
        if node is not None:
            self._let_go(node)
        return node is not None

    # --- actions (the reference has none: named like its service client nodes) ---------------
    def CreateAndAddActionClientNode(self, className: str, action: str  # noqa: N802,N803
                                     ) -> ActionClientNode:
        node = self._actions.get(action)
        if node is None:
            node = self._new(ActionClientNode,
                             ("CreateAndAddActionClientNode", className, action),
                             self.client.action(action, className))
            self._actions[action] = node
        return node

    def GetActionClientNodeByName(self, action: str) -> Optional[ActionClientNode]:  # noqa: N802
        return self._actions.get(action)

    def RemoveAndDeleteActionClientNode(self, action: str) -> bool:  # noqa: N802
        node = self._actions.pop(action, None)
        if node is not None:
            self._let_go(node)
        return node is not None


def _out(result: Any, value: Any, ok: bool) -> bool:
    """Fill an out-argument (``vtk.reference``, or a one-item list) as the reference's
    overloads do; returns `ok`."""
    if hasattr(result, "set"):
        result.set(value)
    elif isinstance(result, list):
        result[:] = [value]
    else:
        raise TypeError(f"expected a vtk.reference (or a list) to fill, got "
                        f"{type(result).__name__}")
    return ok


def _type_name(value: Any) -> str:
    if hasattr(value, "GetClassName"):
        return str(value.GetClassName())
    return {str: "std::string", bool: "bool", int: "int", float: "double"}.get(
        type(value), type(value).__name__)


def _copy_into(value: Any, target: Any) -> Any:
    """What a getter with an output argument does: fill `target` with `value`."""
    if is_vtk_matrix(value) and is_vtk_matrix(target):
        return fill_vtk(value, target)
    if hasattr(target, "DeepCopy") and type(target) is type(value):
        target.DeepCopy(value)
        return target
    if isinstance(value, MessageObject) and type(target) is type(value):
        target._fields = value._fields
        return target
    raise TypeError(f"GetLastMessage: cannot fill a {type(target).__name__} with a "
                    f"{type(value).__name__}")


def _native_for_yaml(message: Optional[Message]) -> Dict[str, Any]:
    """What an image or point cloud subscriber can show as YAML from its native stream: the
    header, sizes and encoding (the pixels and points themselves are left out: megabytes of
    numbers are no use as text)."""
    if message is None:
        return {}
    from protocol.conversions import ros_time_from_igtl
    from protocol.naming import KEY_ENCODING, KEY_FRAME
    sec, nanosec = ros_time_from_igtl(message.timestamp) if message.timestamp else (0, 0)
    out: Dict[str, Any] = {"header": {"stamp": {"sec": sec, "nanosec": nanosec},
                                      "frame_id": message.metadata.get(KEY_FRAME, "")}}
    body = message.body
    pixels = getattr(body, "pixels", None)
    if pixels is not None:
        out.update({"height": int(pixels.shape[-3]), "width": int(pixels.shape[-2]),
                    "encoding": message.metadata.get(KEY_ENCODING, "")})
    points = getattr(body, "points", None)
    if points is not None:
        out["points"] = int(np.asarray(points).reshape(-1, 3).shape[0])
    return out


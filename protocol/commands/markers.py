"""Marker ops: RViz's visualization_msgs/Marker and MarkerArray, nav_msgs/Path,
geometry_msgs/PolygonStamped and PointStamped as models placed by tf.

Why an op of its own and not ``create_subscriber`` with a ``fixed_frame`` argument: a plain
subscriber is one topic -> one device whose message is the codec's conversion of each ROS
message. A marker topic is one topic -> many devices (one per ``ns``/``id``) that come and
go, a TRANSFORM per tf frame, a lifetime timer and mesh files: another capability, with its
own bridge kind (``marker_subscriber``, so quotas, ownership, the YAML section and the
client's re-sync derive from this declaration as for every other kind), and adding it kept
"one schema module + one handler table" true. A plain ``create_subscriber`` on the same
topic still works and gives the message as JSON text.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from protocol.commands.errors import OutOfRangeError, WrongTypeError
from protocol.commands.fields import Args
from protocol.commands.op import Bridge, Example, FrameUse, Op, Resource, TopicUse
from protocol.commands.results import Result
from protocol.commands.values import QoS
from protocol.commands.wire import json_type

__all__ = ["MARKER_SOURCE_TYPES", "CreateMarkerSubscriber", "ListMarkers", "ListMarkersResult",
           "MarkerSubscriberBridge", "RemoveMarkerSubscriber", "RemovedMarkerSubscriber",
           "marker_source_type"]


@dataclass(frozen=True)
class MarkerSubscriberBridge(Result):
    """A marker subscriber, as `create_marker_subscriber` and `list_bridges` describe it:
    its device (the live markers' list), counts of messages, markers shown, withheld and
    refused, whether it reads CDR bytes, what its worker dropped or meshed, and the bytes
    of its models."""

    kind: str  # "marker_subscriber"
    topic: str
    type: str
    fixed_frame: str
    device: str
    qos: dict[str, Any]
    messages: int
    markers: int
    withheld: int
    errors: int
    raw: bool
    dropped: int
    meshed: int
    model_bytes: int


@dataclass(frozen=True)
class RemovedMarkerSubscriber(Result):
    """A removed marker subscriber and the devices it had (its markers', then its own)."""

    topic: str
    devices: tuple[str, ...]


@dataclass(frozen=True)
class ListMarkersResult(Result):
    """A marker subscriber's live markers (each: ns, id, device, type, frame, points,
    whether placed in the fixed frame, its frame's device, seconds to expiry or null), and
    those withheld or refused, with why."""

    large = True

    topic: str
    device: str
    markers: tuple[dict[str, Any], ...]
    withheld: tuple[dict[str, Any], ...]
    errors: tuple[dict[str, Any], ...]

# The types a marker subscriber takes: short name -> ROS type.
MARKER_SOURCE_TYPES: dict[str, str] = {
    "Marker": "visualization_msgs/msg/Marker",
    "MarkerArray": "visualization_msgs/msg/MarkerArray",
    "Path": "nav_msgs/msg/Path",
    "PolygonStamped": "geometry_msgs/msg/PolygonStamped",
    "PointStamped": "geometry_msgs/msg/PointStamped",
}


def marker_source_type(text: object, path: str = "type") -> str:
    """``"Marker"``, ``"visualization_msgs/msg/Marker"`` (or ``pkg/Type``) -> the ROS type;
    `OutOfRangeError` naming the five accepted types otherwise."""
    if not isinstance(text, str):
        raise WrongTypeError(path, "a string", json_type(text))
    for short, full in MARKER_SOURCE_TYPES.items():
        package = full.split("/", 1)[0]
        if text in (short, full, f"{package}/{short}"):
            return full
    raise OutOfRangeError(path, "one of " + ", ".join(MARKER_SOURCE_TYPES) +
                          " (or its pkg/msg/Type)", repr(text))


def _fixed_frame(a: Args) -> str:
    frame = a.frame("fixed_frame").lstrip("/")
    if not frame:
        raise OutOfRangeError(a.path("fixed_frame"), "a non-empty tf frame id", "'/'")
    return frame


@dataclass(frozen=True)
class CreateMarkerSubscriber(Op, op="create_marker_subscriber", result=MarkerSubscriberBridge,
                             ros_names=("topic",), writes=False,
                             content=("frames", "files"),
                             creates=Bridge("marker_subscriber", ("topic",),
                                            section="marker_subscribers")):
    """Subscribe to ``topic`` (``type``: Marker, MarkerArray, Path, PolygonStamped or
    PointStamped): every marker becomes a model (POLYDATA, mm, in its frame) or a text
    point (POINT), under a TRANSFORM that follows ``fixed_frame`` <- its ``frame_id``.

    It reads the topic and reveals the fixed frame's relation to each marker's frame (the
    frames are judged by the frame globs marker by marker, when they arrive); MESH_RESOURCE
    markers read mesh files only inside the mesh roots (as a client's robot)."""

    examples = (Example(
        {"topic": "/m", "type": "MarkerArray", "fixed_frame": "/world"},
        {("frame", "fixed_frame", "world"), ("topic", "topic", "/m")}),)

    topic: str
    type: str
    fixed_frame: str
    qos: QoS = QoS()

    @property
    def ros_type(self) -> str:
        return marker_source_type(self.type)

    def resources(self) -> tuple[Resource, ...]:
        return (TopicUse("topic", self.topic, self.ros_type),
                FrameUse("fixed_frame", self.fixed_frame, client_frame=False))

    @classmethod
    def from_args(cls, a: Args) -> CreateMarkerSubscriber:
        type_text = a.req_str("type")
        marker_source_type(type_text, a.path("type"))
        sub = a.opt_obj("qos")
        return cls(topic=a.ros_name("topic"), type=type_text, fixed_frame=_fixed_frame(a),
                   qos=QoS.from_args(sub) if sub is not None else QoS())


@dataclass(frozen=True)
class RemoveMarkerSubscriber(Op, op="remove_marker_subscriber", result=RemovedMarkerSubscriber,
                             ros_names=("topic",), writes=False,
                             removes="marker_subscriber"):
    examples = (Example({"topic": "/m"}),)

    topic: str

    def resources(self) -> tuple[Resource, ...]:
        return ()  # judged by who made the bridge

    @classmethod
    def from_args(cls, a: Args) -> RemoveMarkerSubscriber:
        return cls(topic=a.ros_name("topic"))


@dataclass(frozen=True)
class ListMarkers(Op, op="list_markers", result=ListMarkersResult,
                  ros_names=("topic",), writes=False):
    """The live markers of a marker subscriber: device, ns, id, type, frame, expiry."""

    examples = (Example({"topic": "/m"}, {("topic", "topic", "/m")}),)

    topic: str

    def resources(self) -> tuple[Resource, ...]:
        return (TopicUse("topic", self.topic),)

    @classmethod
    def from_args(cls, a: Args) -> ListMarkers:
        return cls(topic=a.ros_name("topic"))

"""Topic ops: subscriber and publisher bridges, publishing, the last message."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Optional

from protocol.commands.errors import OutOfRangeError, WrongTypeError
from protocol.commands.fields import MISSING, ROS_NAME, ROS_NAME_DESC, Args
from protocol.commands.op import Bridge, Example, FrameUse, Op, Resource, TopicUse
from protocol.commands.results import Answered, GetLastMessageResult, PublishResult, Result
from protocol.commands.types import check_message_type, resolve_message_type
from protocol.commands.values import QoS
from protocol.commands.wire import json_type

__all__ = ["LABELS_TYPE", "CreatePublisher", "CreateSubscriber", "GetLastMessage", "Publish",
           "RemovePublisher", "RemoveSubscriber", "TopicBridge", "TopicBridgeRemoved"]


@dataclass(frozen=True)
class TopicBridge(Result):
    """A subscriber or publisher bridge, as its create op and `list_bridges` describe it:
    its resolved type, device, OpenIGTLink type, QoS, messages so far and rate cap;
    ``extra``: what its kind adds (a publisher's subscriber count, frame, labels topic; a
    pose subscriber's ``lane_written``, the values its native lane wrote), sent beside the
    others; ``message_device``: where this client gets whole messages."""

    kind: str  # "subscriber" | "publisher"
    topic: str
    type: str
    device: str
    igtl_type: str
    qos: Optional[dict[str, Any]] = None
    messages: int = 0
    rate_hz: Optional[float] = None
    extra: dict[str, Any] = field(default_factory=dict)
    message_device: Optional[str] = None

    def to_dict(self) -> dict[str, Any]:
        out = super().to_dict()
        device = out.pop("message_device", None)
        out.update(out.pop("extra"))
        if device is not None:
            out["message_device"] = device
        return out


@dataclass(frozen=True)
class TopicBridgeRemoved(Result):
    topic: str
    device: str


# The type of a publisher's labels topic (markups labels as a JSON list).
LABELS_TYPE = "std_msgs/msg/String"


def _qos(a: Args) -> QoS:
    sub = a.opt_obj("qos")
    return QoS.from_args(sub) if sub is not None else QoS()


def _msg_type(a: Args) -> str:
    text = a.req_str("type")
    check_message_type(text, a.path("type"))  # a bare name is the daemon's to look up
    return text


@dataclass(frozen=True)
class CreateSubscriber(Op, op="create_subscriber", result=TopicBridge, ros_names=("topic",),
                       writes=False,
                       content=("messages",),
                       creates=Bridge("subscriber", ("topic",), section="subscribers")):
    """Subscribe to a ROS topic; messages then flow to clients as OpenIGTLink messages.

    ``type`` is kept as given (the reference's ``IntTable`` vs ``IntArray`` choose the
    Slicer representation); `ros_type` is the resolved ``pkg/msg/Type``. ``messages``: this
    client also gets the newest message whole, at most once a display frame (60 Hz), as
    generic JSON in ROS units, on the device the reply names ``message_device`` (lossless,
    for message objects; each carries the subscription's count; images and point clouds
    have none: their IMAGE / POLYDATA stream is already whole). ``native``: false, with
    ``messages``, for a client that reads the messages whole only (message objects): it
    then gets none of the topic's native values (TRANSFORM, STRING...), so each message
    costs it and the daemon once, not twice; it still gets the stream's stale/live STATUS.
    Asked again with ``native`` true, it gets the values again."""

    examples = (Example({"topic": "/a", "type": "String"}, {("topic", "topic", "/a")}),
                Example({"topic": "/a", "type": "PoseStamped", "messages": True,
                         "native": False}, {("topic", "topic", "/a")}))

    topic: str
    type: str
    qos: QoS = QoS()
    rate_hz: float | None = None
    messages: bool = False
    native: bool = True

    def resources(self) -> tuple[Resource, ...]:
        return (TopicUse("topic", self.topic, self.type),)

    @property
    def ros_type(self) -> str:
        return resolve_message_type(self.type)

    @classmethod
    def from_args(cls, a: Args) -> CreateSubscriber:
        messages, native = a.opt_bool("messages", False), a.opt_bool("native", True)
        if not native and not messages:
            raise OutOfRangeError(a.path("native"), "true, or false with messages true (a "
                                  "client that declines the values reads them whole)",
                                  "false without messages")
        return cls(topic=a.ros_name("topic"), type=_msg_type(a), qos=_qos(a), rate_hz=a.rate_hz(),
                   messages=messages, native=native)


@dataclass(frozen=True)
class RemoveSubscriber(Op, op="remove_subscriber", result=TopicBridgeRemoved, ros_names=("topic",),
                       writes=False, removes="subscriber"):
    examples = (Example({"topic": "/a"}),)

    topic: str

    def resources(self) -> tuple[Resource, ...]:
        return ()  # judged by who made the bridge

    @classmethod
    def from_args(cls, a: Args) -> RemoveSubscriber:
        return cls(topic=a.ros_name("topic"))


@dataclass(frozen=True)
class CreatePublisher(Op, op="create_publisher", result=TopicBridge,
                      ros_names=("topic", "labels_topic"), writes=True,
                      content=("messages",),
                      creates=Bridge("publisher", ("topic",), section="publishers")):
    """Create a ROS publisher; clients feed it with `Publish` or by sending OpenIGTLink
    messages under the device name the reply gives.

    ``frame``: the frame id its messages are in (a model, markups or a curve from Slicer),
    judged by the frame globs; a message's ``ros2.frame`` metadata may name another, judged
    alike when it is published. ``labels_topic``: where the labels of markups sent as POINT
    go (a ``std_msgs/String`` holding a JSON list, one label per point, published just
    before the points), since PoseArray and PointStamped carry none."""

    examples = (Example({"topic": "/a", "type": "String"}, {("topic", "topic", "/a")}),)

    topic: str
    type: str
    qos: QoS = QoS()
    frame: str | None = None
    labels_topic: str | None = None

    def resources(self) -> tuple[Resource, ...]:
        uses: list[Resource] = [TopicUse("topic", self.topic, self.type, writes=True)]
        if self.labels_topic is not None:
            uses.append(TopicUse("labels_topic", self.labels_topic, LABELS_TYPE, writes=True))
        if self.frame:  # published as given: --frame-prefix is for tf's own frames
            uses.append(FrameUse("frame", self.frame, client_frame=False))
        return tuple(uses)

    @property
    def ros_type(self) -> str:
        return resolve_message_type(self.type)

    @classmethod
    def from_args(cls, a: Args) -> CreatePublisher:
        frame = a.opt_str("frame", None)
        if frame is not None and ("\x00" in frame or frame.strip() != frame):
            raise OutOfRangeError(a.path("frame"), "a frame id without NUL or outer spaces",
                                  repr(frame))
        labels = a.opt_str("labels_topic", None, pattern=ROS_NAME, desc=ROS_NAME_DESC)
        return cls(topic=a.ros_name("topic"), type=_msg_type(a), qos=_qos(a),
                   frame=frame, labels_topic=labels)


@dataclass(frozen=True)
class RemovePublisher(Op, op="remove_publisher", result=TopicBridgeRemoved, ros_names=("topic",),
                      writes=False, removes="publisher"):
    examples = (Example({"topic": "/a"}),)

    topic: str

    def resources(self) -> tuple[Resource, ...]:
        return ()  # judged by who made the bridge

    @classmethod
    def from_args(cls, a: Args) -> RemovePublisher:
        return cls(topic=a.ros_name("topic"))


@dataclass(frozen=True)
class Publish(Op, Answered[PublishResult], op="publish", ros_names=("topic",), writes=True):
    """Publish one message on an existing publisher. Either ``value``: the message as a JSON
    object of its fields, or a bare value for one-field types (String: "text", Int: 3, a
    4x4 mm matrix for Pose/PoseStamped/Transform...); or ``message``: the whole message as
    generic JSON in ROS units (metres, quaternions), every field checked strictly, as a
    subscriber's message stream gives it. Reply: subscriber count."""

    examples = (Example({"topic": "/a", "value": "x"}, {("topic", "topic", "/a")}),)

    topic: str
    value: Any = None
    message: dict[str, Any] | None = None

    def resources(self) -> tuple[Resource, ...]:
        return (TopicUse("topic", self.topic, writes=True),)

    def to_args(self) -> dict[str, Any]:
        out = super().to_args()
        if self.message is None:
            out["value"] = self.value  # null is a value (Empty), not a missing field
        return out

    @classmethod
    def from_args(cls, a: Args) -> Publish:
        topic = a.ros_name("topic")
        message = a.raw("message", False)
        if message is MISSING:
            return cls(topic=topic, value=a.any("value"))
        if "value" in a.keys():
            raise OutOfRangeError(a.path("value"), "either value or message, not both",
                                  "both")
        if not isinstance(message, dict):
            raise WrongTypeError(a.path("message"), "an object", json_type(message))
        return cls(topic=topic, message=message)


@dataclass(frozen=True)
class GetLastMessage(Op, Answered[GetLastMessageResult], op="get_last_message",
                     ros_names=("topic",),
                     writes=False):
    """The last message a subscriber received, as YAML or JSON text, and the count."""

    examples = (Example({"topic": "/a"}, {("topic", "topic", "/a")}),)

    topic: str
    format: str = "yaml"  # yaml | json

    def resources(self) -> tuple[Resource, ...]:
        return (TopicUse("topic", self.topic),)

    @classmethod
    def from_args(cls, a: Args) -> GetLastMessage:
        return cls(topic=a.ros_name("topic"), format=a.choice("format", ("yaml", "json"), "yaml"))

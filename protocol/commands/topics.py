"""Topic ops: subscriber and publisher bridges, publishing, the last message."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from protocol.commands.fields import Args
from protocol.commands.op import Bridge, Op, Resource, TopicUse
from protocol.commands.types import resolve_message_type
from protocol.commands.values import QoS

__all__ = ["CreatePublisher", "CreateSubscriber", "GetLastMessage", "Publish", "RemovePublisher",
           "RemoveSubscriber"]


def _qos(a: Args) -> QoS:
    sub = a.opt_obj("qos")
    return QoS.from_args(sub) if sub is not None else QoS()


def _msg_type(a: Args) -> str:
    text = a.req_str("type")
    resolve_message_type(text, a.path("type"))
    return text


@dataclass(frozen=True)
class CreateSubscriber(Op, op="create_subscriber", writes=False,
                       creates=Bridge("subscriber", ("topic",), section="subscribers")):
    """Subscribe to a ROS topic; messages then flow to clients as OpenIGTLink messages.

    ``type`` is kept as given (the reference's ``IntTable`` vs ``IntArray`` choose the
    Slicer representation); `ros_type` is the resolved ``pkg/msg/Type``."""

    topic: str
    type: str
    qos: QoS = QoS()
    rate_hz: float | None = None

    def resources(self) -> tuple[Resource, ...]:
        return (TopicUse("topic", self.topic, self.type),)

    @property
    def ros_type(self) -> str:
        return resolve_message_type(self.type)

    @classmethod
    def from_args(cls, a: Args) -> CreateSubscriber:
        return cls(topic=a.ros_name("topic"), type=_msg_type(a), qos=_qos(a), rate_hz=a.rate_hz())


@dataclass(frozen=True)
class RemoveSubscriber(Op, op="remove_subscriber", writes=False, removes="subscriber"):
    topic: str

    def resources(self) -> tuple[Resource, ...]:
        return ()  # judged by who made the bridge

    @classmethod
    def from_args(cls, a: Args) -> RemoveSubscriber:
        return cls(topic=a.ros_name("topic"))


@dataclass(frozen=True)
class CreatePublisher(Op, op="create_publisher", writes=True,
                      creates=Bridge("publisher", ("topic",), section="publishers")):
    """Create a ROS publisher; clients feed it with `Publish` or by sending OpenIGTLink
    messages under the device name the reply gives."""

    topic: str
    type: str
    qos: QoS = QoS()

    def resources(self) -> tuple[Resource, ...]:
        return (TopicUse("topic", self.topic, self.type, writes=True),)

    @property
    def ros_type(self) -> str:
        return resolve_message_type(self.type)

    @classmethod
    def from_args(cls, a: Args) -> CreatePublisher:
        return cls(topic=a.ros_name("topic"), type=_msg_type(a), qos=_qos(a))


@dataclass(frozen=True)
class RemovePublisher(Op, op="remove_publisher", writes=False, removes="publisher"):
    topic: str

    def resources(self) -> tuple[Resource, ...]:
        return ()  # judged by who made the bridge

    @classmethod
    def from_args(cls, a: Args) -> RemovePublisher:
        return cls(topic=a.ros_name("topic"))


@dataclass(frozen=True)
class Publish(Op, op="publish", writes=True):
    """Publish one message on an existing publisher. ``value`` is the message as a JSON
    object of its fields, or a bare value for one-field types (String: "text", Int: 3, a
    4x4 mm matrix for Pose/PoseStamped/Transform...). Reply: subscriber count."""

    topic: str
    value: Any

    def resources(self) -> tuple[Resource, ...]:
        return (TopicUse("topic", self.topic, writes=True),)

    @classmethod
    def from_args(cls, a: Args) -> Publish:
        return cls(topic=a.ros_name("topic"), value=a.any("value"))


@dataclass(frozen=True)
class GetLastMessage(Op, op="get_last_message", writes=False):
    """The last message a subscriber received, as YAML or JSON text, and the count."""

    topic: str
    format: str = "yaml"  # yaml | json

    def resources(self) -> tuple[Resource, ...]:
        return (TopicUse("topic", self.topic),)

    @classmethod
    def from_args(cls, a: Args) -> GetLastMessage:
        return cls(topic=a.ros_name("topic"), format=a.choice("format", ("yaml", "json"), "yaml"))

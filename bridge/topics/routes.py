"""How a subscribed topic's messages reach clients: one route per message kind, decided
here (`route_for`), read top to bottom.

Every subscriber bridge takes its messages serialized (CDR bytes), so a message's size is
known before anything is kept, and its last one stays as bytes until someone asks for it.
Then, by the message's kind:

1. ``POSE`` (geometry_msgs Pose, PoseStamped, TransformStamped): its numbers are read
   straight from the bytes (bridge/codecs/cdr.py) into a TRANSFORM made from a template
   (bridge/codecs/fast.py: `RawPoseStream`). Where the native lane is built
   (bridge/core/_native_stream.pyx), it does the same in C in the middleware's callback and
   writes to every client's socket itself; what it cannot write whole (a client that
   lags, a paced display, bytes it does not read) comes back to the Python way, in order.
2. ``IMAGE`` (sensor_msgs Image): a frame laid out as the last one is sent with its pixels
   where they lie in the bytes (bridge/codecs/fast_image.py); the first, or one laid out
   otherwise, goes as ``SERIALIZED``.
3. ``SERIALIZED`` (types whose codec reads the bytes itself: PointCloud2): the codec
   converts from the bytes, without building the rclpy message.
4. ``MESSAGE`` (every other type, and any topic the security policy filters, such as /tf
   for a client with a frame allow list: the filter needs the message): rclpy deserializes
   it, the filter judges it, its codec converts it.

Each route ends in one `Frame` per message posted to the hub (bridge/core/hub.py), which
writes it to each client from the posting thread when nothing of that client waits, else
hands it to the event loop (newest value per device for a client that lags); a client
paced to a display takes its newest values once a frame (bridge/core/display.py). A
subscriber's message stream (each message whole, as JSON) is made at display rate by its
own thread from the last message (bridge/topics/whole_messages.py), whatever the route.
"""

from __future__ import annotations

import enum

from bridge.codecs import TypeCodec
from bridge.codecs.fast import has_fast_path
from bridge.codecs.image import ImageCodec

__all__ = ["Route", "route_for"]


class Route(enum.Enum):
    POSE = "pose"
    IMAGE = "image"
    SERIALIZED = "serialized"
    MESSAGE = "message"


def route_for(codec: TypeCodec, filtered: bool) -> Route:
    """The route of a topic of `codec`'s type; `filtered`: the policy judges each message
    (it needs the rclpy message)."""
    if filtered:
        return Route.MESSAGE
    if has_fast_path(codec.ros_type):
        return Route.POSE
    if isinstance(codec, ImageCodec):
        return Route.IMAGE
    reads_bytes = getattr(type(codec), "encode_serialized", TypeCodec.encode_serialized)
    if reads_bytes is not TypeCodec.encode_serialized:  # its codec has a reader of the bytes
        return Route.SERIALIZED
    return Route.MESSAGE

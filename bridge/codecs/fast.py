"""The hot path of a streamed pose: CDR bytes in, a TRANSFORM's packed content and its
stream's `StreamTemplate` out, with no rclpy message, numpy array or `Message` built.

The bytes it makes are the ones `TypeCodec.encode` + `protocol.framing.encode` make for the
same message (tests compare them): the numbers go through the one quaternion formula
(`protocol.conversions.pose_to_igtl12`), and the metadata of each (frame_id,
child_frame_id) pair is computed once by the ordinary codec and then reused. Whatever this
path does not handle (another CDR encoding, a NaN, a zero quaternion, a translation beyond
float32 in mm) raises `NotFast`, and the caller converts that message the ordinary way,
which says what is wrong with it (and drops it).
"""

from __future__ import annotations

import struct
from typing import Any
from bridge.codecs.base import TypeCodec
from bridge.codecs.cdr import RAW_POSE_READERS, CdrError, RawPose
from protocol.conversions import (
    igtl12_to_matrix,
    igtl_stamp_or_now,
    pose_to_igtl12,
)
from protocol.errors import ProtocolError
from protocol.framing import StreamTemplate
from protocol.messages import Transform

__all__ = ["NotFast", "RawPoseStream", "has_fast_path", "pose_document", "read_raw_pose",
           "transform_body"]

_TWELVE = struct.Struct(">12f")
_U32_MAX = 0xFFFFFFFF
# Distinct (frame_id, child_frame_id) pairs remembered per stream: a publisher that changes
# frame ids on every message only costs a re-computation, never memory.
_MAX_TEMPLATES = 64


class NotFast(Exception):
    """This message takes the ordinary path (the reason is in the message)."""


def has_fast_path(ros_type: str) -> bool:
    return ros_type in RAW_POSE_READERS


def read_raw_pose(ros_type: str, data: bytes) -> RawPose:
    """A hot pose type's numbers, read straight from its CDR bytes; `NotFast` if they
    cannot be (the caller deserializes them the ordinary way)."""
    try:
        return RAW_POSE_READERS[ros_type](data)
    except CdrError as error:
        raise NotFast(str(error)) from None


def pose_document(ros_type: str, raw: RawPose) -> dict[str, Any]:
    """A hot pose type as `message_to_dict` gives it (the message stream's generic JSON),
    from its numbers, without building the rclpy message (tests/bridge/test_fast_path.py
    holds the two equal)."""
    sec, nanosec, frame, child, tx, ty, tz, x, y, z, w = raw
    position = {"x": tx, "y": ty, "z": tz}
    orientation = {"x": x, "y": y, "z": z, "w": w}
    if ros_type == "geometry_msgs/msg/Pose":
        return {"position": position, "orientation": orientation}
    header = {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": frame}
    if ros_type == "geometry_msgs/msg/PoseStamped":
        return {"header": header, "pose": {"position": position, "orientation": orientation}}
    return {"header": header, "child_frame_id": child,
            "transform": {"translation": position, "rotation": orientation}}


def pack_transform(values: tuple[float, ...]) -> bytes:
    """A TRANSFORM's content from the 12 wire-order numbers `pose_to_igtl12` gave (they fit
    float32: it judged them)."""
    return _TWELVE.pack(*values)


def transform_body(values: tuple[float, ...]) -> Transform:
    """The `Transform` body of 12 wire-order numbers (for a `TemplateFrame`'s message)."""
    return Transform(matrix=igtl12_to_matrix(values))


class RawPoseStream:
    """One streamed Pose / PoseStamped / TransformStamped topic's conversion."""

    def __init__(self, codec: TypeCodec, device: str, metadata: dict[str, str]) -> None:
        self._codec = codec
        self._device = device
        self._metadata = metadata
        self._templates: dict[tuple[str, str], StreamTemplate] = {}
        self.ids = ("", "")  # the (frame_id, child_frame_id) of the last message converted

    def convert(self, data: bytes) -> tuple[StreamTemplate, bytes, int, tuple[float, ...]]:
        """CDR bytes -> (template, TRANSFORM content, IGTL time stamp, the 12 numbers)."""
        sec, nanosec, frame, child, tx, ty, tz, x, y, z, w = read_raw_pose(
            self._codec.ros_type, data)
        values = pose_to_igtl12(tx, ty, tz, x, y, z, w)
        if values is None:
            raise NotFast("a NaN, an infinity, a zero quaternion or a length beyond float32")
        content = pack_transform(values)
        template = self._templates.get((frame, child))
        if template is None:
            template = self._template_for(data, frame, child)
        self.ids = (frame, child)
        return template, content, igtl_stamp_or_now(sec, nanosec), values

    def _template_for(self, data: bytes, frame: str, child: str) -> StreamTemplate:
        from rclpy.serialization import deserialize_message

        # The ordinary codec says what metadata this frame pair gets: one place for it.
        try:
            encoded = self._codec.encode(deserialize_message(data, self._codec.message_class))
            metadata = dict(self._metadata)
            metadata.update(encoded.metadata)
            template = StreamTemplate(self._codec.igtl_type, self._device, metadata)
        except (ProtocolError, ValueError, TypeError) as error:
            raise NotFast(f"metadata: {error}") from None
        if len(self._templates) >= _MAX_TEMPLATES:
            self._templates.clear()
        self._templates[(frame, child)] = template
        return template


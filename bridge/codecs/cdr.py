"""Serialized ROS messages (CDR bytes, as a ``raw=True`` subscription delivers them) read
straight into numbers, for the hot types whose callbacks run thousands of times a second:
geometry_msgs Pose, PoseStamped and TransformStamped, and tf2_msgs TFMessage; and
sensor_msgs Image, whose pixels are then read in place (rclpy would copy them twice).

rclpy builds six to ten Python objects for one PoseStamped; reading its numbers with one
precompiled `struct` is far cheaper (bench/bench_pose_path.py weighs both). Only
little-endian plain CDR (what every ROS 2 middleware sends on x86 and ARM) is read here;
anything else raises `CdrError` and the caller deserializes the message the ordinary way.

Layout (XCDR1, offsets after the 4-byte encapsulation header; primitives aligned to their
size from there): ``Time`` = int32 sec, uint32 nanosec; ``string`` = uint32 length
including the NUL, the bytes, the NUL; then doubles aligned to 8.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Callable

__all__ = ["CdrError", "RawImage", "RawPointCloud2", "RawPointField", "RawPose",
           "RAW_POSE_READERS", "plain_little_endian", "read_image", "read_point_cloud2",
           "read_pose", "read_pose_stamped", "read_tf_message", "read_transform_stamped"]

_CDR_LE = b"\x00\x01"
_STAMP = struct.Struct("<iiI")  # sec, nanosec, frame_id length (all at offset 4)
_U32 = struct.Struct("<I")
_SEC_NANOSEC = struct.Struct("<iI")
_SEVEN = struct.Struct("<7d")

# (sec, nanosec, frame_id, child_frame_id, tx, ty, tz, qx, qy, qz, qw); sec = -1 and
# nanosec = 0 when the type has no header (Pose).
RawPose = tuple[int, int, str, str, float, float, float, float, float, float, float]


class CdrError(ValueError):
    """Bytes this reader does not handle (another encoding, or too short)."""

    def __init__(self, expected: str, got: str) -> None:
        super().__init__(f"expected {expected}, got {got}")


def plain_little_endian(data: bytes) -> bool:
    """Whether ``data`` is in the one encoding read here (encapsulation 00 01)."""
    return data[:2] == _CDR_LE


def _check(data: bytes) -> None:
    if not plain_little_endian(data):
        raise CdrError("little-endian plain CDR (encapsulation 00 01)", data[:2].hex() or "0 bytes")


def _string(data: bytes, offset: int) -> tuple[str, int]:
    """A CDR string at ``offset`` (already aligned to 4) -> (text, offset after it)."""
    (length,) = _U32.unpack_from(data, offset)
    start = offset + 4
    end = start + length
    if length == 0 or end > len(data):
        raise CdrError("a string within the message", f"length {length} at offset {offset}")
    return data[start:end - 1].decode("utf-8"), end


def _align8(offset: int) -> int:
    # Alignment counts from the end of the 4-byte encapsulation header.
    return offset + (-(offset - 4) & 7)


def read_pose_stamped(data: bytes) -> RawPose:
    _check(data)
    try:
        sec, nanosec, length = _STAMP.unpack_from(data, 4)
        end = 16 + length
        if length == 0 or end > len(data):
            raise CdrError("a frame_id within the message", f"length {length}")
        frame = data[16:end - 1].decode("utf-8")
        return (sec, nanosec, frame, "", *_SEVEN.unpack_from(data, _align8(end)))
    except (struct.error, UnicodeDecodeError) as error:
        raise CdrError("a whole PoseStamped", str(error)) from None


def _transform_stamped_at(data: bytes, offset: int) -> tuple[RawPose, int]:
    """A TransformStamped starting at ``offset`` (aligned to 4) -> (it, offset after it)."""
    sec, nanosec = _SEC_NANOSEC.unpack_from(data, offset)
    frame, offset = _string(data, offset + 8)
    child, offset = _string(data, offset + (-(offset - 4) & 3))
    offset = _align8(offset)
    return (sec, nanosec, frame, child, *_SEVEN.unpack_from(data, offset)), offset + 56


def read_transform_stamped(data: bytes) -> RawPose:
    _check(data)
    try:
        return _transform_stamped_at(data, 4)[0]
    except (struct.error, UnicodeDecodeError) as error:
        raise CdrError("a whole TransformStamped", str(error)) from None


def read_tf_message(data: bytes) -> list[RawPose]:
    """tf2_msgs/TFMessage: its transforms, in order."""
    _check(data)
    try:
        (count,) = _U32.unpack_from(data, 4)
        if count > (len(data) - 8) // 72:  # 72: the smallest TransformStamped
            raise CdrError("a transform count the message can hold", str(count))
        out = []
        offset = 8
        for _ in range(count):
            transform, offset = _transform_stamped_at(data, offset)
            out.append(transform)
        return out
    except (struct.error, UnicodeDecodeError) as error:
        raise CdrError("a whole TFMessage", str(error)) from None


def read_pose(data: bytes) -> RawPose:
    _check(data)
    try:
        return (-1, 0, "", "", *_SEVEN.unpack_from(data, 4))
    except struct.error as error:
        raise CdrError("a whole Pose", str(error)) from None


RAW_POSE_READERS: dict[str, Callable[[bytes], RawPose]] = {
    "geometry_msgs/msg/Pose": read_pose,
    "geometry_msgs/msg/PoseStamped": read_pose_stamped,
    "geometry_msgs/msg/TransformStamped": read_transform_stamped,
}


@dataclass(frozen=True)
class _Time:
    sec: int
    nanosec: int


@dataclass(frozen=True)
class _Header:
    stamp: _Time
    frame_id: str


@dataclass(frozen=True)
class RawImage:
    """A sensor_msgs/Image read from its bytes, with the message's field names (so a codec
    reads it as it reads an rclpy Image); ``data`` is a view on the serialized bytes."""

    header: _Header
    height: int
    width: int
    encoding: str
    is_bigendian: int
    step: int
    data: memoryview
    data_start: int  # where ``data`` begins in the serialized bytes
    # The byte ranges that hold the other fields after the stamp (alignment padding, which
    # a serializer may leave unset, left out).
    field_spans: tuple[tuple[int, int], ...]


_HEIGHT_WIDTH = struct.Struct("<II")
_U8_U32 = struct.Struct("<B3xI")  # a PointField's datatype, padding, count


@dataclass(frozen=True)
class RawPointField:
    name: str
    offset: int
    datatype: int
    count: int


@dataclass(frozen=True)
class RawPointCloud2:
    """A sensor_msgs/PointCloud2 read from its bytes, with the message's field names (a
    codec reads it as an rclpy PointCloud2); ``data`` is a view on the serialized bytes."""

    header: _Header
    height: int
    width: int
    fields: tuple[RawPointField, ...]
    is_bigendian: int
    point_step: int
    row_step: int
    data: memoryview
    is_dense: int


def read_image(data: bytes) -> RawImage:
    """sensor_msgs/Image: header, height, width, encoding, is_bigendian, step, data
    (uint32 count, then the bytes)."""
    _check(data)
    try:
        sec, nanosec = _SEC_NANOSEC.unpack_from(data, 4)
        frame, frame_end = _string(data, 12)
        sizes = frame_end + (-frame_end & 3)
        height, width = _HEIGHT_WIDTH.unpack_from(data, sizes)
        encoding, offset = _string(data, sizes + 8)
        is_bigendian = data[offset]
        offset += 1
        steps = offset + (-offset & 3)
        step, count = _HEIGHT_WIDTH.unpack_from(data, steps)
        start = steps + 8
        if start + count > len(data):
            raise CdrError("the image's data within the message",
                           f"{count} bytes at offset {start} of {len(data)}")
        return RawImage(_Header(_Time(sec, nanosec), frame), height, width, encoding,
                        is_bigendian, step, memoryview(data)[start:start + count], start,
                        ((12, frame_end), (sizes, offset), (steps, start)))
    except (struct.error, UnicodeDecodeError, IndexError) as error:
        raise CdrError("a whole Image", str(error)) from None


def read_point_cloud2(data: bytes) -> RawPointCloud2:
    """sensor_msgs/PointCloud2: header, height, width, fields (uint32 count, then each
    name, offset, datatype, count), is_bigendian, point_step, row_step, data (uint32
    count, then the bytes), is_dense."""
    _check(data)
    try:
        sec, nanosec = _SEC_NANOSEC.unpack_from(data, 4)
        frame, offset = _string(data, 12)
        offset += -offset & 3
        height, width = _HEIGHT_WIDTH.unpack_from(data, offset)
        (nfields,) = _U32.unpack_from(data, offset + 8)
        offset += 12
        if nfields > len(data) // 13:  # each takes 13 bytes or more
            raise CdrError("a field count within the message", str(nfields))
        fields = []
        for _ in range(nfields):
            name, offset = _string(data, offset)
            offset += -offset & 3
            (field_offset,) = _U32.unpack_from(data, offset)
            datatype, count = _U8_U32.unpack_from(data, offset + 4)
            fields.append(RawPointField(name, field_offset, datatype, count))
            offset += 12
        is_bigendian = data[offset]
        offset += 1
        offset += -offset & 3
        point_step, row_step = _HEIGHT_WIDTH.unpack_from(data, offset)
        (size,) = _U32.unpack_from(data, offset + 8)
        start = offset + 12
        if start + size >= len(data):  # is_dense follows the data
            raise CdrError("the cloud's data within the message",
                           f"{size} bytes at offset {start} of {len(data)}")
        return RawPointCloud2(_Header(_Time(sec, nanosec), frame), height, width,
                              tuple(fields), is_bigendian, point_step, row_step,
                              memoryview(data)[start:start + size], data[start + size])
    except (struct.error, UnicodeDecodeError, IndexError) as error:
        raise CdrError("a whole PointCloud2", str(error)) from None

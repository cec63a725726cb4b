"""visualization_msgs Marker and MarkerArray read from their CDR bytes (a ``raw=True``
subscription) straight into `MarkerEvent`s.

Why: rclpy builds about twenty Python objects per Marker; a MarkerArray of 1000 markers
costs ~70 ms to deserialize and ~35 ms more to read field by field, more than a 10 Hz
publisher leaves. Reading the bytes with precompiled structs and numpy (points, colours)
costs a fraction of that. Little-endian plain CDR only (what every ROS 2 middleware sends
on x86 and ARM); anything else raises `CdrError` and the caller deserializes the message.

The layout is the Marker of the installed visualization_msgs (Humble has no texture and
mesh_file fields, Jazzy has them): `layout_supported` compares the installed message's
field list with `MARKER_FIELDS` and the capability uses this reader only when they match.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable
from typing import Optional

import numpy as np

from bridge.codecs.cdr import CdrError
from bridge.markers.convert import ADD, MarkerEvent, marker_event
from bridge.markers.geometry import MAX_MARKER_POINTS, MarkerError

__all__ = ["MARKER_FIELDS", "layout_supported", "read_marker", "read_marker_array"]

MARKER_FIELDS = ("header", "ns", "id", "type", "action", "pose", "scale", "color",
                 "lifetime", "frame_locked", "points", "colors", "texture_resource",
                 "texture", "uv_coordinates", "text", "mesh_resource", "mesh_file",
                 "mesh_use_embedded_materials")
_CDR_LE = b"\x00\x01"
_I32x3 = struct.Struct("<iii")
_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")
_POSE_SCALE = struct.Struct("<10d")  # position, orientation, scale
_COLOR = struct.Struct("<4f")


def layout_supported(fields: Iterable[str]) -> bool:
    """Does the installed Marker have exactly the fields this reader reads?"""
    return tuple(fields) == MARKER_FIELDS


class _Reader:
    __slots__ = ("data", "pos")

    def __init__(self, data: bytes, pos: int) -> None:
        self.data = data
        self.pos = pos

    def align(self, size: int) -> None:
        self.pos += -(self.pos - 4) % size  # alignment counts after the 4-byte header

    def need(self, size: int) -> None:
        if self.pos + size > len(self.data):
            raise CdrError("a complete Marker", f"{len(self.data)} bytes, needing "
                           f"{self.pos + size}")

    def u32(self) -> int:
        self.align(4)
        self.need(4)
        (value,) = _U32.unpack_from(self.data, self.pos)
        self.pos += 4
        return int(value)

    def string(self) -> str:
        length = self.u32()
        self.need(length)
        start = self.pos
        self.pos += length
        if length == 0:
            raise CdrError("a string with its NUL", "length 0")
        return self.data[start:self.pos - 1].decode("utf-8", "replace")

    def skip_bytes(self) -> None:
        count = self.u32()
        self.need(count)
        self.pos += count

    def floats(self, count: int, width: int, dtype: str) -> np.ndarray:
        if count:
            self.align(width)
        self.need(count * width)
        out = np.frombuffer(self.data, dtype=dtype, count=count, offset=self.pos)
        self.pos += count * width
        return out


def _marker(r: _Reader) -> MarkerEvent:
    r.align(4)
    r.need(8)
    sec, nanosec = _STAMP.unpack_from(r.data, r.pos)
    r.pos += 8
    frame = r.string()
    ns = r.string()
    r.align(4)
    r.need(12)
    marker_id, marker_type, action = _I32x3.unpack_from(r.data, r.pos)
    r.pos += 12
    r.align(8)
    r.need(80)
    numbers = _POSE_SCALE.unpack_from(r.data, r.pos)
    r.pos += 80
    r.need(16)
    color = _COLOR.unpack_from(r.data, r.pos)
    r.pos += 16
    r.need(9)
    life_sec, life_nanosec = _STAMP.unpack_from(r.data, r.pos)
    r.pos += 8
    frame_locked = r.data[r.pos] != 0
    r.pos += 1
    n_points = r.u32()
    too_many: Optional[MarkerError] = None
    if n_points > MAX_MARKER_POINTS:
        too_many = MarkerError("points", f"at most {MAX_MARKER_POINTS} points",
                               f"{n_points} points")
    points = r.floats(3 * n_points, 8, "<f8").reshape(n_points, 3)
    n_colors = r.u32()
    colors = r.floats(4 * n_colors, 4, "<f4").reshape(n_colors, 4).astype(np.float64)
    r.string()  # texture_resource
    r.align(4)
    r.need(8)
    r.pos += 8  # texture.header.stamp
    r.string()  # texture.header.frame_id
    r.string()  # texture.format
    r.skip_bytes()  # texture.data
    n_uv = r.u32()
    r.floats(2 * n_uv, 4, "<f4")  # uv_coordinates
    text = r.string()
    mesh_resource = r.string()
    mesh_file = r.string()  # mesh_file.filename
    r.skip_bytes()  # mesh_file.data
    r.need(1)
    embedded = r.data[r.pos] != 0
    r.pos += 1
    if too_many is not None:
        return MarkerEvent(ADD, ns, int(marker_id), error=too_many)
    return marker_event(
        ns=ns, marker_id=int(marker_id), marker_type=int(marker_type), action=int(action),
        frame=frame, numbers=numbers, color=color, lifetime=(life_sec, life_nanosec),
        frame_locked=frame_locked, points=points, colors=colors if n_colors else None,
        text=text, mesh_resource=mesh_resource, mesh_file=mesh_file,
        embedded=embedded, stamp=(int(sec), int(nanosec)))


def _start(data: bytes) -> _Reader:
    if data[:2] != _CDR_LE:
        raise CdrError("little-endian plain CDR (encapsulation 00 01)",
                       data[:2].hex() or "0 bytes")
    return _Reader(data, 4)


def read_marker(data: bytes) -> list[MarkerEvent]:
    return [_marker(_start(data))]


def read_marker_array(data: bytes) -> list[MarkerEvent]:
    r = _start(data)
    count = r.u32()
    return [_marker(r) for _ in range(count)]

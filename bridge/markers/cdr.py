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

import numpy as np

from bridge.codecs.cdr import CdrError
from bridge.markers.convert import ADD, MarkerEvent, check_array_size, marker_event
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

    def u32(self) -> int:
        self.align(4)
        if self.pos + 4 > len(self.data):
            raise CdrError("a complete MarkerArray", f"{len(self.data)} bytes")
        (value,) = _U32.unpack_from(self.data, self.pos)
        self.pos += 4
        return int(value)


def _marker(r: _Reader) -> MarkerEvent:
    # Inlined reads (this runs 1000 times per array): the position in a local, alignment
    # counted after the 4-byte header, every read bounds-checked (struct, or here).
    data, pos = r.data, r.pos
    size = len(data)
    u32 = _U32.unpack_from

    def string(pos: int) -> tuple[str, int]:
        pos += -(pos - 4) % 4
        (length,) = u32(data, pos)
        pos += 4
        if length == 0 or pos + length > size:
            raise CdrError("a string with its NUL within the message",
                           f"length {length} at {pos - 4} of {size} bytes")
        return data[pos:pos + length - 1].decode("utf-8", "replace"), pos + length

    try:
        pos += -(pos - 4) % 4
        sec, nanosec = _STAMP.unpack_from(data, pos)
        frame, pos = string(pos + 8)
        ns, pos = string(pos)
        pos += -(pos - 4) % 4
        marker_id, marker_type, action = _I32x3.unpack_from(data, pos)
        pos += 12
        pos += -(pos - 4) % 8
        numbers = _POSE_SCALE.unpack_from(data, pos)
        color = _COLOR.unpack_from(data, pos + 80)
        life_sec, life_nanosec = _STAMP.unpack_from(data, pos + 96)
        frame_locked = data[pos + 104] != 0
        pos += 105
        pos += -(pos - 4) % 4
        (n_points,) = u32(data, pos)
        pos += 4
        if n_points:
            pos += -(pos - 4) % 8
        if pos + 24 * n_points > size:
            raise IndexError
        too_many = n_points > MAX_MARKER_POINTS  # skipped, not converted: refused below
        points = np.frombuffer(data, "<f8", 0 if too_many else 3 * n_points,
                               pos).reshape(-1, 3)
        pos += 24 * n_points
        pos += -(pos - 4) % 4
        (n_colors,) = u32(data, pos)
        pos += 4
        if pos + 16 * n_colors > size:
            raise IndexError
        colors = np.frombuffer(data, "<f4", 4 * n_colors, pos).reshape(n_colors, 4)
        pos += 16 * n_colors
        _, pos = string(pos)  # texture_resource
        pos += -(pos - 4) % 4
        _, pos = string(pos + 8)  # texture: header stamp, frame_id
        _, pos = string(pos)  # texture.format
        pos += -(pos - 4) % 4
        (count,) = u32(data, pos)
        pos += 4 + count  # texture.data
        pos += -(pos - 4) % 4
        (n_uv,) = u32(data, pos)
        pos += 4 + 8 * n_uv  # uv_coordinates
        text, pos = string(pos)
        mesh_resource, pos = string(pos)
        mesh_file, pos = string(pos)  # mesh_file.filename
        pos += -(pos - 4) % 4
        (count,) = u32(data, pos)
        pos += 4 + count  # mesh_file.data
        if pos >= size:
            raise IndexError
        embedded = data[pos] != 0
        r.pos = pos + 1
    except (struct.error, IndexError):
        raise CdrError("a complete Marker", f"{size} bytes") from None
    if too_many:
        return MarkerEvent(ADD, ns, int(marker_id), error=MarkerError(
            "points", f"at most {MAX_MARKER_POINTS} points", f"{n_points} points"))
    return marker_event(
        ns=ns, marker_id=int(marker_id), marker_type=int(marker_type), action=int(action),
        frame=frame, numbers=numbers, color=color, lifetime=(life_sec, life_nanosec),
        frame_locked=frame_locked, points=points,
        colors=colors.astype(np.float64) if n_colors else None,
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
    """Raises `MarkerError` for an array of more than `MAX_ARRAY_MARKERS` markers."""
    r = _start(data)
    count = r.u32()
    check_array_size(count)
    return [_marker(r) for _ in range(count)]

"""Medical data made in 3D Slicer, to ROS: models (POLYDATA) as ``shape_msgs/Mesh`` and
``visualization_msgs/Marker`` TRIANGLE_LIST, markups points (POINT) as
``geometry_msgs/PoseArray`` / ``PointStamped`` (one per point), and a drawn line or curve
(POINT list or a POLYDATA polyline) as ``nav_msgs/Path``.

Units: Slicer sends millimetres, ROS gets metres, through `protocol.conversions` only. Axes
are unchanged (RAS as the ROS frame, as everywhere in the project).

Polygons: Slicer's models are usually triangles, but a model may hold quads or larger
polygons; each polygon of k >= 3 points is cut into a fan (0, i, i+1), which is exact for
the convex polygons VTK writes. Triangle strips are refused (Slicer's surface filters
triangulate; a strip means an unexpected producer), as are polygons of fewer than 3 points.

Bounds: `MAX_MESH_VERTICES` / `MAX_MESH_TRIANGLES` for Mesh, `MAX_MARKER_TRIANGLES` for a
Marker (which repeats 3 points per triangle), `MAX_PATH_POINTS` and `MAX_MARKUP_POINTS`.
Beyond them, and for NaN/inf coordinates, `CodecError` says what came. Mesh and Marker also
come serialized (`from_igtl_raw`: the CDR bytes built with numpy, spliced into rclpy's
serialization of the rest), which is what the daemon publishes: building a model's million
Points as rclpy objects takes seconds, its bytes milliseconds.

The way back (ROS -> client) is kept where it is lossless: Mesh -> POLYDATA (triangles, mm;
float32 on the wire); PoseArray keeps its STRING of 4x4 matrices (geometry.py). Marker and
Path keep the generic JSON (STRING) to clients: their conversion to Slicer models belongs
to the markers work, not here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, ClassVar

import numpy as np

from bridge.codecs.base import Body, TypeCodec, Stamp
from bridge.codecs.errors import CodecError
from bridge.codecs.generic import numeric_array
from bridge.codecs.json_codec import GenericJsonCodec
from protocol.conversions import fit_float32_mm, metres_to_mm, mm_to_metres
from protocol.messages import Point as PointBody
from protocol.messages import PolyData, cells_from_array, cells_to_list
from protocol.naming import KEY_COLOR, KEY_MARKER_ID, KEY_MARKER_NS, KEY_UNITS, UNITS_MM

__all__ = [
    "MAX_MARKER_TRIANGLES",
    "MAX_MARKUP_POINTS",
    "MAX_MESH_TRIANGLES",
    "MAX_MESH_VERTICES",
    "MAX_PATH_POINTS",
    "MarkerCodec",
    "MeshCodec",
    "PathCodec",
    "PointStampedCodec",
    "fan_triangles",
    "mesh_cdr",
    "splice_points",
    "markup_labels",
    "points_in_metres",
    "pose_array_from_points",
]

# Within the daemon's 64 MiB message limit (12 bytes a point, 16 a triangle on the wire);
# the daemon publishes models serialized with numpy (`from_igtl_raw`), in milliseconds.
MAX_MESH_VERTICES = 1_000_000
MAX_MESH_TRIANGLES = 2_000_000
MAX_MARKER_TRIANGLES = 500_000  # 72 bytes a triangle in ROS (3 points)
MAX_PATH_POINTS = 100_000
MAX_MARKUP_POINTS = 10_000


def _polydata(body: Body, ros_type: str) -> PolyData:
    if not isinstance(body, PolyData):
        raise CodecError(field="body", expected=f"an OpenIGTLink POLYDATA (for {ros_type})",
                         got=type(body).__name__)
    return body


def points_in_metres(points_mm: Any, field: str, limit: int) -> np.ndarray:
    """(N, 3) millimetres from Slicer -> (N, 3) float64 metres; NaN/inf and more than
    ``limit`` points raise `CodecError` naming the first bad point."""
    arr = np.asarray(points_mm, dtype=np.float64).reshape(-1, 3)
    if len(arr) > limit:
        raise CodecError(field=field, expected=f"at most {limit} points", got=f"{len(arr)}")
    bad = np.flatnonzero(~np.isfinite(arr).all(axis=1))
    if bad.size:
        i = int(bad[0])
        raise CodecError(field=f"{field}[{i}]", expected="finite coordinates (mm)",
                         got=repr(arr[i].tolist()))
    return mm_to_metres(arr)


def fan_triangles(body: PolyData, limit: int) -> np.ndarray:
    """The polygons of ``body`` as (M, 3) point indices: triangles as they are, each
    polygon of k > 3 points as the fan (0, i, i+1). Strips, polygons of < 3 points, a model
    without polygons or more than ``limit`` triangles raise `CodecError`."""
    if len(body.triangle_strips):
        raise CodecError(field="body.triangle_strips", expected="polygons (Slicer models are "
                         "triangulated; triangle strips are not converted)",
                         got=f"{len(cells_to_list(body.triangle_strips))} strip(s)")
    flat = np.asarray(body.polygons, dtype=np.int64)
    if flat.size == 0:
        lines = len(body.lines)
        raise CodecError(field="body.polygons", expected="a surface model (polygons)",
                         got="no polygons" + (" (a polyline: publish it as nav_msgs/Path)"
                                              if lines else ""))
    if flat.size % 4 == 0 and bool(np.all(flat[::4] == 3)):  # all triangles: no Python loop
        tris = flat.reshape(-1, 4)[:, 1:]
    else:
        parts: list[np.ndarray] = []
        for i, cell in enumerate(cells_to_list(body.polygons)):
            k = len(cell)
            if k < 3:
                raise CodecError(field=f"body.polygons[{i}]", expected="a polygon of 3 or "
                                 "more points", got=f"{k} point(s)")
            c = np.asarray(cell, dtype=np.int64)
            fan = np.empty((k - 2, 3), dtype=np.int64)
            fan[:, 0] = c[0]
            fan[:, 1] = c[1:-1]
            fan[:, 2] = c[2:]
            parts.append(fan)
        tris = np.concatenate(parts)
    if len(tris) > limit:
        raise CodecError(field="body.polygons", expected=f"at most {limit} triangles",
                         got=f"{len(tris)} triangles")
    return tris


# ---------------------------------------------------------------- serialized (CDR) bulk
# A model of 300,000 triangles is a million rclpy objects (Points, MeshTriangles): about
# 2 s to build. Its serialized form is two numpy arrays and a few bytes, built in ms and
# published as is (rclpy publishes bytes). Little-endian plain CDR (XCDR1), as rclpy's
# serialize_message writes on x86 and ARM: offsets count from after the 4-byte
# encapsulation header; a sequence is a uint32 count, then its elements aligned to their
# primitive size. The tests check the bytes equal serialize_message's.

_ENCAPSULATION = b"\x00\x01\x00\x00"


def _u32(value: int) -> bytes:
    return int(value).to_bytes(4, "little")


def _points_sequence(xyz_m: np.ndarray, at: int) -> bytes:
    """A geometry_msgs/Point sequence whose count starts at absolute offset ``at`` (4-aligned):
    the count, padding to 8, then x, y, z float64 per point."""
    pad = -(at + 4 - 4) & 7
    return b"".join((_u32(len(xyz_m)), b"\x00" * pad,
                     np.ascontiguousarray(xyz_m, dtype="<f8").tobytes()))


def mesh_cdr(vertices_m: np.ndarray, triangles: np.ndarray) -> bytes:
    """shape_msgs/Mesh serialized: MeshTriangle[] (uint32[3] each), then Point[]."""
    tris = np.ascontiguousarray(triangles, dtype="<u4").tobytes()
    head = b"".join((_ENCAPSULATION, _u32(len(triangles)), tris))
    return head + _points_sequence(vertices_m, len(head))


def splice_points(template: bytes, empty_at: int, xyz_m: np.ndarray) -> bytes:
    """A serialized message whose Point sequence (empty in ``template``, its 0 count at
    ``empty_at``) becomes ``xyz_m``. Valid when no field after the sequence needs 8-byte
    alignment (so the tail keeps its alignment: 24 bytes a point, padding 0 or 4)."""
    return template[:empty_at] + _points_sequence(xyz_m, empty_at) + template[empty_at + 4:]


def _colour(metadata: dict[str, str]) -> tuple[float, float, float, float]:
    text = metadata.get(KEY_COLOR)
    if text is None:
        return (1.0, 1.0, 1.0, 1.0)
    try:
        values = tuple(float(v) for v in text.replace(",", " ").split())
    except ValueError:
        values = ()
    if len(values) != 4 or not all(math.isfinite(v) and 0.0 <= v <= 1.0 for v in values):
        raise CodecError(field=f"metadata.{KEY_COLOR}", expected="'r g b a', 4 numbers in "
                         "0..1", got=repr(text))
    return values[0], values[1], values[2], values[3]


def _ros_points(xyz_m: np.ndarray) -> list[Any]:
    from geometry_msgs.msg import Point

    return [Point(x=x, y=y, z=z) for x, y, z in xyz_m.tolist()]


@dataclass(frozen=True)
class MeshCodec(TypeCodec):
    """shape_msgs/Mesh <-> POLYDATA (vertices in mm, one triangle per polygon)."""

    heavy_polydata: ClassVar[bool] = True

    def _to_igtl(self, msg: Any) -> tuple[Body, dict[str, str]]:
        vertices, triangles = self._arrays(msg)
        return (PolyData(points=metres_to_mm(vertices).astype(np.float32),
                         polygons=cells_from_array(triangles.astype(np.uint32))),
                {KEY_UNITS: UNITS_MM})

    def _arrays(self, msg: Any) -> tuple[np.ndarray, np.ndarray]:
        vertices = np.array([(p.x, p.y, p.z) for p in msg.vertices],
                            dtype=np.float64).reshape(-1, 3)
        bad = np.flatnonzero(~fit_float32_mm(vertices).all(axis=1))
        if bad.size:
            raise CodecError(field=f"vertices[{int(bad[0])}]",
                             expected="finite coordinates (within float32 once in mm)",
                             got=repr(vertices[int(bad[0])].tolist()))
        triangles = np.array([list(t.vertex_indices) for t in msg.triangles],
                             dtype=np.int64).reshape(-1, 3)
        if triangles.size and int(triangles.max()) >= len(vertices):
            row = int(np.argwhere(triangles >= len(vertices))[0][0])
            raise CodecError(field=f"triangles[{row}].vertex_indices",
                             expected=f"indices < {len(vertices)} (the vertex count)",
                             got=repr(triangles[row].tolist()))
        return vertices, triangles

    def _build(self, vertices_m: np.ndarray, triangles: np.ndarray) -> Any:
        from shape_msgs.msg import MeshTriangle

        msg = self.message_class()
        msg.vertices = _ros_points(vertices_m)
        msg.triangles = [MeshTriangle(vertex_indices=np.asarray(t, dtype=np.uint32))
                         for t in triangles]
        return msg

    def _from_igtl(self, body: Body, metadata: dict[str, str]) -> Any:
        poly = _polydata(body, self.ros_type)
        vertices = points_in_metres(poly.points, "body.points", MAX_MESH_VERTICES)
        return self._build(vertices, fan_triangles(poly, MAX_MESH_TRIANGLES))

    def _from_igtl_raw(self, body: Body, metadata: dict[str, str]
                       ) -> tuple[Any, Callable[[Any], bytes]]:
        poly = _polydata(body, self.ros_type)
        vertices = points_in_metres(poly.points, "body.points", MAX_MESH_VERTICES)
        triangles = fan_triangles(poly, MAX_MESH_TRIANGLES)
        return self.message_class(), lambda _probe: mesh_cdr(vertices, triangles)

    def _to_value(self, msg: Any) -> Any:
        vertices, triangles = self._arrays(msg)
        return {"vertices": metres_to_mm(vertices).tolist(), "triangles": triangles.tolist()}

    def _from_value(self, value: Any) -> Any:
        if not isinstance(value, dict) or set(value) - {"vertices", "triangles"}:
            raise CodecError(field="value", expected="{'vertices': [[x, y, z] mm...], "
                             "'triangles': [[i, j, k]...]}", got=repr(value)[:80])
        vertices = numeric_array(value.get("vertices", []), "value.vertices", "double", ndim=2)
        triangles = numeric_array(value.get("triangles", []), "value.triangles", "uint32",
                                  ndim=2)
        if vertices.size and vertices.shape[1] != 3:
            raise CodecError(field="value.vertices", expected="[x, y, z] rows",
                             got=f"shape {vertices.shape}")
        if triangles.size and triangles.shape[1] != 3:
            raise CodecError(field="value.triangles", expected="[i, j, k] rows",
                             got=f"shape {triangles.shape}")
        if len(triangles) > MAX_MESH_TRIANGLES:
            raise CodecError(field="value.triangles",
                             expected=f"at most {MAX_MESH_TRIANGLES} triangles",
                             got=f"{len(triangles)}")
        metres = points_in_metres(vertices, "value.vertices", MAX_MESH_VERTICES)
        if triangles.size and int(triangles.max()) >= len(metres):
            raise CodecError(field="value.triangles", expected=f"indices < {len(metres)}",
                             got=str(int(triangles.max())))
        return self._build(metres, triangles.reshape(-1, 3))


@dataclass(frozen=True)
class MarkerCodec(GenericJsonCodec):
    """visualization_msgs/Marker: from a POLYDATA, a TRIANGLE_LIST (3 points per triangle,
    metres) with ns / id / colour from the message's metadata (``ros2.ns``, default
    "slicer"; ``ros2.id``, default 0; ``ros2.color`` "r g b a", default white), scale
    1 and an identity pose. A STRING body and every other direction: the generic JSON."""

    heavy_polydata: ClassVar[bool] = True

    def _template(self, body: PolyData, metadata: dict[str, str]) -> tuple[Any, np.ndarray]:
        """The Marker without its points, and the points (metres, 3 per triangle)."""
        vertices = points_in_metres(body.points, "body.points", 3 * MAX_MARKER_TRIANGLES)
        triangles = fan_triangles(body, MAX_MARKER_TRIANGLES)
        msg = self.message_class()
        msg.type = msg.TRIANGLE_LIST
        msg.action = msg.ADD
        msg.ns = metadata.get(KEY_MARKER_NS, "slicer")
        text_id = metadata.get(KEY_MARKER_ID, "0")
        try:
            marker_id = int(text_id)
        except ValueError:
            marker_id = None
        if marker_id is None or not -(2**31) <= marker_id < 2**31:
            raise CodecError(field=f"metadata.{KEY_MARKER_ID}", expected="an int32",
                             got=repr(text_id))
        msg.id = marker_id
        msg.pose.orientation.w = 1.0
        msg.scale.x = msg.scale.y = msg.scale.z = 1.0
        r, g, b, a = _colour(metadata)
        msg.color.r, msg.color.g, msg.color.b, msg.color.a = r, g, b, a
        return msg, vertices[triangles.reshape(-1)]

    def _from_igtl(self, body: Body, metadata: dict[str, str]) -> Any:
        if not isinstance(body, PolyData):
            return super()._from_igtl(body, metadata)
        msg, points = self._template(body, metadata)
        msg.points = _ros_points(points)
        return msg

    def _from_igtl_raw(self, body: Body, metadata: dict[str, str]
                       ) -> tuple[Any, Callable[[Any], bytes]] | None:
        if not isinstance(body, PolyData):
            return None
        template, points = self._template(body, metadata)

        def finish(probe: Any) -> bytes:
            from rclpy.serialization import serialize_message  # to ROS only: the daemon's

            return splice_points(serialize_message(probe), _points_count_offset(probe), points)
        return template, finish


def _align(offset: int, size: int) -> int:
    return offset + (-(offset - 4) & (size - 1))  # alignment counts after the 4-byte header


def _string_end(offset: int, text: str) -> int:
    return _align(offset, 4) + 4 + len(text.encode("utf-8")) + 1


def _points_count_offset(marker: Any) -> int:
    """Where a serialized visualization_msgs/Marker's points count is, walking the fields
    before it: header (stamp, frame_id), ns, id, type, action, pose, scale, color,
    lifetime, frame_locked (rosidl order; checked by the tests against rclpy)."""
    offset = 4 + 8  # encapsulation, header.stamp (int32 sec, uint32 nanosec)
    offset = _string_end(offset, marker.header.frame_id)
    offset = _string_end(offset, marker.ns)
    offset = _align(offset, 4) + 12  # id, type, action
    offset = _align(offset, 8) + 56 + 24  # pose (7 float64), scale (3 float64)
    offset = _align(offset, 4) + 16 + 8 + 1  # color (4 float32), lifetime, frame_locked
    return _align(offset, 4)


def markup_labels(body: PointBody) -> list[str]:
    """The markups' labels (the POINT elements' NAME), in order."""
    return [p.name for p in body.points]


def _markup_positions(body: PointBody, limit: int) -> np.ndarray:
    if not body.points:
        raise CodecError(field="body.points", expected="at least one point", got="none")
    return points_in_metres([p.position for p in body.points], "body.points", limit)


@dataclass(frozen=True)
class PointStampedCodec(GenericJsonCodec):
    """geometry_msgs/PointStamped: a POINT body becomes one PointStamped per element (metres,
    in order; ``from_igtl`` wants exactly one). Other directions: the generic JSON."""

    def _from_igtl_all(self, body: Body, metadata: dict[str, str]) -> list[Any] | None:
        if not isinstance(body, PointBody):
            return None
        out = []
        for x, y, z in _markup_positions(body, MAX_MARKUP_POINTS).tolist():
            msg = self.message_class()
            msg.point.x, msg.point.y, msg.point.z = x, y, z
            out.append(msg)
        return out

    def _from_igtl(self, body: Body, metadata: dict[str, str]) -> Any:
        if not isinstance(body, PointBody):
            return super()._from_igtl(body, metadata)
        msgs = self._from_igtl_all(body, metadata) or []
        if len(msgs) != 1:
            raise CodecError(field="body.points", expected="one point (a list is published "
                             "as one PointStamped per point)", got=f"{len(msgs)} points")
        return msgs[0]


def pose_array_from_points(message_class: Any, body: PointBody) -> Any:
    """geometry_msgs/PoseArray from a POINT body: one pose per markup (metres, identity
    orientation: a markups point has no orientation)."""
    from geometry_msgs.msg import Pose

    msg = message_class()
    poses = []
    for x, y, z in _markup_positions(body, MAX_MARKUP_POINTS).tolist():
        pose = Pose()
        pose.position.x, pose.position.y, pose.position.z = x, y, z
        pose.orientation.w = 1.0
        poses.append(pose)
    msg.poses = poses
    return msg


@dataclass(frozen=True)
class PathCodec(GenericJsonCodec):
    """nav_msgs/Path from a line or curve drawn in Slicer: a POINT list (its control points,
    in order) or a POLYDATA holding one polyline (its points in line order, as Slicer's
    model of a curve). Poses: metres, identity orientation, each with the Path's header.
    A STRING body and every other direction: the generic JSON."""

    heavy_polydata: ClassVar[bool] = True

    def _from_igtl(self, body: Body, metadata: dict[str, str]) -> Any:
        if isinstance(body, PointBody):
            xyz = _markup_positions(body, MAX_PATH_POINTS)
        elif isinstance(body, PolyData):
            lines = cells_to_list(body.lines)
            if len(lines) != 1:
                raise CodecError(field="body.lines", expected="exactly one polyline (a curve)",
                                 got=f"{len(lines)} line(s)")
            order = np.asarray(lines[0], dtype=np.int64)
            if len(order) > MAX_PATH_POINTS:
                raise CodecError(field="body.lines", expected=f"at most {MAX_PATH_POINTS} "
                                 "points", got=str(len(order)))
            xyz = points_in_metres(np.asarray(body.points, dtype=np.float64)[order],
                                   "body.points", MAX_PATH_POINTS)
        else:
            return super()._from_igtl(body, metadata)
        from geometry_msgs.msg import PoseStamped

        msg = self.message_class()
        poses = []
        for x, y, z in xyz.tolist():
            pose = PoseStamped()
            pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = x, y, z
            pose.pose.orientation.w = 1.0
            poses.append(pose)
        msg.poses = poses
        return msg

    def _stamp(self, msg: Any, stamp: Stamp, frame_id: str) -> Any:
        msg = super()._stamp(msg, stamp, frame_id)
        for pose in msg.poses:  # a pose of a Path is in the Path's frame, at its time
            if stamp is not None:
                pose.header.stamp = msg.header.stamp
            if frame_id:
                pose.header.frame_id = frame_id
        return msg


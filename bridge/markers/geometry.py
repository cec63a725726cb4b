"""Marker geometry: a `MarkerSpec` (what one RViz marker, Path, polygon or point says, as
numpy arrays in metres) -> a `MarkerModel` (the OpenIGTLink body Slicer shows, in mm, in
the marker's frame: the marker's own pose is applied here, the frame's pose in the fixed
frame is the TRANSFORM the model goes under).

No ROS import (`bridge.markers.convert` reads rclpy messages into specs), no I/O except a
MESH_RESOURCE's file, read through the robot loader's resolver and cache.

What each type becomes (RViz's meaning of ``scale`` for each, from the Marker message's
documentation and rviz_default_plugins' marker classes):

=================  ==========================================================================
ARROW (pose)       shaft + cone along +x from the pose: length scale.x, head 23 % of it,
                   head diameter scale.y (y) and scale.z (z), shaft half of that
ARROW (2 points)   shaft from points[0] to the head ending at points[1]: shaft diameter
                   scale.x, head diameter scale.y, head length scale.z (0: 23 % of length)
CUBE/SPHERE/       a box / ellipsoid / cylinder (along z) of size scale, centred on the pose
CYLINDER
LINE_STRIP         one polyline cell through the points; scale.x (line width) in metadata
LINE_LIST          one 2-point line cell per pair (an odd last point is left out, as RViz)
CUBE_LIST/         a box / sphere of size scale at each point, joined in one mesh
SPHERE_LIST
POINTS             one polyvertex cell of all the points (`protocol.polydata.vertex_cell`);
                   scale.x, scale.y (point size) in metadata
TRIANGLE_LIST      one triangle per 3 points, points scaled by scale (as RViz does)
TEXT_VIEW_FACING   a STRING message (the text) with metadata ros2.position ("x y z" mm, the
                   pose's position) and ros2.text_height (scale.z in mm): SlicerOpenIGTLink
                   makes no node of a POINT message, so the Slicer module places a markups
                   point labelled with the text from these
MESH_RESOURCE      the file (robot mesh loader, mesh roots only), scaled, posed
Path / Polygon     a polyline through the poses' positions / a closed polyline
PointStamped       one vertex (a polyvertex cell of one point)
=================  ==========================================================================

Colours: a model always has the point colours "RGBA" (0..1, what robots send, as
`protocol.polydata.colour_attribute` lays them out):
the per-point ``colors`` when there is one per point (points, lines, lists, triangles),
else the marker's ``color`` on every point; the whole colour also goes in metadata
(``ros2.color``) for Slicer's display node. An all-zero quaternion is taken as identity
(as RViz does); NaN or infinity anywhere is refused.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from typing import Optional, Union

import math
from pathlib import Path

import numpy as np
import numpy.typing as npt

from bridge.robots.errors import RobotError
from bridge.robots.resources import PackageResolver
from protocol.conversions import fit_float32_mm, metres_to_mm, quaternion_to_rotation
from protocol.crc64 import KnownCrc
from protocol.errors import ProtocolError
from protocol.messages import PolyData, RawBody, String
from protocol.polydata import colour_attribute, vertex_cell
from protocol.naming import (KEY_LINE_WIDTH, KEY_POINT_COLORS, KEY_POINT_SIZE, KEY_POSITION,
                             KEY_TEXT_HEIGHT)

__all__ = ["ARROW_HEAD_FRACTION", "KINDS", "MAX_ARRAY_MARKERS", "MAX_MARKER_POINTS",
           "MAX_MODEL_POINTS",
           "MarkerError", "MarkerModel", "MarkerSpec", "build_model",
           "kind_of_type", "model_bytes", "packed", "warm_up"]

F64 = npt.NDArray[np.float64]
F32 = npt.NDArray[np.float32]
U32 = npt.NDArray[np.uint32]
Rgba = tuple[float, float, float, float]

# visualization_msgs/Marker type constants -> the word metadata and errors use.
KINDS: dict[int, str] = {0: "arrow", 1: "cube", 2: "sphere", 3: "cylinder", 4: "line_strip",
                         5: "line_list", 6: "cube_list", 7: "sphere_list", 8: "points",
                         9: "text_view_facing", 10: "mesh_resource", 11: "triangle_list"}
ARROW_HEAD_FRACTION = 0.23  # RViz's head length over total length when none is given
ARROW_SHAFT_OVER_HEAD = 0.5  # shaft diameter over head diameter (pose form)
# Bounds: a marker's point list, and the points of the model made of it (a SPHERE_LIST of
# 100,000 points would be 4.2 million vertices). Past them the marker is refused whole.
MAX_MARKER_POINTS = 100_000
MAX_MODEL_POINTS = 1_000_000
MAX_ARRAY_MARKERS = 20_000  # markers in one MarkerArray; a larger array is refused whole
LIST_SPHERE_SUBDIVISIONS = 1  # 42 vertices a sphere in a SPHERE_LIST
MAX_TEXT_BYTES = 4096  # of a TEXT_VIEW_FACING marker's text (a STRING holds 64 KiB)


# Kinds whose models have one colour (no per-point colours to look for).
_UNIFORM = frozenset({"arrow", "cube", "sphere", "cylinder", "text_view_facing"})


class MarkerError(ProtocolError):
    """A marker that cannot be shown: names the field, what was expected and what came."""


def kind_of_type(marker_type: int) -> str:
    kind = KINDS.get(marker_type)
    if kind is None:
        raise MarkerError("type", "a Marker type 0..11 (ARROW .. TRIANGLE_LIST)",
                          str(marker_type))
    return kind


def _zeros3() -> F64:
    return np.zeros(3)


def _identity_q() -> F64:
    return np.array([0.0, 0.0, 0.0, 1.0])


def _no_points() -> F64:
    return np.zeros((0, 3))


@dataclass(frozen=True, eq=False)
class MarkerSpec:
    """One marker as numbers: positions in METRES, colours 0..1, in the marker's frame."""

    kind: str  # a KINDS value, or "path", "polygon", "point"
    ns: str = ""
    id: int = 0
    frame: str = ""
    position: F64 = field(default_factory=_zeros3)
    orientation: F64 = field(default_factory=_identity_q)  # x, y, z, w
    scale: F64 = field(default_factory=lambda: np.ones(3))
    color: Rgba = (1.0, 1.0, 1.0, 1.0)
    points: F64 = field(default_factory=_no_points)  # (N, 3)
    colors: Optional[F64] = None  # (N, 4), used when N equals the points'
    text: str = ""
    mesh_resource: str = ""
    use_embedded_materials: bool = False
    lifetime_ns: int = 0  # 0: forever
    frame_locked: bool = False
    stamp: tuple[int, int] = (0, 0)  # header.stamp (sec, nanosec): the message's time stamp

    def digest(self) -> bytes:
        """What decides the model: equal digests give equal models (a MODIFY that changes
        nothing costs no meshing and no message)."""
        import hashlib

        h = hashlib.blake2b(digest_size=16)
        h.update(f"{self.kind}\0{self.frame}\0{self.text}\0{self.mesh_resource}\0"
                 f"{self.use_embedded_materials}\0{self.color}".encode("utf-8", "replace"))
        for array in (self.position, self.orientation, self.scale, self.points):
            h.update(np.ascontiguousarray(array, dtype=np.float64).tobytes())
        if self.colors is not None:
            h.update(np.ascontiguousarray(self.colors, dtype=np.float64).tobytes())
        return h.digest()


@dataclass(frozen=True, eq=False)
class MarkerModel:
    """What the client gets for one marker: a POLYDATA (mm, marker frame) or, for text, a
    STRING; ``metadata`` holds what the body cannot (line width, point size, position)."""

    kind: str
    body: Union[PolyData, String, RawBody]  # RawBody: a POLYDATA packed from a template
    rgba: Rgba
    metadata: dict[str, str]
    content_crc: Optional[KnownCrc] = None  # a packed body's (`packed`), for its frames

    @property
    def type_name(self) -> str:
        return self.body.type_name if isinstance(self.body, RawBody) else self.body.TYPE

    @property
    def point_count(self) -> int:
        if isinstance(self.body, PolyData):
            return int(len(self.body.points))
        if isinstance(self.body, RawBody):
            return int.from_bytes(self.body.data[:4], "big")
        return 1

    @property
    def nbytes(self) -> int:
        """What it holds: its content's bytes (packed, `packed`) or its text's."""
        if isinstance(self.body, RawBody):
            return len(self.body.data)
        if isinstance(self.body, String):
            return len(self.body.text)
        return len(self.body.pack_view())


def packed(model: MarkerModel) -> MarkerModel:
    """``model`` with its POLYDATA as its content's bytes alone (one numpy buffer): its
    arrays, several times its size while they were made, go; what is kept and sent is one
    copy, shared by every client that gets it."""
    if not isinstance(model.body, PolyData):
        return model
    content = model.body.pack_view()
    return MarkerModel(model.kind, RawBody(PolyData.TYPE, content), model.rgba,
                       model.metadata, KnownCrc(content))


# ---------------------------------------------------------------------------- checks


def _finite(array: npt.ArrayLike, name: str) -> F64:
    values = np.asarray(array, dtype=np.float64)
    # A NaN or infinity makes the sum non-finite: one reduction instead of two (a finite
    # sum that overflowed is looked at element by element).
    if not math.isfinite(float(values.sum())) and not np.all(np.isfinite(values)):
        bad = np.argwhere(~np.isfinite(values))[0]
        where = f"{name}[{bad[0]}]" if values.ndim > 1 else name
        raise MarkerError(where, "finite numbers", "NaN or infinity")
    return values


def _float32_mm(points_m: F64, dtype: str = "=f4") -> npt.NDArray[np.float32]:
    """The model's points as the float32 mm sent, or `MarkerError` where one is not finite
    as float32 (a finite pose far away: 1e36 m)."""
    fits = fit_float32_mm(points_m)
    if not fits.all():
        bad = np.argwhere(~fits)[0]
        raise MarkerError(f"points[{bad[0]}]", "coordinates within float32 once in mm (the "
                          "marker posed)", f"{np.asarray(points_m)[bad[0]].tolist()} m")
    return np.ascontiguousarray(metres_to_mm(points_m), dtype=dtype)


def _rotation(q: F64) -> F64:
    key = tuple(float(v) for v in q)
    if not all(math.isfinite(v) for v in key):
        raise MarkerError("pose.orientation", "finite numbers", "NaN or infinity")
    return _rotation_of(key)


@lru_cache(maxsize=4096)
def _rotation_of(q: tuple[float, ...]) -> F64:
    """Markers re-sent with the same orientation (most of them) share one matrix."""
    if not any(q):
        rotation = np.eye(3)  # an unset quaternion: RViz assumes identity
    else:
        rotation = quaternion_to_rotation(np.asarray(q))
    rotation.setflags(write=False)
    return rotation


def _positive_scale(scale: F64, axes: str = "xyz") -> None:
    for axis in axes:
        value = float(scale["xyz".index(axis)])
        if not value > 0:
            raise MarkerError(f"scale.{axis}", "a positive size in metres", f"{value:g}")


def _colour(color: Rgba, name: str = "color") -> Rgba:
    values = [float(v) for v in color]
    if not all(math.isfinite(v) for v in values):
        raise MarkerError(name, "finite numbers", "NaN or infinity")
    r, g, b, a = (min(1.0, max(0.0, v)) for v in values)
    return (r, g, b, a)


def _point_colours(spec: MarkerSpec, count: int) -> Optional[F32]:
    """(count, 4) per-point colours when the marker gives one per point, else None."""
    colors = spec.colors
    if colors is None or len(colors) == 0 or len(colors) != len(spec.points):
        return None
    values = _finite(colors, "colors")
    return np.clip(values, 0.0, 1.0).astype(np.float32)


# ---------------------------------------------------------------------------- meshes


@lru_cache(maxsize=None)
def _unit(kind: str) -> tuple[F64, U32]:
    """Unit primitives (size 1 m) from the robot loader's mesh module: box, sphere,
    cylinder (along z, centred), cone (base at z=0), list sphere (coarser)."""
    from bridge.robots.meshes import DEFAULT_MESH_CACHE as cache

    if kind == "cube":
        mesh = cache.primitive("box", 1.0, 1.0, 1.0)
    elif kind == "sphere":
        mesh = cache.primitive("sphere", 0.5)
    elif kind == "list_sphere":
        mesh = cache.primitive("sphere", 0.5, LIST_SPHERE_SUBDIVISIONS)
    elif kind == "cylinder":
        mesh = cache.primitive("cylinder", 0.5, 1.0)
    else:
        mesh = cache.primitive("cone", 0.5, 1.0)
    return np.asarray(mesh.vertices), np.asarray(mesh.triangles)


def warm_up() -> None:
    """Make the unit primitives now (their first use imports the mesh libraries: a second
    or two of a thread that holds the interpreter), so that it is not the first marker of
    a storm that pays it."""
    for kind in ("cube", "sphere", "list_sphere", "cylinder", "cone"):
        _unit(kind)


def _polydata(points_m: F64, *, rgba: Rgba, colours: Optional[F32] = None,
              as_points: bool = False, lines: Optional[U32] = None,
              triangles: Optional[U32] = None) -> PolyData:
    """A model of these points (metres) in mm with its colours; ``as_points``: drawn as
    points (one polyvertex cell, `protocol.polydata.vertex_cell`)."""
    n = len(points_m)
    if n > MAX_MODEL_POINTS:
        raise MarkerError("points", f"a model of at most {MAX_MODEL_POINTS} points",
                          f"{n} points")
    pts = _float32_mm(points_m).reshape(n, 3)
    if colours is None:
        colours = np.broadcast_to(np.asarray(rgba, dtype=np.float32), (n, 4))
    poly = PolyData(points=pts, attributes=[colour_attribute(colours)])
    if as_points:
        poly.vertices = vertex_cell(n)
    if lines is not None:
        poly.lines = lines
    if triangles is not None:
        poly.polygons = _cells(triangles)
    return poly


def _cells(indices: npt.ArrayLike) -> U32:
    """(M, k) indices -> the flat [k, i0..ik-1, ...] cell array."""
    idx = np.asarray(indices, dtype=np.uint32)
    if idx.size == 0:
        return np.zeros(0, dtype=np.uint32)
    counts = np.full((len(idx), 1), idx.shape[1], dtype=np.uint32)
    return np.ascontiguousarray(np.hstack([counts, idx]).ravel())


def _posed(local_m: F64, spec: MarkerSpec) -> F64:
    return np.asarray(local_m @ _rotation(spec.orientation).T
                      + _finite(spec.position, "pose.position"))


@lru_cache(maxsize=1024)
def _scaled_unit(kind: str, scale: tuple[float, float, float]) -> tuple[F64, U32]:
    """A primitive at its size (metres) and its polygon cells, shared by every marker of
    that kind and size (read-only)."""
    v, t = _unit(kind)
    vertices = v * np.asarray(scale)
    cells = _cells(t)
    vertices.setflags(write=False)
    cells.setflags(write=False)
    return vertices, cells


@lru_cache(maxsize=1024)
def _uniform_colour(rgba: Rgba, n: int) -> F32:
    colours = np.empty((n, 4), dtype=np.float32)
    colours[:] = rgba
    colours.setflags(write=False)
    return colours


def _z_to(direction: F64) -> F64:
    """A rotation taking +z onto the unit vector ``direction``."""
    z = np.array([0.0, 0.0, 1.0])
    v = np.cross(z, direction)
    c = float(np.dot(z, direction))
    if np.linalg.norm(v) < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.asarray(np.eye(3) + vx + vx @ vx * (1.0 / (1.0 + c)))


def _arrow_along_z(shaft_length: float, shaft_d: tuple[float, float], head_length: float,
                   head_d: tuple[float, float]) -> tuple[F64, U32]:
    """An arrow from z=0 to z=shaft+head: (vertices m, triangles)."""
    parts_v: list[F64] = []
    parts_t: list[U32] = []
    offset = 0
    if shaft_length > 0:
        v, t = _unit("cylinder")
        parts_v.append(v * [shaft_d[0], shaft_d[1], shaft_length] + [0, 0, shaft_length / 2])
        parts_t.append(t + offset)
        offset += len(v)
    v, t = _unit("cone")
    parts_v.append(v * [head_d[0], head_d[1], head_length] + [0, 0, shaft_length])
    parts_t.append(t + offset)
    return np.concatenate(parts_v), np.concatenate(parts_t).astype(np.uint32)


def _arrow(spec: MarkerSpec, rgba: Rgba) -> PolyData:
    scale = _finite(spec.scale, "scale")
    if len(spec.points) >= 2:
        p0, p1 = spec.points[0], spec.points[1]
        direction = p1 - p0
        length = float(np.linalg.norm(direction))
        if not length > 0:
            raise MarkerError("points", "an arrow's two points at different places",
                              "points[0] == points[1]")
        _positive_scale(scale, "xy")
        head = float(scale[2]) if scale[2] > 0 else ARROW_HEAD_FRACTION * length
        head = min(head, length)
        v, t = _arrow_along_z(length - head, (scale[0], scale[0]), head, (scale[1], scale[1]))
        local = v @ _z_to(direction / length).T + p0
    else:
        _positive_scale(scale)
        length = float(scale[0])
        head = ARROW_HEAD_FRACTION * length
        # Built along z with its x extent = height (scale.z), y = width (scale.y), then
        # turned so z -> +x (x -> -z): a rotation of +90 degrees about y.
        head_d = (float(scale[2]), float(scale[1]))
        shaft_d = (head_d[0] * ARROW_SHAFT_OVER_HEAD, head_d[1] * ARROW_SHAFT_OVER_HEAD)
        v, t = _arrow_along_z(length - head, shaft_d, head, head_d)
        turn = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
        local = v @ turn.T
    return _polydata(_posed(local, spec), rgba=rgba, triangles=t)


@lru_cache(maxsize=1024)
def _shape_template(kind: str, scale: tuple[float, float, float], rgba: Rgba
                    ) -> tuple[bytes, bytes, F64]:
    """The POLYDATA content of a primitive of this size and colour split around its
    points: (bytes before, bytes after, the vertices in metres). A cube's content is then
    two joins and one conversion of its 8 points, not a full pack (a 1000-cube array:
    ~15 ms less on the loop)."""
    v, cells = _scaled_unit(kind, scale)
    body = PolyData(points=np.zeros((len(v), 3), dtype=np.float32), polygons=cells,
                    attributes=[colour_attribute(_uniform_colour(rgba, len(v)))])
    content = body.pack()
    head = _POLY_HEAD_BYTES
    return content[:head], content[head + 12 * len(v):], v


_POLY_HEAD_BYTES = 40  # NPOINTS and the cell/attribute counts, ten u32 (polydata.md)


def _shape(spec: MarkerSpec, rgba: Rgba) -> RawBody:
    scale = _finite(spec.scale, "scale")
    _positive_scale(scale)
    head, tail, v = _shape_template(spec.kind, (float(scale[0]), float(scale[1]),
                                                float(scale[2])), rgba)
    # The hot path of a large MarkerArray: one matrix product, the rest is a template.
    rotation = _rotation(spec.orientation)
    position = _finite(spec.position, "pose.position")
    points = _float32_mm(v @ rotation.T + position, ">f4")
    return RawBody(PolyData.TYPE, head + points.tobytes() + tail)


def _shape_list(spec: MarkerSpec, rgba: Rgba) -> PolyData:
    scale = _finite(spec.scale, "scale")
    _positive_scale(scale)
    v, t = _unit("cube" if spec.kind == "cube_list" else "list_sphere")
    centres = spec.points
    n = len(centres)
    if n * len(v) > MAX_MODEL_POINTS:
        raise MarkerError("points", f"at most {MAX_MODEL_POINTS // len(v)} points in a "
                          f"{spec.kind.upper()} (a model of {MAX_MODEL_POINTS} points)",
                          f"{n} points")
    local = (v * scale)[None, :, :] + centres[:, None, :]
    triangles = (t[None, :, :] + (np.arange(n, dtype=np.uint32) * len(v))[:, None, None])
    per_point = _point_colours(spec, n)
    colours = None if per_point is None else np.repeat(per_point, len(v), axis=0)
    return _polydata(_posed(local.reshape(-1, 3), spec), rgba=rgba, colours=colours,
                     triangles=triangles.reshape(-1, 3))


def _line_strip(points: F64, closed: bool = False) -> U32:
    n = len(points)
    if n < 2:
        return np.zeros(0, dtype=np.uint32)
    order = list(range(n)) + ([0] if closed and n > 2 else [])
    return np.asarray([len(order), *order], dtype=np.uint32)


def _lines(spec: MarkerSpec, rgba: Rgba) -> PolyData:
    pts = spec.points
    if spec.kind == "line_list":
        pairs = len(pts) // 2
        cells = _cells(np.arange(pairs * 2, dtype=np.uint32).reshape(pairs, 2))
    else:
        cells = _line_strip(pts, closed=spec.kind == "polygon")
    return _polydata(_posed(pts, spec), rgba=rgba, colours=_point_colours(spec, len(pts)),
                     lines=cells)


def _points(spec: MarkerSpec, rgba: Rgba) -> PolyData:
    pts = spec.points
    return _polydata(_posed(pts, spec), rgba=rgba, colours=_point_colours(spec, len(pts)),
                     as_points=True)


def _triangles(spec: MarkerSpec, rgba: Rgba) -> PolyData:
    pts = spec.points
    if len(pts) % 3:
        raise MarkerError("points", "a multiple of 3 points (one triangle per 3)",
                          f"{len(pts)} points")
    scale = _finite(spec.scale, "scale")
    _positive_scale(scale)
    triangles = np.arange(len(pts), dtype=np.uint32).reshape(-1, 3)
    return _polydata(_posed(pts * scale, spec), rgba=rgba,
                     colours=_point_colours(spec, len(pts)), triangles=triangles)


def _text(spec: MarkerSpec, metadata: dict[str, str]) -> String:
    position = metres_to_mm(_finite(spec.position, "pose.position"))
    height = float(_finite(spec.scale, "scale")[2])
    metadata[KEY_POSITION] = " ".join(f"{float(v):.6g}" for v in position)
    metadata[KEY_TEXT_HEIGHT] = f"{float(metres_to_mm(max(height, 0.0))):.6g}"
    text = spec.text.encode("utf-8", "replace")[:MAX_TEXT_BYTES].decode("utf-8", "ignore")
    return String(text)


def _mesh(spec: MarkerSpec, rgba: Rgba, mesh_roots: Optional[tuple[object, ...]],
          package_paths: Optional[dict[str, object]]) -> tuple[PolyData, Rgba]:
    from bridge.robots.meshes import DEFAULT_MESH_CACHE  # trimesh: loaded with the first mesh

    scale = _finite(spec.scale, "scale")
    _positive_scale(scale)
    resolver = PackageResolver({k: Path(str(v)) for k, v in (package_paths or {}).items()},
                               allowed_roots=None if mesh_roots is None else
                               tuple(Path(str(r)) for r in mesh_roots))
    uri = spec.mesh_resource
    try:
        path = resolver.resolve(uri)
    except RobotError as exc:  # the robots' wording: a refused file reads as a missing one
        raise MarkerError("mesh_resource", exc.expected, exc.got) from None
    try:
        mesh = DEFAULT_MESH_CACHE.mesh_file(path, tuple(float(s) for s in scale))
    except RobotError as exc:
        raise MarkerError("mesh_resource", exc.expected, f"{uri!r}: {exc.got}") from None
    colours: Optional[F32] = None
    if spec.use_embedded_materials and mesh.vertex_rgba is not None:
        colours = mesh.vertex_rgba.astype(np.float32) / np.float32(255.0)
    elif spec.use_embedded_materials and mesh.rgba is not None:
        rgba = mesh.rgba
    body = _polydata(_posed(np.asarray(mesh.vertices), spec), rgba=rgba, colours=colours,
                     triangles=np.asarray(mesh.triangles))
    return body, rgba


# POLYDATA bytes of a model: a point (3 + 4 float32: position, RGBA) and a triangle cell.
_POINT_BYTES = 28
_TRIANGLE_BYTES = 16


def model_bytes(spec: MarkerSpec) -> int:
    """The size of the model `build_model` would make of ``spec`` (its POLYDATA content,
    to within a few hundred bytes), known before any of it is made: a memory budget is
    judged on it first. A MESH_RESOURCE's size is known only once its file is read: 0."""
    kind, n = spec.kind, len(spec.points)
    if kind in ("cube_list", "sphere_list"):
        v, t = _unit("cube" if kind == "cube_list" else "list_sphere")
        return 64 + n * (len(v) * _POINT_BYTES + len(t) * _TRIANGLE_BYTES)
    if kind in ("points", "point"):
        return 64 + n * (_POINT_BYTES + 8)
    if kind in ("line_strip", "line_list", "path", "polygon"):
        return 64 + n * (_POINT_BYTES + 4) + 8
    if kind == "triangle_list":
        return 64 + n * _POINT_BYTES + (n // 3) * _TRIANGLE_BYTES
    if kind == "text_view_facing":
        return 64 + min(len(spec.text), MAX_TEXT_BYTES)
    if kind in ("cube", "sphere", "cylinder", "arrow"):
        v, t = _unit("sphere" if kind in ("sphere", "arrow") else kind)
        return 64 + len(v) * _POINT_BYTES + len(t) * _TRIANGLE_BYTES
    return 0


def build_model(spec: MarkerSpec, *, mesh_roots: Optional[tuple[object, ...]] = (),
                package_paths: Optional[dict[str, object]] = None) -> MarkerModel:
    """The model of one marker; `MarkerError` says why a marker cannot be shown.
    ``mesh_roots``: folders a MESH_RESOURCE may be read from (None: anywhere)."""
    if len(spec.points) > MAX_MARKER_POINTS:
        raise MarkerError("points", f"at most {MAX_MARKER_POINTS} points",
                          f"{len(spec.points)} points")
    _finite(spec.points, "points")
    rgba = _colour(spec.color)
    kind = spec.kind
    metadata: dict[str, str] = {}
    scale = _finite(spec.scale, "scale")
    body: Union[PolyData, String, RawBody]
    if kind == "arrow":
        body = _arrow(spec, rgba)
    elif kind in ("cube", "sphere", "cylinder"):
        body = _shape(spec, rgba)
    elif kind in ("line_strip", "line_list", "path", "polygon"):
        body = _lines(spec, rgba)
        if kind.startswith("line"):
            metadata[KEY_LINE_WIDTH] = f"{float(metres_to_mm(scale[0])):.6g}"
    elif kind in ("cube_list", "sphere_list"):
        body = _shape_list(spec, rgba)
    elif kind in ("points", "point"):
        body = _points(spec, rgba)
        if kind == "points":
            size = metres_to_mm(scale[:2])
            metadata[KEY_POINT_SIZE] = f"{float(size[0]):.6g} {float(size[1]):.6g}"
    elif kind == "triangle_list":
        body = _triangles(spec, rgba)
    elif kind == "text_view_facing":
        body = _text(spec, metadata)
    elif kind == "mesh_resource":
        body, rgba = _mesh(spec, rgba, mesh_roots, package_paths)
    else:
        raise MarkerError("type", "a marker type this bridge shows", repr(kind))
    if isinstance(body, PolyData) and len(body.points) and kind not in _UNIFORM:
        colours = np.asarray(body.attributes[0].data)
        if np.any(colours != colours[0]):
            metadata[KEY_POINT_COLORS] = "1"
    return MarkerModel(kind, body, rgba, metadata)

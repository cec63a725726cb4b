"""Triangle meshes for robot visuals: files (STL, OBJ, DAE, ... via trimesh), URDF
primitives, a cache, decimation and normals.

Everything here is in METRES and in the mesh's own frame: the visual origin and the
conversion to millimetres happen in `bridge.robots.model`. A `MeshData` is immutable (its
arrays are read-only) so one cached copy can be shared by every robot that uses the file.

Vertices are merged when their position (and colour, if the file gives per-vertex colours)
are bit-for-bit equal, never within a tolerance: the counts are then those of the file
(an STL of F triangles gives exactly its distinct corner positions), and two robots
loading the same file get identical arrays.
"""

from __future__ import annotations

import hashlib
import importlib
import json
import logging
import os
import tempfile
import threading
from collections import OrderedDict
from concurrent.futures import Future
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional, Protocol, Sequence

import numpy as np
import numpy.typing as npt
import trimesh
import trimesh.units

from bridge.robots.cache_folder import user_cache_dir
from bridge.robots.errors import MeshError
from bridge.robots.mesh_extras import take_back

__all__ = [
    "MeshData",
    "MeshCache",
    "MeshReader",
    "DEFAULT_MESH_CACHE",
    "MESH_FOLDER_ENTRIES",
    "MESH_SUFFIXES",
    "default_mesh_folder",
    "load_mesh_file",
    "box_mesh",
    "cylinder_mesh",
    "sphere_mesh",
    "cone_mesh",
    "decimate",
    "vertex_normals",
]

_log = logging.getLogger("bridge.robots.meshes")

F64 = npt.NDArray[np.float64]
U32 = npt.NDArray[np.uint32]
U8 = npt.NDArray[np.uint8]

# What trimesh reads with the project's dependencies (pycollada gives DAE).
MESH_SUFFIXES = (".stl", ".obj", ".dae", ".ply", ".off", ".glb", ".gltf", ".3mf")

# Primitive tessellation: enough facets to look round in Slicer, few enough to stay small.
CYLINDER_SECTIONS = 48
SPHERE_SUBDIVISIONS = 3  # icosphere: 642 vertices, 1280 triangles
# Parts of a multi-geometry file that have no colour when others do (= model.DEFAULT_RGBA).
DEFAULT_GREY_U8 = (179, 179, 179, 255)


@dataclass(frozen=True)
class MeshData:
    """A triangle mesh in metres, in its own frame, with the colours its file gave.

    ``rgba`` is the file's single colour (0..1) if it has exactly one, ``vertex_rgba`` the
    per-vertex colours (uint8) if they vary; both None when the file says nothing (STL).
    """

    vertices: F64  # (N, 3) float64, metres, scale applied
    triangles: U32  # (M, 3) uint32
    rgba: Optional[tuple[float, float, float, float]]
    vertex_rgba: Optional[U8]  # (N, 4) uint8 or None
    description: str  # "stl, 2848 triangles" ...
    original_triangles: int  # before decimation

    @property
    def triangle_count(self) -> int:
        return int(self.triangles.shape[0])

    def __setstate__(self, state: dict[str, Any]) -> None:
        # A mesh read in a reader process comes by pickle, its arrays writeable again:
        # read-only as every MeshData's (one cached copy is shared by every robot).
        for value in state.values():
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
        self.__dict__.update(state)


def _frozen(array: np.ndarray) -> Any:
    array.setflags(write=False)
    return array


# ---------------------------------------------------------------------------- merging


# Odd 64-bit multipliers (splitmix/xxhash constants) mixing a vertex's bytes into one key.
_MIX = np.array([0x9E3779B97F4A7C15, 0xC2B2AE3D27D4EB4F, 0x165667B19E3779F9,
                 0x27D4EB2F165667C5], dtype=np.uint64)


def _merge_exact(vertices: F64, triangles: U32, colours: Optional[U8]
                 ) -> tuple[F64, U32, Optional[U8]]:
    """Merge vertices whose position (and colour) bytes are equal; drop unused ones. The
    vertices keep the order in which the triangles first use them.

    Each vertex's bytes are mixed into one 64-bit key, and the keys sorted (np.unique on
    uint64: a quarter of the time of sorting the rows as bytes); the merged vertices are
    then checked byte for byte against every vertex merged into them, and on a collision
    of two different vertices (about 1 in 2**64 per pair) the rows are sorted as they are.
    """
    if len(vertices) == 0:
        return vertices, triangles, colours
    pos = np.ascontiguousarray(vertices, dtype=np.float64)
    used = np.zeros(len(pos), dtype=bool)
    used[triangles.ravel()] = True
    used_idx = np.flatnonzero(used)
    columns = [pos[used_idx].view(np.uint64)]
    if colours is not None:
        columns.append(np.ascontiguousarray(colours[used_idx], dtype=np.uint8)
                       .view(np.uint32).astype(np.uint64))
    rows = np.concatenate(columns, axis=1) if len(columns) > 1 else columns[0]
    with np.errstate(over="ignore"):
        key = rows[:, 0] * _MIX[0]
        for k in range(1, rows.shape[1]):
            key ^= rows[:, k] * _MIX[k]
    _, first, inverse = np.unique(key, return_index=True, return_inverse=True)
    inverse = inverse.ravel()
    if not np.array_equal(rows[first][inverse], rows):  # a collision: sort the rows
        keys = np.ascontiguousarray(rows).view(np.dtype((np.void, rows.shape[1] * 8))).ravel()
        _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
        inverse = inverse.ravel()
    order = np.argsort(first, kind="stable")  # merged vertices in order of first use
    rank = np.empty(len(first), dtype=np.int64)
    rank[order] = np.arange(len(first))
    remap = np.zeros(len(pos), dtype=np.int64)
    remap[used_idx] = rank[inverse]
    keep = used_idx[first[order]]
    new_colours = colours[keep] if colours is not None else None
    return pos[keep], remap[triangles].astype(np.uint32), new_colours


# ---------------------------------------------------------------------------- colours


def _visual_colours(geom: trimesh.Trimesh) -> Optional[U8]:
    """(N, 4) uint8 colours of a trimesh geometry, or None when its file gives none."""
    # Dispatched on `kind` as the file gave it, not on trimesh's visual classes.
    visual: Any = geom.visual
    kind = getattr(visual, "kind", None)
    if kind is None:
        return None
    try:
        if kind == "texture":
            # None: `material.main_color` below fails like any broken material (caught).
            material: Any = getattr(visual, "material", None)
            image = getattr(material, "image", None) or getattr(material, "baseColorTexture",
                                                                 None)
            uv = getattr(visual, "uv", None)
            if image is not None and uv is not None and len(uv) == len(geom.vertices):
                colours = visual.to_color().vertex_colors  # samples the texture per vertex
            else:
                main = np.asarray(material.main_color, dtype=np.uint8).reshape(4)
                colours = np.broadcast_to(main, (len(geom.vertices), 4))
        elif kind == "face":
            faces = np.asarray(visual.face_colors, dtype=np.uint8)
            if len(faces) and np.all(faces == faces[0]):
                colours = np.broadcast_to(faces[0], (len(geom.vertices), 4))
            else:
                colours = _face_to_vertex_colours(np.asarray(geom.faces, dtype=np.int64),
                                                  faces, len(geom.vertices))
        else:
            colours = visual.vertex_colors
    except Exception as exc:  # a broken material must not lose the geometry
        _log.debug("ignoring the colours of a geometry: %s", exc)
        return None
    colours = np.asarray(colours, dtype=np.uint8)
    if colours.shape != (len(geom.vertices), 4):
        return None
    return np.ascontiguousarray(colours)


def _face_to_vertex_colours(faces: npt.NDArray[np.int64], face_colours: U8,
                            vertex_count: int) -> U8:
    """Each vertex the mean of the colours of the faces that use it, truncated to uint8
    (trimesh's `face_to_vertex_color`, whose scipy.sparse a daemon leaves out:
    `bridge.robots.mesh_extras`). Sums of uint8 values are exact in float64, so the result
    is trimesh's to the bit."""
    corners = faces.ravel()
    per_corner = np.repeat(face_colours.astype(np.float64), faces.shape[1], axis=0)
    sums: F64 = np.stack([np.bincount(corners, per_corner[:, k], minlength=vertex_count)
                          for k in range(4)], axis=1).astype(np.float64)
    degree = np.bincount(corners, minlength=vertex_count).astype(np.float64)
    used = degree > 0
    sums[used] /= degree[used, None]
    return sums.astype(np.uint8)


def _split_colours(colours: Optional[U8]
                   ) -> tuple[Optional[tuple[float, float, float, float]], Optional[U8]]:
    """One colour if all are equal (rgba 0..1), else the per-vertex array."""
    if colours is None or len(colours) == 0:
        return None, None
    if np.all(colours == colours[0]):
        c = colours[0].astype(np.float64) / 255.0
        return (float(c[0]), float(c[1]), float(c[2]), float(c[3])), None
    return None, colours


# ---------------------------------------------------------------------------- units

def _unit_scale(units: Optional[str]) -> float:
    """Metres per file unit from trimesh's units string (COLLADA ``<unit meter="0.01">``
    gives ``"0.01 * meters"``), else 1: STL and OBJ carry no unit and are taken as metres.

    COLLADA files often say centimetres or inches; RViz (assimp) honours that, so do we.
    """
    if not isinstance(units, str) or not units.strip():
        return 1.0
    try:
        value = float(trimesh.units.unit_conversion(units, "meters"))
    except Exception:  # an unknown unit name: keep the numbers as they are
        _log.debug("unknown mesh units %r, taken as metres", units)
        return 1.0
    return value if np.isfinite(value) and value > 0 else 1.0


# ---------------------------------------------------------------------------- files


def _read_geometries(path: Path) -> tuple[list[tuple[trimesh.Trimesh, F64]], float]:
    """The file's triangle meshes, each with the transform its scene node places it by,
    and the file's unit in metres."""
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise MeshError(str(path), "a mesh file (" + ", ".join(MESH_SUFFIXES) + ")",
                        f"suffix {suffix or '(none)'}")
    if suffix == ".3mf":
        _take_back_3mf_reader()
    try:
        # process=False: keep the file's vertices; merging is ours (exact, see module doc).
        loaded = _load_collada(path) if suffix == ".dae" else \
            trimesh.load(str(path), process=False, force="scene")
    except MeshError:
        raise
    except Exception as exc:  # trimesh raises many types for a corrupt file
        raise MeshError(str(path), f"a readable {suffix[1:].upper()} mesh",
                        f"{type(exc).__name__}: {exc}") from None
    scale = _unit_scale(getattr(loaded, "units", None))
    placed: list[tuple[Any, F64]] = [(loaded, np.eye(4))]
    if isinstance(loaded, trimesh.Scene):
        # Not `Scene.dump`: it copies every geometry, and the copy of a face-coloured one
        # averages its colours per vertex with scipy (left out in a daemon:
        # `bridge.robots.mesh_extras`), to throw them away.
        try:
            placed = []
            for node in loaded.graph.nodes_geometry:
                transform, name = loaded.graph[node]
                placed.append((loaded.geometry.get(name),
                               np.asarray(transform, dtype=np.float64)))
        except Exception as exc:
            raise MeshError(str(path), "a mesh scene", f"{type(exc).__name__}: {exc}") from None
    meshes = [(g, t) for g, t in placed if isinstance(g, trimesh.Trimesh) and len(g.faces) > 0]
    return meshes, scale


_IDENTITY = np.eye(4)


def _placed(geom: trimesh.Trimesh, transform: F64) -> tuple[F64, npt.NDArray[np.int64]]:
    """A scene geometry's vertices where its node puts them, and its faces (their winding
    flipped by a mirroring transform), as trimesh's `apply_transform` makes them."""
    vertices = np.asarray(geom.vertices, dtype=np.float64)
    faces = np.asarray(geom.faces, dtype=np.int64)
    if trimesh.util.allclose(transform, _IDENTITY, 1e-8):
        return vertices, faces
    vertices = trimesh.transformations.transform_points(vertices, transform)
    if not trimesh.util.allclose(transform[:3, :3], _IDENTITY[:3, :3], 1e-6) and \
            trimesh.transformations.flips_winding(transform):  # type: ignore[no-untyped-call]
        faces = np.ascontiguousarray(np.fliplr(faces))
    return vertices, faces



def _load_collada(path: Path) -> Any:
    """A COLLADA file as a trimesh scene with its vertices as the file has them.
    `trimesh.load` does not hand ``process=False`` on to a COLLADA scene's geometries: each
    was merged within trimesh's tolerance (a third of the file's reading time), then again
    exactly here."""
    from trimesh.exchange.dae import load_collada
    from trimesh.resolvers import FilePathResolver

    with path.open("rb") as file:
        kwargs = load_collada(file, resolver=FilePathResolver(str(path)))  # type: ignore[no-untyped-call]
    for geometry in kwargs.get("geometry", {}).values():
        if isinstance(geometry, dict):
            geometry["process"] = False
    return trimesh.load(kwargs, force="scene")


_READER_LOCK = threading.Lock()


def _take_back_3mf_reader() -> None:
    """trimesh's 3MF reader needs networkx (its build graph), which trimesh looks for only
    as it starts and a daemon leaves out then (`bridge.robots.mesh_extras`: 0.06-0.1 s of
    its first robot): the first 3MF file takes it back and registers the reader again."""
    from trimesh.exchange import load as exchange, threemf

    with _READER_LOCK:
        if hasattr(threemf, "nx"):
            return
        take_back("networkx")
        importlib.reload(threemf)  # its optional imports, tried again
        exchange.mesh_loaders.update(threemf._three_loaders)


def _explain_empty_collada(path: Path) -> None:
    """A COLLADA scene with no triangles may still hold them: its nodes were dropped for a
    broken reference (a material binding to a missing id, typically). Say so, not "empty"."""
    import collada

    try:
        document = collada.Collada(str(path), ignore=[collada.common.DaeError])
        triangles = sum(len(primitive.triangleset()) if hasattr(primitive, "triangleset")
                        else len(primitive)
                        for geometry in document.geometries
                        for primitive in geometry.primitives)
    except Exception:  # unreadable even leniently: the plain message stands
        return
    if triangles:
        causes = "; ".join(dict.fromkeys(str(error) for error in document.errors)) or \
            "no <node> instantiates its geometry"
        raise MeshError(str(path), "a COLLADA scene that places its triangles",
                        f"{triangles} triangles in <library_geometries> that the scene drops "
                        f"({causes})")


def load_mesh_file(path: Path, scale: Sequence[float] = (1.0, 1.0, 1.0), *,
                   max_triangles: Optional[int] = None) -> MeshData:
    """Read a mesh file into a `MeshData` (metres, ``scale`` applied per axis).

    Raises `MeshError` when the file is not a mesh trimesh can read, or holds no triangles.
    Several geometries (a DAE scene) are placed by their node transforms and joined.
    """
    geoms, unit = _read_geometries(path)
    if not geoms:
        if path.suffix.lower() == ".dae":
            _explain_empty_collada(path)
        raise MeshError(str(path), "at least one triangle", "no triangles in the file")
    verts: list[F64] = []
    tris: list[U32] = []
    colour_parts: list[Optional[U8]] = []
    offset = 0
    for g, transform in geoms:
        v, f = _placed(g, transform)
        if f.ndim != 2 or f.shape[1] != 3 or (len(f) and (f.min() < 0 or f.max() >= len(v))):
            raise MeshError(str(path), "triangles indexing the vertices",
                            f"faces of shape {f.shape}")
        verts.append(v)
        tris.append((f + offset).astype(np.uint32))
        colour_parts.append(_visual_colours(g))
        offset += len(v)
    vertices = np.concatenate(verts)
    triangles = np.concatenate(tris)
    colours: Optional[U8] = None
    if any(c is not None for c in colour_parts):
        grey = np.array(DEFAULT_GREY_U8, dtype=np.uint8)
        colours = np.concatenate([
            c if c is not None else np.broadcast_to(grey, (len(v), 4))
            for c, v in zip(colour_parts, verts)])
    if not np.all(np.isfinite(vertices)):
        raise MeshError(str(path), "finite vertex coordinates", "NaN or infinity")
    vertices, triangles, colours = _merge_exact(vertices, triangles, colours)
    factor = np.asarray(scale, dtype=np.float64) * unit
    vertices = vertices * factor
    if np.linalg.det(np.diag(factor)) < 0:
        triangles = triangles[:, ::-1].copy()  # a mirroring scale flips the winding
    original = len(triangles)
    if max_triangles is not None and original > max_triangles:
        vertices, triangles, colours = decimate(vertices, triangles, max_triangles, colours)
    rgba, vertex_rgba = _split_colours(colours)
    desc = f"{path.suffix[1:].lower()} {path.name}, {original} triangles"
    if len(triangles) != original:
        desc += f" decimated to {len(triangles)}"
    return MeshData(_frozen(np.ascontiguousarray(vertices)),
                    _frozen(np.ascontiguousarray(triangles, dtype=np.uint32)), rgba,
                    None if vertex_rgba is None else _frozen(vertex_rgba), desc, original)


# ---------------------------------------------------------------------------- primitives


def _from_trimesh(mesh: trimesh.Trimesh, description: str) -> MeshData:
    v = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
    t = np.ascontiguousarray(mesh.faces, dtype=np.uint32)
    return MeshData(_frozen(v), _frozen(t), None, None, description, len(t))


def _positive(value: float, what: str) -> float:
    if not np.isfinite(value) or value <= 0:
        raise MeshError(what, "a positive finite number (metres)", value)
    return float(value)


def box_mesh(size: Sequence[float]) -> MeshData:
    """A box of extents ``size`` (x, y, z metres) centred on the origin (URDF <box>)."""
    sx, sy, sz = (_positive(float(s), "box size") for s in size)
    return _from_trimesh(trimesh.creation.box(extents=(sx, sy, sz)),
                         f"box {sx:g} x {sy:g} x {sz:g} m")


def cylinder_mesh(radius: float, length: float) -> MeshData:
    """A cylinder along z, centred on the origin (URDF <cylinder>)."""
    r = _positive(radius, "cylinder radius")
    h = _positive(length, "cylinder length")
    return _from_trimesh(trimesh.creation.cylinder(radius=r, height=h,
                                                   sections=CYLINDER_SECTIONS),
                         f"cylinder r {r:g} m, length {h:g} m")


def sphere_mesh(radius: float, subdivisions: int = SPHERE_SUBDIVISIONS) -> MeshData:
    """A sphere centred on the origin (URDF <sphere>); fewer ``subdivisions`` for the
    thousands of spheres of a marker SPHERE_LIST (1: 42 vertices, 80 triangles)."""
    r = _positive(radius, "sphere radius")
    return _from_trimesh(trimesh.creation.icosphere(subdivisions=subdivisions, radius=r),
                         f"sphere r {r:g} m")


def cone_mesh(radius: float, length: float) -> MeshData:
    """A cone along z, base at z=0, apex at z=``length`` (an arrow's head)."""
    r = _positive(radius, "cone radius")
    h = _positive(length, "cone length")
    return _from_trimesh(trimesh.creation.cone(radius=r, height=h, sections=CYLINDER_SECTIONS),
                         f"cone r {r:g} m, length {h:g} m")


# ---------------------------------------------------------------------------- decimation


def _cluster(vertices: F64, triangles: U32, cells: int
             ) -> tuple[npt.NDArray[np.int64], U32]:
    """Vertex clustering on a grid of ``cells`` along the longest side.

    Returns the cluster of every vertex (0..K-1) and the surviving triangles in cluster ids.
    """
    low = vertices.min(axis=0)
    extent = float(np.max(vertices.max(axis=0) - low)) or 1.0
    size = extent / cells
    grid = np.floor((vertices - low) / size).astype(np.int64)
    grid = np.minimum(grid, cells)  # the far face lands in the last cell
    key = (grid[:, 0] * (cells + 1) + grid[:, 1]) * (cells + 1) + grid[:, 2]
    _, cluster = np.unique(key, return_inverse=True)
    cluster = cluster.ravel()
    t = cluster[triangles]
    ok = (t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 0] != t[:, 2])
    t = t[ok]
    # The same cluster triple can come from several triangles: keep one of each winding.
    canonical = _rotate_min_first(t)
    _, first = np.unique(canonical, axis=0, return_index=True)
    return cluster, t[np.sort(first)].astype(np.uint32)


def _rotate_min_first(t: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
    """Rotate each triangle so its smallest index comes first (winding kept)."""
    shift = np.argmin(t, axis=1)
    idx = (shift[:, None] + np.arange(3)[None, :]) % 3
    return np.take_along_axis(t, idx, axis=1)


def decimate(vertices: F64, triangles: U32, max_triangles: int,
             colours: Optional[U8] = None) -> tuple[F64, U32, Optional[U8]]:
    """Reduce a mesh to at most ``max_triangles`` by vertex clustering (numpy only).

    trimesh's quadric decimation needs the optional ``fast_simplification`` package, which
    the project does not depend on; clustering is cruder (it can close small holes and
    thin walls) but is vectorised, deterministic and good enough to show a huge CAD mesh.
    The finest grid that meets the budget is found by bisection (~12 passes).
    """
    if max_triangles < 4:
        raise MeshError("max_triangles", "at least 4", max_triangles)
    if len(triangles) <= max_triangles:
        return vertices, triangles, colours
    lo, hi = 1, 2
    best: Optional[tuple[npt.NDArray[np.int64], U32]] = None
    # Grow the grid until it is too fine, then bisect between the last fitting and it.
    while True:
        cluster, tris = _cluster(vertices, triangles, hi)
        if len(tris) > max_triangles or hi >= 1 << 16:
            break
        lo, best = hi, (cluster, tris)
        hi *= 2
    while hi - lo > 1:
        mid = (lo + hi) // 2
        cluster, tris = _cluster(vertices, triangles, mid)
        if len(tris) <= max_triangles:
            lo, best = mid, (cluster, tris)
        else:
            hi = mid
    if best is None:
        coarse = _cluster(vertices, triangles, 1)
        if not 0 < len(coarse[1]) <= max_triangles:
            # Even the coarsest grid misses the budget, or leaves nothing of the mesh: a
            # mesh over budget or a silently empty visual would both be wrong.
            needed = min(n for n in (len(coarse[1]), len(tris)) if n > 0)
            raise MeshError("max_triangles", f"at least {needed} for this mesh of "
                            f"{len(triangles)} triangles", max_triangles)
        best = coarse
    cluster, tris = best
    count = int(cluster.max()) + 1
    weights = np.bincount(cluster, minlength=count).astype(np.float64)
    new_vertices = np.stack([np.bincount(cluster, vertices[:, k], minlength=count)
                             for k in range(3)], axis=1) / weights[:, None]
    new_colours: Optional[U8] = None
    if colours is not None:
        sums = np.stack([np.bincount(cluster, colours[:, k].astype(np.float64),
                                     minlength=count) for k in range(4)], axis=1)
        new_colours = np.clip(np.rint(sums / weights[:, None]), 0, 255).astype(np.uint8)
    # Drop clusters no surviving triangle uses.
    used = np.zeros(count, dtype=bool)
    used[tris.ravel()] = True
    remap = np.cumsum(used) - 1
    new_vertices = new_vertices[used]
    if new_colours is not None:
        new_colours = new_colours[used]
    return new_vertices, remap[tris].astype(np.uint32), new_colours


# ---------------------------------------------------------------------------- normals


def vertex_normals(vertices: npt.ArrayLike, triangles: npt.ArrayLike
                   ) -> npt.NDArray[np.float32]:
    """Area-weighted unit vertex normals (float32), vectorised; (0, 0, 0) for a vertex of
    degenerate triangles only."""
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    face = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])  # length = 2 * area
    idx = t.ravel()
    rep = np.repeat(face, 3, axis=0)
    acc = np.stack([np.bincount(idx, rep[:, k], minlength=len(v)) for k in range(3)], axis=1)
    norm = np.linalg.norm(acc, axis=1, keepdims=True)
    out: F64 = np.divide(acc, norm, out=np.zeros_like(acc), where=norm > 0)
    return out.astype(np.float32)


# ---------------------------------------------------------------------------- cache


class MeshReader(Protocol):
    """What reads a mesh file for a `MeshCache`: `load_mesh_file`, or the daemon's reader
    processes (`bridge.robots.mesh_readers.MeshReaders.read`)."""

    def __call__(self, path: Path, scale: Sequence[float] = ..., *,
                 max_triangles: Optional[int] = None) -> MeshData: ...


class MeshCache:
    """Loaded meshes keyed by (resolved file, its mtime and size, scale, triangle budget).

    Several robots, or a robot loaded again, share the arrays instead of re-reading the
    file; an edited file (new mtime or size) is read again. Thread-safe; keeps at most
    ``max_entries`` meshes, least recently used first out. A mesh being read when another
    thread asks for it is read once: the second waits for it (a robot's loader reads
    several files at once, and one file often serves several links).

    With a ``folder``, each mesh read from a file is also kept there as it was made (one
    ``.mesh`` file per key, `MESH_FOLDER_ENTRIES` at most, the oldest used out first), so a
    daemon started again, or another process, reads the arrays instead of parsing the file
    again (a 3,000-triangle COLLADA file: 9 ms to parse, well under 1 ms from the folder).
    """

    def __init__(self, max_entries: int = 512, *, folder: Optional[Path] = None) -> None:
        self.max_entries = max_entries
        self.folder = folder
        self._entries: OrderedDict[tuple[object, ...], MeshData] = OrderedDict()
        self._reading: dict[tuple[object, ...], Future[MeshData]] = {}
        self._lock = threading.Lock()
        self.hits = 0
        self.misses = 0
        self.folder_hits = 0

    def clear(self) -> None:
        with self._lock:
            self._entries.clear()
            self.hits = self.misses = self.folder_hits = 0

    def __len__(self) -> int:
        return len(self._entries)

    def mesh_file(self, path: Path, scale: Sequence[float] = (1.0, 1.0, 1.0), *,
                  max_triangles: Optional[int] = None,
                  reader: Optional[MeshReader] = None) -> MeshData:
        """The mesh of a file, from memory, the folder, or read by ``reader`` (default
        `load_mesh_file`, in this process)."""
        resolved = path.resolve()
        try:
            stat = resolved.stat()
        except OSError as exc:
            raise MeshError(str(path), "a readable file", str(exc)) from None
        key = ("file", str(resolved), stat.st_mtime_ns, stat.st_size,
               tuple(float(s) for s in scale), max_triangles)
        read = reader or load_mesh_file
        return self._get(key, lambda: self._kept_or_read(key, resolved, scale, max_triangles,
                                                         read))

    def _kept_or_read(self, key: tuple[object, ...], path: Path, scale: Sequence[float],
                      max_triangles: Optional[int], read: MeshReader) -> MeshData:
        if self.folder is None:
            return read(path, scale, max_triangles=max_triangles)
        kept = self.folder / (hashlib.sha256(repr((_FOLDER_FORMAT, key)).encode()).hexdigest()
                              + ".mesh")
        mesh = _read_kept(kept)
        if mesh is not None:
            with self._lock:
                self.folder_hits += 1
            return mesh
        mesh = read(path, scale, max_triangles=max_triangles)
        _keep(kept, mesh)
        return mesh

    def primitive(self, kind: str, *params: float) -> MeshData:
        key = (kind, *(float(p) for p in params))
        if kind == "box":
            return self._get(key, lambda: box_mesh(params))
        if kind == "cylinder":
            return self._get(key, lambda: cylinder_mesh(params[0], params[1]))
        if kind == "sphere":
            return self._get(key, lambda: sphere_mesh(params[0]) if len(params) == 1
                             else sphere_mesh(params[0], int(params[1])))
        if kind == "cone":
            return self._get(key, lambda: cone_mesh(params[0], params[1]))
        raise MeshError("primitive", "box, cylinder, sphere or cone", kind)

    def _get(self, key: tuple[object, ...], make: Any) -> MeshData:
        with self._lock:
            found = self._entries.get(key)
            if found is not None:
                self._entries.move_to_end(key)
                self.hits += 1
                return found
            reading = self._reading.get(key)
            if reading is None:
                self.misses += 1
                mine: Future[MeshData] = Future()
                self._reading[key] = mine
            else:
                self.hits += 1
        if reading is not None:
            return reading.result()  # read by another thread (its MeshError too)
        try:
            mesh: MeshData = make()  # outside the lock: reading a file may take a while
        except BaseException as error:
            with self._lock:
                del self._reading[key]
            mine.set_exception(error)
            raise
        with self._lock:
            del self._reading[key]
            self._entries[key] = mesh
            self._entries.move_to_end(key)
            while len(self._entries) > self.max_entries:
                self._entries.popitem(last=False)
        mine.set_result(mesh)
        return mesh


# ---------------------------------------------------------------------------- kept meshes

# Bumped when what a kept mesh holds, or how a file is read, changes: older ones are unused.
_FOLDER_FORMAT = 1
MESH_FOLDER_ENTRIES = 4096
# The folder is pruned at this process's first write and every this many writes after it.
_PRUNE_EVERY = 256
_written = 0


def default_mesh_folder() -> Path:
    return user_cache_dir() / "meshes"


def _read_kept(kept: Path) -> Optional[MeshData]:
    """A mesh `_keep` wrote, or None (none there, or unreadable: read the file again)."""
    try:
        data = kept.read_bytes()
    except FileNotFoundError:
        return None
    except OSError as exc:
        _log.debug("mesh cache entry %s unreadable (%s)", kept, exc)
        return None
    try:
        end = data.index(b"\n")
        head = json.loads(data[:end])
        n, m = int(head["vertices"]), int(head["triangles"])
        at = end + 1
        vertices = np.frombuffer(data, np.float64, n * 3, at).reshape(n, 3)
        at += n * 24
        triangles = np.frombuffer(data, np.uint32, m * 3, at).reshape(m, 3)
        at += m * 12
        vertex_rgba = None
        if head["vertex_rgba"]:
            vertex_rgba = np.frombuffer(data, np.uint8, n * 4, at).reshape(n, 4)
            at += n * 4
        if at != len(data):
            raise ValueError(f"{len(data) - at} bytes more than its header says")
        if m and int(triangles.max()) >= n:
            raise ValueError(f"a triangle names vertex {int(triangles.max())} of {n}")
        rgba = head["rgba"]
        mesh = MeshData(_frozen(vertices), _frozen(triangles),
                        None if rgba is None else (float(rgba[0]), float(rgba[1]),
                                                   float(rgba[2]), float(rgba[3])),
                        None if vertex_rgba is None else _frozen(vertex_rgba),
                        str(head["description"]), int(head["original_triangles"]))
    except Exception as exc:  # noqa: BLE001 - a damaged entry is read from its file again
        _log.debug("mesh cache entry %s unusable (%s)", kept, exc)
        return None
    try:
        os.utime(kept)  # its age says when it was last used (`_prune`)
    except OSError:
        pass
    return mesh


def _keep(kept: Path, mesh: MeshData) -> None:
    """Write `mesh` to `kept` (atomically): a JSON line (counts, colours, description),
    then the vertices (float64), triangles (uint32) and per-vertex colours (uint8) as
    bytes. A folder that cannot be written is skipped."""
    head = {"vertices": len(mesh.vertices), "triangles": len(mesh.triangles),
            "rgba": None if mesh.rgba is None else list(mesh.rgba),
            "vertex_rgba": mesh.vertex_rgba is not None, "description": mesh.description,
            "original_triangles": mesh.original_triangles}
    parts = [json.dumps(head).encode() + b"\n",
             np.ascontiguousarray(mesh.vertices, dtype=np.float64).tobytes(),
             np.ascontiguousarray(mesh.triangles, dtype=np.uint32).tobytes()]
    if mesh.vertex_rgba is not None:
        parts.append(np.ascontiguousarray(mesh.vertex_rgba, dtype=np.uint8).tobytes())
    try:
        kept.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=kept.parent, suffix=".part", delete=False) as out:
            out.write(b"".join(parts))
        os.replace(out.name, kept)
        global _written
        _written += 1
        if (_written - 1) % _PRUNE_EVERY == 0:  # listing a full folder takes ms: not always
            _prune(kept.parent)
    except OSError as exc:
        _log.debug("mesh cache %s not written (%s)", kept.parent, exc)


def _prune(folder: Path) -> None:
    """At most `MESH_FOLDER_ENTRIES` kept meshes (a few hundred more between two prunings):
    the least recently used go."""
    entries = [e for e in os.scandir(folder) if e.name.endswith(".mesh")]
    if len(entries) <= MESH_FOLDER_ENTRIES:
        return
    entries.sort(key=lambda e: e.stat().st_mtime)
    for entry in entries[:len(entries) - MESH_FOLDER_ENTRIES]:
        try:
            os.unlink(entry.path)
        except OSError:
            pass


# The process-wide cache `load_robot` uses unless given another one, kept on disk too.
DEFAULT_MESH_CACHE = MeshCache(folder=default_mesh_folder())

"""A robot ready for Slicer: every link visual as a triangle mesh in MILLIMETRES, plus FK.

`load_robot` (URDF text) and `load_robot_file` (a path) parse the URDF (`parse_urdf`),
resolve each mesh URI (`PackageResolver`), read it through a shared `MeshCache`, apply
the per-visual ``scale`` and ``<origin>``, convert metres to millimetres with
`protocol.conversions.metres_to_mm`, and pick a colour:

1. the URDF material of the visual (inline ``<color>``, or a named material defined at
   robot level or inline in an earlier visual);
2. else the mesh file's own colours (DAE/OBJ materials, face or vertex colours);
3. else `DEFAULT_RGBA` (grey).

A mesh that is missing, unreadable or not a mesh becomes a warning naming the file and the
link (``RobotModel.warnings``, also logged) and the rest of the robot loads. Only a
malformed URDF raises (`UrdfError`).

`to_polydata` turns one `VisualMesh` into the POLYDATA message the daemon sends once per
connection; link poses come from `RobotModel.link_poses` (metres, the root link's frame).
"""

from __future__ import annotations

import logging
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterator, Mapping, Optional, Sequence

import numpy as np
import numpy.typing as npt

from bridge.robots.description import JointSpec, RobotDescription, VisualSpec, parse_urdf
from bridge.robots.errors import MeshError, ResourceError, UrdfError
from bridge.robots.kinematics import Kinematics
from bridge.robots.meshes import DEFAULT_MESH_CACHE, MeshCache, MeshData, vertex_normals
from bridge.robots.resources import PackageResolver
from protocol.conversions import metres_to_mm
from protocol.messages import AttributeKind, PolyData, PolyDataAttribute, cells_from_array
from protocol.polydata import NORMALS_ATTRIBUTE, colour_attribute, point_attribute

if TYPE_CHECKING:
    from bridge.robots.mesh_readers import MeshReaders

__all__ = [
    "DEFAULT_RGBA",
    "LoadOptions",
    "MeshSource",
    "VisualMesh",
    "RobotModel",
    "load_robot",
    "load_robot_file",
    "mesh_for",
    "to_polydata",
]

_log = logging.getLogger("bridge.robots")

F32 = npt.NDArray[np.float32]
F64 = npt.NDArray[np.float64]
U32 = npt.NDArray[np.uint32]
Rgba = tuple[float, float, float, float]

DEFAULT_RGBA: Rgba = (0.7, 0.7, 0.7, 1.0)

# Told the parsed description before any mesh is read, then each visual as it is made (on
# the loading thread): whoever serves the robot starts its link poses and sends each mesh
# while the rest are read (`bridge.robots.capability`).
DescriptionListener = Callable[[RobotDescription], None]
VisualListener = Callable[["VisualMesh"], None]


@dataclass(frozen=True)
class LoadOptions:
    """How meshes are prepared.

    ``max_triangles``: decimate any mesh file above this many triangles (None: never).
    ``normals``: compute per-point normals (smooth shading; without them Slicer shades
    each triangle flat, which suits CAD meshes with sharp edges).
    ``progress_after_s``: log each mesh once loading has taken longer than this.
    """

    max_triangles: Optional[int] = None
    normals: bool = False
    progress_after_s: float = 0.5


@dataclass(frozen=True, eq=False)
class VisualMesh:
    """One ``<visual>`` of one link, ready to draw: vertices in mm, in the LINK frame
    (the visual origin and scale already applied)."""

    link: str
    index: int  # among the link's visuals, in URDF order
    name: str  # the URDF visual name, else "<link>_visual<index>"
    vertices: F32  # (N, 3) float32, mm, link frame
    triangles: U32  # (M, 3) uint32
    rgba: Rgba  # the visual's colour, 0..1
    normals: Optional[F32] = None  # (N, 3) unit, link frame, if LoadOptions.normals
    vertex_rgba: Optional[F32] = None  # (N, 4) 0..1 when the mesh file's colours vary
    source: str = ""  # "package://... -> /path (stl ..., 2848 triangles)", "box ..."
    colour_source: str = "default"  # "urdf", "mesh" or "default"


@dataclass(frozen=True, eq=False)
class MeshSource:
    """Where a robot's meshes were read from: its resolver (package paths, and the folders
    it may read, as the robot's request allowed) and the mesh cache. Whoever reads more of
    the robot's meshes later (its collision geometry) reads them under the same rules."""

    resolver: PackageResolver
    cache: MeshCache


@dataclass(frozen=True, eq=False)
class RobotModel:
    """A loaded robot: its description, its visuals and forward kinematics."""

    description: RobotDescription
    visuals: tuple[VisualMesh, ...]
    warnings: tuple[str, ...]
    kinematics: Kinematics
    meshes: Optional[MeshSource] = None

    @property
    def name(self) -> str:
        return self.description.name

    @property
    def root_link(self) -> str:
        return self.description.root_link

    @property
    def links(self) -> tuple[str, ...]:
        return tuple(self.description.links)

    @property
    def joints(self) -> Mapping[str, JointSpec]:
        return self.description.joints

    @property
    def urdf(self) -> str:
        return self.description.xml

    @cached_property
    def _visuals_by_link(self) -> dict[str, tuple[VisualMesh, ...]]:
        grouped: dict[str, list[VisualMesh]] = {}
        for v in self.visuals:
            grouped.setdefault(v.link, []).append(v)
        return {link: tuple(vs) for link, vs in grouped.items()}

    def visuals_of(self, link: str) -> tuple[VisualMesh, ...]:
        """The visuals of ``link`` in URDF order (those that loaded); O(1)."""
        return self._visuals_by_link.get(link, ())

    def link_poses(self, joint_positions: Mapping[str, float]) -> dict[str, F64]:
        """4x4 pose (metres) of every link in the root link's frame."""
        return self.kinematics.link_poses(joint_positions)


# ---------------------------------------------------------------------------- loading


def mesh_for(spec: VisualSpec, resolver: PackageResolver, cache: MeshCache,
             options: LoadOptions, readers: Optional[MeshReaders] = None
             ) -> tuple[MeshData, str]:
    """The triangle mesh (metres, the geometry's own frame, scale applied) of one visual or
    collision spec, and where it came from; a file is parsed by ``readers`` (processes) if
    given, else here. Raises `ResourceError` / `MeshError`."""
    g = spec.geometry
    if g.kind == "mesh":
        assert g.filename is not None
        path = resolver.resolve(g.filename)
        mesh = cache.mesh_file(path, g.scale, max_triangles=options.max_triangles,
                               reader=None if readers is None else readers.read)
        return mesh, f"{g.filename} -> {path} ({mesh.description})"
    if g.kind == "box":
        mesh = cache.primitive("box", *g.size)
    elif g.kind == "cylinder":
        mesh = cache.primitive("cylinder", g.radius, g.length)
    else:
        mesh = cache.primitive("sphere", g.radius)
    return mesh, mesh.description


def _visual_mesh(spec: VisualSpec, mesh: MeshData, source: str,
                 options: LoadOptions) -> VisualMesh:
    rotation = spec.origin[:3, :3]
    # Visual frame -> link frame in metres, then the project's one unit conversion.
    link_m = mesh.vertices @ rotation.T + spec.origin[:3, 3]
    vertices = np.ascontiguousarray(metres_to_mm(link_m), dtype=np.float32)
    normals: Optional[F32] = None
    if options.normals:
        normals = np.ascontiguousarray(
            vertex_normals(mesh.vertices, mesh.triangles) @ rotation.T.astype(np.float32),
            dtype=np.float32)
    vertex_rgba: Optional[F32] = None
    if spec.rgba is not None:
        rgba, colour_source = spec.rgba, "urdf"
    elif mesh.rgba is not None:
        rgba, colour_source = mesh.rgba, "mesh"
    elif mesh.vertex_rgba is not None:
        vertex_rgba = mesh.vertex_rgba.astype(np.float32) / np.float32(255.0)
        mean = vertex_rgba.mean(axis=0)
        rgba, colour_source = (float(mean[0]), float(mean[1]), float(mean[2]),
                               float(mean[3])), "mesh"
    else:
        rgba, colour_source = DEFAULT_RGBA, "default"
    for array in (vertices, normals, vertex_rgba):
        if array is not None:
            array.setflags(write=False)
    name = spec.name or f"{spec.link}_visual{spec.index}"
    return VisualMesh(spec.link, spec.index, name, vertices, mesh.triangles, rgba, normals,
                      vertex_rgba, source, colour_source)


def _made(spec: VisualSpec, resolver: PackageResolver, cache: MeshCache,
          options: LoadOptions, readers: Optional[MeshReaders]) -> tuple[VisualMesh | str, str]:
    """One visual made, or the warning that leaves it out; and where its mesh came from."""
    what = f"link {spec.link!r} visual {spec.index}"
    try:
        mesh, source = mesh_for(spec, resolver, cache, options, readers)
    except ResourceError as exc:
        return (f"{what}: mesh {spec.geometry.filename!r} not found: expected "
                f"{exc.expected}, got {exc.got}; the visual is left out"), ""
    except MeshError as exc:
        uri = spec.geometry.filename or spec.geometry.kind
        return (f"{what}: mesh {uri!r} ({exc.field}) cannot be used: expected "
                f"{exc.expected}, got {exc.got}; the visual is left out"), ""
    return _visual_mesh(spec, mesh, source, options), source


def _as_made(specs: Sequence[VisualSpec], make: Callable[[VisualSpec], tuple[VisualMesh | str,
                                                                             str]],
             threads: int) -> Iterator[tuple[int, tuple[VisualMesh | str, str]]]:
    """(index, made) for every spec, in the order they are made: by ``threads`` threads
    (each waiting on a reader process most of the time) if more than one, else here in
    order. An unexpected error stops the rest and is raised."""
    if threads <= 1:
        for index, spec in enumerate(specs):
            yield index, make(spec)
        return
    pool = ThreadPoolExecutor(threads, thread_name_prefix="mesh-read")
    try:
        futures = {pool.submit(make, spec): index for index, spec in enumerate(specs)}
        for future in as_completed(futures):
            yield futures[future], future.result()
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _load(description: RobotDescription, resolver: PackageResolver, cache: MeshCache,
          options: LoadOptions, logger: logging.Logger,
          on_description: Optional[DescriptionListener] = None,
          on_visual: Optional[VisualListener] = None,
          readers: Optional[MeshReaders] = None) -> RobotModel:
    if on_description is not None:
        on_description(description)
    warnings = list(description.warnings)
    for w in description.warnings:
        logger.warning("robot %r: %s", description.name, w)
    specs = [v for link in description.links.values() for v in link.visuals]
    made: dict[int, VisualMesh] = {}
    left_out: dict[int, str] = {}
    start = time.monotonic()
    reported = False
    # Two files in flight per reader: each has the next while this process makes the last.
    threads = 2 * readers.workers if readers is not None else 1
    for number, (index, (visual, source)) in enumerate(
            _as_made(specs, lambda spec: _made(spec, resolver, cache, options, readers),
                     threads), 1):
        if isinstance(visual, str):
            left_out[index] = visual
            logger.warning("robot %r: %s", description.name, visual)
            continue
        made[index] = visual
        if on_visual is not None:
            on_visual(visual)
        elapsed = time.monotonic() - start
        if elapsed > options.progress_after_s:
            reported = True
            logger.info("robot %r: visual %d/%d loaded (%s, %.1f s)", description.name,
                        number, len(specs), source, elapsed)
    # The model lists visuals and warnings in URDF order, whatever order they were made in.
    visuals = [made[index] for index in sorted(made)]
    warnings += [left_out[index] for index in sorted(left_out)]
    if reported:
        logger.info("robot %r: %d visuals of %d links loaded in %.1f s", description.name,
                    len(visuals), len(description.links), time.monotonic() - start)
    return RobotModel(description, tuple(visuals), tuple(warnings), Kinematics(description),
                      MeshSource(resolver, cache))


def load_robot(urdf: str | bytes, *, package_paths: Optional[Mapping[str, Path]] = None,
               base_dir: Optional[Path] = None, options: LoadOptions = LoadOptions(),
               cache: Optional[MeshCache] = None,
               logger: Optional[logging.Logger] = None,
               allowed_roots: Optional[tuple[Path, ...]] = None,
               on_description: Optional[DescriptionListener] = None,
               on_visual: Optional[VisualListener] = None,
               readers: Optional[MeshReaders] = None) -> RobotModel:
    """Load a robot from URDF TEXT (for example a ``robot_description`` parameter).

    ``package_paths`` maps package names to folders for ``package://`` URIs (searched
    before ROS_PACKAGE_PATH and the ament index, see `bridge.robots.resources`);
    relative mesh paths are taken relative to ``base_dir`` (default: current directory).
    ``allowed_roots``: meshes only from inside these folders (a client's robot).
    ``on_description``, ``on_visual``: told the parsed URDF, then each visual as it is made
    (on this thread), before the whole model is returned.
    ``readers``: mesh files are parsed in these processes, several at once (the daemon's;
    `bridge.robots.mesh_readers`); without them, here, one after the other.
    Raises `UrdfError` for a malformed URDF; mesh problems become ``warnings``.
    """
    description = parse_urdf(urdf)
    resolver = PackageResolver(dict(package_paths or {}), base_dir=base_dir,
                               allowed_roots=allowed_roots)
    return _load(description, resolver, cache if cache is not None else DEFAULT_MESH_CACHE,
                 options, logger or _log, on_description, on_visual, readers)


def load_robot_file(path: str | Path, *, package_paths: Optional[Mapping[str, Path]] = None,
                    options: LoadOptions = LoadOptions(), cache: Optional[MeshCache] = None,
                    logger: Optional[logging.Logger] = None,
                    allowed_roots: Optional[tuple[Path, ...]] = None,
                    on_description: Optional[DescriptionListener] = None,
                    on_visual: Optional[VisualListener] = None,
                    readers: Optional[MeshReaders] = None) -> RobotModel:
    """Load a robot from a URDF FILE; relative mesh paths are relative to its folder."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as exc:
        # strerror, not str(exc): that repeats the path the field already names.
        raise UrdfError(str(p), "a readable URDF file",
                        exc.strerror or type(exc).__name__) from None
    return load_robot(data, package_paths=package_paths, base_dir=p.resolve().parent,
                      options=options, cache=cache, logger=logger,
                      allowed_roots=allowed_roots, on_description=on_description,
                      on_visual=on_visual, readers=readers)


# ---------------------------------------------------------------------------- POLYDATA


def to_polydata(visual: VisualMesh, *, colours: bool = True,
                normals: bool = True) -> PolyData:
    """One visual as a POLYDATA body: points (mm, link frame), triangles as polygons, the
    point colours (``"RGBA"``, 0..1, `protocol.polydata.colour_attribute`) and, if the
    visual has them, the point normals ``"Normals"``."""
    attributes: list[PolyDataAttribute] = []
    n = len(visual.vertices)
    if colours:
        if visual.vertex_rgba is not None:
            rgba = visual.vertex_rgba
        else:
            rgba = np.broadcast_to(np.asarray(visual.rgba, dtype=np.float32), (n, 4))
        attributes.append(colour_attribute(rgba))
    if normals and visual.normals is not None:
        attributes.append(point_attribute(NORMALS_ATTRIBUTE, AttributeKind.NORMAL,
                                          visual.normals))
    return PolyData(points=visual.vertices, polygons=cells_from_array(visual.triangles),
                    attributes=attributes)

"""Collision geometry of a robot and of obstacles, checked and measured with coal.

Each link's geometry is its URDF ``<collision>`` elements (boxes, cylinders and spheres as
coal's exact shapes, meshes as bounding-volume hierarchies), and a link with none falls
back to its loaded visuals (the triangles Slicer shows). Obstacles are triangle meshes in
the robot's root link frame, each with a pose that may change (a model moved in Slicer).

Self-collision is not checked: which link pairs may touch needs an SRDF, which a URDF
does not carry. Everything is in METRES.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Optional

import coal
import numpy as np
import numpy.typing as npt

from bridge.motion.errors import MotionInputError, NoCollisionGeometry, ObstacleError
from bridge.motion.model import MotionModel
from bridge.robots.description import VisualSpec
from bridge.robots.errors import MeshError, ResourceError
from bridge.robots.model import LoadOptions, mesh_for
from protocol.conversions import fits_float32, metres_to_mm, mm_to_metres

__all__ = ["MAX_OBSTACLE_TRIANGLES", "CollisionWorld", "Contact", "Distance", "mesh_bvh"]

log = logging.getLogger(__name__)

F64 = npt.NDArray[np.float64]

# An obstacle above this is refused, not simplified: a segmentation's surface has ~1e5
# triangles; 2e6 (a 0.1 mm marching-cubes surface of a whole torso) takes ~5 s to build.
MAX_OBSTACLE_TRIANGLES = 2_000_000
# The smallest triangle area (m^2) that counts: 1e-6 mm^2; a mesh of only smaller ones is
# degenerate (a flattened or collapsed segmentation).
_MIN_AREA_M2 = 1e-18


@dataclass(frozen=True)
class Contact:
    link: str
    obstacle: str


@dataclass(frozen=True)
class Distance:
    """From one link to one obstacle: the distance (metres, 0 in contact) and the nearest
    points on each (root link frame)."""

    obstacle: str
    distance_m: float
    on_link: F64
    on_obstacle: F64

    def to_dict(self) -> dict[str, object]:
        return {"obstacle": self.obstacle, "distance_mm": float(metres_to_mm(self.distance_m)),
                "on_link_mm": metres_to_mm(self.on_link).tolist(),
                "on_obstacle_mm": metres_to_mm(self.on_obstacle).tolist()}


@dataclass(frozen=True)
class _Piece:
    link: str
    frame: int
    geometry: coal.CollisionGeometry
    placement: F64  # 4x4, in the link frame
    source: str  # "collision" or "visual"


@dataclass
class _Obstacle:
    name: str
    geometry: coal.BVHModelOBBRSS
    pose: F64
    triangles: int


def _transform(matrix: F64) -> coal.Transform3s:
    return coal.Transform3s(np.ascontiguousarray(matrix[:3, :3]),
                            np.ascontiguousarray(matrix[:3, 3]))


def mesh_bvh(vertices_m: npt.ArrayLike, triangles: npt.ArrayLike,
             field: str = "mesh") -> coal.BVHModelOBBRSS:
    """A coal bounding-volume hierarchy of a triangle mesh, after the checks that make an
    obstacle usable (finite, within float32 in mm, indices in range, not degenerate, at most
    `MAX_OBSTACLE_TRIANGLES`); raises `ObstacleError`."""
    v = np.asarray(vertices_m, dtype=np.float64)
    t = np.asarray(triangles)
    if v.ndim != 2 or v.shape[1] != 3 or len(v) < 3:
        raise ObstacleError(f"{field}.points", "at least 3 points (N x 3)", f"shape {v.shape}")
    if t.ndim != 2 or t.shape[1] != 3 or len(t) == 0:
        raise ObstacleError(f"{field}.triangles", "at least one triangle (M x 3)",
                            f"shape {t.shape}")
    if len(t) > MAX_OBSTACLE_TRIANGLES:
        raise ObstacleError(f"{field}.triangles", f"at most {MAX_OBSTACLE_TRIANGLES} "
                            "triangles (decimate the model first)", f"{len(t)}")
    if not np.all(np.isfinite(v)):
        raise ObstacleError(f"{field}.points", "finite numbers", "NaN or infinity")
    if not fits_float32(float(metres_to_mm(np.max(np.abs(v))))):
        raise ObstacleError(f"{field}.points", "coordinates within float32 in mm",
                            f"{float(np.max(np.abs(v)))} m")
    if not np.issubdtype(t.dtype, np.integer) or t.min() < 0 or t.max() >= len(v):
        raise ObstacleError(f"{field}.triangles", f"indices of points 0..{len(v) - 1}",
                            f"{t.min()}..{t.max()}" if np.issubdtype(t.dtype, np.integer)
                            else str(t.dtype))
    corners = v[t]
    areas = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0],
                                          corners[:, 2] - corners[:, 0]), axis=1)
    if not np.any(areas > _MIN_AREA_M2):
        raise ObstacleError(f"{field}.triangles", "triangles with an area", "only "
                            "degenerate ones (zero area: collapsed or repeated points)")
    bvh = coal.BVHModelOBBRSS()
    bvh.beginModel(len(t), len(v))
    bvh.addVertices(np.ascontiguousarray(v))
    bvh.addTriangles(np.ascontiguousarray(t, dtype=np.int64))
    bvh.endModel()
    return bvh


def _shape(spec: VisualSpec, model: MotionModel) -> coal.CollisionGeometry:
    g = spec.geometry
    if g.kind == "box":
        return coal.Box(*g.size)
    if g.kind == "cylinder":
        return coal.Cylinder(g.radius, g.length)  # both along z, centred
    if g.kind == "sphere":
        return coal.Sphere(g.radius)
    meshes = model.robot.meshes
    if meshes is None:
        raise MeshError(g.filename or "mesh", "a robot loaded with its mesh source", "none")
    mesh, _ = mesh_for(spec, meshes.resolver, meshes.cache, LoadOptions())
    return mesh_bvh(mesh.vertices, mesh.triangles, f"link {spec.link!r} collision")


class CollisionWorld:
    """One robot's collision geometry and the obstacles around it."""

    def __init__(self, model: MotionModel) -> None:
        self.model = model
        self.warnings: list[str] = list(model.robot.description.collision_warnings)
        pieces: list[_Piece] = []
        description = model.robot.description
        for link in model.link_names:
            frame = model.frame_id(link)
            specs = description.links[link].collisions
            if specs:
                for spec in specs:
                    try:
                        geometry = _shape(spec, model)
                    except (MeshError, ResourceError, ObstacleError) as error:
                        self.warnings.append(f"link {link!r} collision {spec.index} left "
                                             f"out: {error}")
                        continue
                    pieces.append(_Piece(link, frame, geometry, spec.origin, "collision"))
                continue
            for visual in model.robot.visuals_of(link):  # vertices already in the link frame
                try:
                    geometry = mesh_bvh(mm_to_metres(visual.vertices), visual.triangles,
                                        f"link {link!r} visual {visual.index}")
                except ObstacleError as error:
                    self.warnings.append(str(error))
                    continue
                pieces.append(_Piece(link, frame, geometry, np.eye(4), "visual"))
        self._pieces = pieces
        self.obstacles: dict[str, _Obstacle] = {}
        self._collide_request = coal.CollisionRequest()
        self._distance_request = coal.DistanceRequest()

    @property
    def links(self) -> tuple[str, ...]:
        """The links that have collision geometry (their own, or their visuals')."""
        return tuple(dict.fromkeys(p.link for p in self._pieces))

    def source_of(self, link: str) -> str:
        kinds = {p.source for p in self._pieces if p.link == link}
        return kinds.pop() if len(kinds) == 1 else ("none" if not kinds else "mixed")

    def require_geometry(self, field: str = "name") -> None:
        if not self._pieces:
            raise NoCollisionGeometry(field, f"a robot with collision geometry or visuals "
                                      f"(robot {self.model.name!r})", "no link has any")

    # ------------------------------------------------------------------ obstacles

    def set_obstacle(self, name: str, vertices_m: npt.ArrayLike, triangles: npt.ArrayLike,
                     pose_m: Optional[F64] = None) -> None:
        """Add or replace obstacle ``name`` (vertices in its own frame, posed by ``pose_m``
        in the robot's root link frame)."""
        self.put_obstacle(name, mesh_bvh(vertices_m, triangles, f"obstacle {name!r}"), pose_m)

    def put_obstacle(self, name: str, bvh: coal.BVHModelOBBRSS,
                     pose_m: Optional[F64] = None) -> None:
        """Add or replace obstacle ``name`` from a hierarchy `mesh_bvh` built (which may
        take a while: outside any lock a query holds)."""
        self.obstacles[name] = _Obstacle(name, bvh, self._checked_pose(pose_m, name),
                                         int(bvh.num_tris))

    def move_obstacle(self, name: str, pose_m: F64) -> None:
        self._obstacle(name).pose = self._checked_pose(pose_m, name)

    def remove_obstacle(self, name: str) -> None:
        self._obstacle(name)
        del self.obstacles[name]

    def _obstacle(self, name: str) -> _Obstacle:
        found = self.obstacles.get(name)
        if found is None:
            raise MotionInputError("obstacle", f"an obstacle of robot {self.model.name!r} "
                                   f"({', '.join(self.obstacles) or 'none'})", name)
        return found

    @staticmethod
    def _checked_pose(pose_m: Optional[F64], name: str) -> F64:
        if pose_m is None:
            return np.eye(4)
        pose = np.asarray(pose_m, dtype=np.float64)
        if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
            raise MotionInputError(f"obstacle {name!r} pose", "a finite 4x4 transform",
                                   f"shape {pose.shape}")
        return pose

    # ------------------------------------------------------------------ queries

    def _placed(self, theta: F64, links: Optional[set[str]] = None
                ) -> list[tuple[_Piece, coal.Transform3s]]:
        self.model.update(theta)
        out = []
        for piece in self._pieces:
            if links is not None and piece.link not in links:
                continue
            pose = np.array(self.model.pose(piece.frame).homogeneous) @ piece.placement
            out.append((piece, _transform(pose)))
        return out

    def contacts(self, theta: F64, *, first: bool = False) -> list[Contact]:
        """Link-obstacle pairs in contact at ``theta`` (each pair once)."""
        found: list[Contact] = []
        if not self.obstacles:
            return found
        placed = [(o, _transform(o.pose)) for o in self.obstacles.values()]
        for piece, where in self._placed(theta):
            for obstacle, at in placed:
                contact = Contact(piece.link, obstacle.name)
                if contact in found:
                    continue
                result = coal.CollisionResult()
                if coal.collide(piece.geometry, where, obstacle.geometry, at,
                                self._collide_request, result):
                    found.append(contact)
                    if first:
                        return found
        return found

    def first_contact(self, theta: F64) -> Optional[Contact]:
        hits = self.contacts(theta, first=True)
        return hits[0] if hits else None

    def distances(self, theta: F64, link: str) -> list[Distance]:
        """The minimum distance from ``link``'s geometry to each obstacle at ``theta``."""
        self.model.frame_id(link, "link")
        pieces = self._placed(theta, {link})
        if not pieces:
            raise NoCollisionGeometry("link", f"a link with collision geometry or visuals "
                                      f"({', '.join(self.links) or 'none'})", link)
        out = []
        for obstacle in self.obstacles.values():
            at = _transform(obstacle.pose)
            best: Optional[Distance] = None
            for piece, where in pieces:
                result = coal.DistanceResult()
                d = max(0.0, float(coal.distance(piece.geometry, where, obstacle.geometry, at,
                                                 self._distance_request, result)))
                if best is None or d < best.distance_m:
                    best = Distance(obstacle.name, d, np.array(result.getNearestPoint1()),
                                    np.array(result.getNearestPoint2()))
            assert best is not None
            out.append(best)
        return out

    def path_contact(self, thetas: F64) -> Optional[tuple[int, Contact]]:
        """The first configuration of a path (rows of ``thetas``) in contact, if any."""
        for index, theta in enumerate(thetas):
            contact = self.first_contact(theta)
            if contact is not None:
                return index, contact
        return None

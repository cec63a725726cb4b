"""rclpy messages -> `MarkerEvent`s (duck-typed: this module imports no ROS package).

A Marker or MarkerArray gives one event per marker (in order: a DELETEALL then ADDs in
one array is the usual "replace everything" idiom); a Path, PolygonStamped or PointStamped
gives one "add" of the topic's single model (ns "", id 0).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional

import numpy as np

from bridge.markers.geometry import (MAX_MARKER_POINTS, MarkerError, MarkerSpec,
                                     kind_of_type)

__all__ = ["ADD", "DELETE", "DELETEALL", "MarkerEvent", "events_of"]

ADD, DELETE, DELETEALL = "add", "delete", "deleteall"
_ACTIONS = {0: ADD, 1: ADD, 2: DELETE, 3: DELETEALL}  # 1: the deprecated MODIFY
_NS_PER_S = 1_000_000_000
# RViz's default colours for the types that carry none (its Path and Polygon displays'
# 25,255,0; its PointStamped display's 204,41,204).
PATH_RGBA = (25 / 255, 1.0, 0.0, 1.0)
POINT_RGBA = (204 / 255, 41 / 255, 204 / 255, 1.0)


@dataclass(frozen=True, eq=False)
class MarkerEvent:
    """One marker's action; ``spec`` for an add, ``error`` when it cannot be read."""

    action: str
    ns: str
    id: int
    spec: Optional[MarkerSpec] = None
    error: Optional[MarkerError] = None


def _xyz(points: Any, field: str) -> np.ndarray:
    n = len(points)
    if n > MAX_MARKER_POINTS:
        raise MarkerError(field, f"at most {MAX_MARKER_POINTS} points", f"{n} points")
    out = np.fromiter((c for p in points for c in (p.x, p.y, p.z)), dtype=np.float64,
                      count=3 * n)
    return out.reshape(n, 3)


def _rgba(colors: Any) -> Optional[np.ndarray]:
    n = len(colors)
    if n == 0:
        return None
    if n > MAX_MARKER_POINTS:
        raise MarkerError("colors", f"at most {MAX_MARKER_POINTS} colours", f"{n} colours")
    out = np.fromiter((v for c in colors for v in (c.r, c.g, c.b, c.a)), dtype=np.float64,
                      count=4 * n)
    return out.reshape(n, 4)


def _marker(msg: Any) -> MarkerEvent:
    ns, marker_id = str(msg.ns), int(msg.id)
    action = _ACTIONS.get(int(msg.action))
    if action is None:
        return MarkerEvent(ADD, ns, marker_id, error=MarkerError(
            "action", "ADD (0), MODIFY (1), DELETE (2) or DELETEALL (3)", str(msg.action)))
    if action != ADD:
        return MarkerEvent(action, ns, marker_id)
    try:
        kind = kind_of_type(int(msg.type))
        p, q, s, c = msg.pose.position, msg.pose.orientation, msg.scale, msg.color
        lifetime = msg.lifetime
        spec = MarkerSpec(
            kind=kind, ns=ns, id=marker_id, frame=str(msg.header.frame_id),
            position=np.array([p.x, p.y, p.z]), orientation=np.array([q.x, q.y, q.z, q.w]),
            scale=np.array([s.x, s.y, s.z]), color=(c.r, c.g, c.b, c.a),
            points=_xyz(msg.points, "points"), colors=_rgba(msg.colors),
            text=str(msg.text), mesh_resource=str(msg.mesh_resource),
            use_embedded_materials=bool(msg.mesh_use_embedded_materials),
            lifetime_ns=max(0, int(lifetime.sec) * _NS_PER_S + int(lifetime.nanosec)),
            frame_locked=bool(msg.frame_locked), stamp=_stamp(msg.header))
    except MarkerError as error:
        return MarkerEvent(ADD, ns, marker_id, error=error)
    if kind == "mesh_resource" and not spec.mesh_resource:
        embedded = getattr(getattr(msg, "mesh_file", None), "filename", "")
        return MarkerEvent(ADD, ns, marker_id, error=MarkerError(
            "mesh_resource", "a mesh URI (package://, file:// or a path inside the mesh "
            "roots; an embedded mesh_file is not read)",
            f"mesh_file {embedded!r}" if embedded else "an empty string"))
    return MarkerEvent(ADD, ns, marker_id, spec)


def _stamp(header: Any) -> tuple[int, int]:
    return int(header.stamp.sec), int(header.stamp.nanosec)


def _single(kind: str, header: Any, points: np.ndarray, rgba: tuple[float, ...]
            ) -> MarkerEvent:
    spec = MarkerSpec(kind=kind, frame=str(header.frame_id), points=points,
                      color=(rgba[0], rgba[1], rgba[2], rgba[3]), stamp=_stamp(header))
    return MarkerEvent(ADD, "", 0, spec)


def events_of(ros_type: str, msg: Any) -> list[MarkerEvent]:
    """The events of one message of a marker subscriber's type (worker thread)."""
    if ros_type == "visualization_msgs/msg/Marker":
        return [_marker(msg)]
    if ros_type == "visualization_msgs/msg/MarkerArray":
        return [_marker(m) for m in msg.markers]
    try:
        if ros_type == "nav_msgs/msg/Path":
            return [_single("path", msg.header,
                            _xyz([pose.pose.position for pose in msg.poses], "poses"),
                            PATH_RGBA)]
        if ros_type == "geometry_msgs/msg/PolygonStamped":
            return [_single("polygon", msg.header,
                            _xyz(msg.polygon.points, "polygon.points"), PATH_RGBA)]
        if ros_type == "geometry_msgs/msg/PointStamped":
            return [_single("point", msg.header, _xyz([msg.point], "point"),
                            POINT_RGBA)]
    except MarkerError as error:
        return [MarkerEvent(ADD, "", 0, error=error)]
    raise MarkerError("type", "a marker source type", ros_type)

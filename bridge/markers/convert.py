"""rclpy messages -> `MarkerEvent`s (duck-typed: this module imports no ROS package).

A Marker or MarkerArray gives one event per marker (in order: a DELETEALL then ADDs in
one array is the usual "replace everything" idiom); a Path, PolygonStamped or PointStamped
gives one "add" of the topic's single model (ns "", id 0).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional, Sequence

import numpy as np

from bridge.markers.geometry import (MAX_ARRAY_MARKERS, MAX_MARKER_POINTS, MarkerError,
                                     MarkerSpec, kind_of_type)

__all__ = ["ADD", "DELETE", "DELETEALL", "MarkerEvent", "check_array_size", "events_of",
           "marker_event"]

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


def marker_event(*, ns: str, marker_id: int, marker_type: int, action: int, frame: str,
                 numbers: Sequence[float], color: Sequence[float],
                 lifetime: tuple[int, int], frame_locked: bool, points: np.ndarray,
                 colors: Optional[np.ndarray], text: str, mesh_resource: str,
                 mesh_file: str, embedded: bool, stamp: tuple[int, int]) -> MarkerEvent:
    """One Marker's event from its values (``numbers``: position, orientation x y z w,
    scale); shared by the rclpy path (`events_of`) and the CDR reader."""
    kind_action = _ACTIONS.get(action)
    if kind_action is None:
        return MarkerEvent(ADD, ns, marker_id, error=MarkerError(
            "action", "ADD (0), MODIFY (1), DELETE (2) or DELETEALL (3)", str(action)))
    if kind_action != ADD:
        return MarkerEvent(kind_action, ns, marker_id)
    try:
        kind = kind_of_type(marker_type)
    except MarkerError as error:
        return MarkerEvent(ADD, ns, marker_id, error=error)
    if kind == "mesh_resource" and not mesh_resource:
        return MarkerEvent(ADD, ns, marker_id, error=MarkerError(
            "mesh_resource", "a mesh URI (package://, file:// or a path inside the mesh "
            "roots; an embedded mesh_file is not read)",
            f"mesh_file {mesh_file!r}" if mesh_file else "an empty string"))
    n = np.asarray(numbers, dtype=np.float64)
    spec = MarkerSpec(
        kind=kind, ns=ns, id=marker_id, frame=frame, position=n[0:3], orientation=n[3:7],
        scale=n[7:10], color=(float(color[0]), float(color[1]), float(color[2]),
                              float(color[3])),
        points=points, colors=colors, text=text, mesh_resource=mesh_resource,
        use_embedded_materials=embedded,
        lifetime_ns=max(0, int(lifetime[0]) * _NS_PER_S + int(lifetime[1])),
        frame_locked=frame_locked, stamp=stamp)
    return MarkerEvent(ADD, ns, marker_id, spec)


def _marker(msg: Any) -> MarkerEvent:
    ns, marker_id = str(msg.ns), int(msg.id)
    try:
        points = _xyz(msg.points, "points")
        colors = _rgba(msg.colors)
    except MarkerError as error:
        return MarkerEvent(ADD, ns, marker_id, error=error)
    p, q, s, c = msg.pose.position, msg.pose.orientation, msg.scale, msg.color
    return marker_event(
        ns=ns, marker_id=marker_id, marker_type=int(msg.type), action=int(msg.action),
        frame=str(msg.header.frame_id),
        numbers=(p.x, p.y, p.z, q.x, q.y, q.z, q.w, s.x, s.y, s.z),
        color=(c.r, c.g, c.b, c.a), lifetime=(msg.lifetime.sec, msg.lifetime.nanosec),
        frame_locked=bool(msg.frame_locked), points=points, colors=colors,
        text=str(msg.text), mesh_resource=str(msg.mesh_resource),
        mesh_file=str(getattr(getattr(msg, "mesh_file", None), "filename", "")),
        embedded=bool(msg.mesh_use_embedded_materials), stamp=_stamp(msg.header))


def _stamp(header: Any) -> tuple[int, int]:
    return int(header.stamp.sec), int(header.stamp.nanosec)


def _single(kind: str, header: Any, points: np.ndarray, rgba: tuple[float, ...]
            ) -> MarkerEvent:
    spec = MarkerSpec(kind=kind, frame=str(header.frame_id), points=points,
                      color=(rgba[0], rgba[1], rgba[2], rgba[3]), stamp=_stamp(header))
    return MarkerEvent(ADD, "", 0, spec)


def check_array_size(count: int) -> None:
    if count > MAX_ARRAY_MARKERS:
        raise MarkerError("markers", f"a MarkerArray of at most {MAX_ARRAY_MARKERS} markers "
                          "(the array is not shown)", f"{count} markers")


def events_of(ros_type: str, msg: Any) -> list[MarkerEvent]:
    """The events of one message of a marker subscriber's type (worker thread); raises
    `MarkerError` for a MarkerArray too large to show."""
    if ros_type == "visualization_msgs/msg/Marker":
        return [_marker(msg)]
    if ros_type == "visualization_msgs/msg/MarkerArray":
        check_array_size(len(msg.markers))
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

"""The scene planner: which MRML nodes the 3D Slicer module makes of what arrives, decided
without Slicer (so it is unit-tested here; slicer_module/ROS2Bridge only applies plans).

3D Slicer's OpenIGTLinkIF names each node after the device name and copies the message's
metadata onto it as attributes ``OpenIGTLink.<key>``. From those attributes the planner
says: what the node is (robot link transform, robot link model, tf lookup, subscriber...),
which transform it goes under, which subject-hierarchy folder it belongs to, a readable
name, and a colour. Node names are never changed: the connector finds its nodes again by
name after a reconnect, so renaming would duplicate them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

import numpy as np
import numpy.typing as npt

from protocol.naming import (KEY_CHILD, KEY_FRAME, KEY_LINK, KEY_MARKER_ID, KEY_MARKER_NS,
                             KEY_MARKER_TYPE, KEY_NODE, KEY_PARENT, KEY_PARENT_DEVICE,
                             KEY_POINT_COLORS, KEY_POSITION, KEY_ROBOT, KEY_ROLE, KEY_TOPIC,
                             KEY_TYPE, KEY_UNITS, KEY_VISUAL, NameKey, NamingError, Role,
                             device_name_for)

__all__ = ["ATTRIBUTE_PREFIX", "DEFAULT_COLOUR", "MARKERS_FOLDER", "NodePlan", "ROBOTS_FOLDER",
           "describe_bridges", "is_point_like", "link_metadata", "marker_folder",
           "metadata_from_attributes",
           "model_colour", "plan_node", "point_colours_differ", "robot_folder",
           "stale_marker_nodes", "vertex_per_point"]

ATTRIBUTE_PREFIX = "OpenIGTLink."
ROBOTS_FOLDER = "ROS2 robots"
MARKERS_FOLDER = "ROS2 markers"
DEFAULT_COLOUR: Tuple[float, float, float] = (0.7, 0.7, 0.7)
# Metadata keys a daemon may add for colours (r g b [a], each 0..1).
_COLOUR_KEYS = ("ros2.color", "ros2.colour", "ros2.rgba")
# Models drawn as points: a point cloud subscriber's (its ROS type) and POINTS-like markers
# (their ros2.marker_type). The daemon sends them as one polyvertex cell.
POINT_CLOUD_TYPES = ("sensor_msgs/msg/PointCloud2", "sensor_msgs/msg/PointCloud")
POINT_MARKER_TYPES = ("points", "point")

Rgb = Tuple[float, float, float]


@dataclass(frozen=True)
class NodePlan:
    device: str
    kind: str  # robot_link | robot_visual | robot_description | tf_lookup | subscriber | ...
    display_name: str
    parent_device: Optional[str] = None  # the transform node this node goes under
    folder: Optional[str] = None  # subject-hierarchy folder (one per robot)
    colour: Optional[Rgb] = None
    opacity: float = 1.0
    # Show the model's "RGBA" point colours as they are (scalars on, direct mapping): its
    # points differ in colour (a DAE's vertex colours, a marker's per-point colours).
    point_colours: bool = False
    # A text marker (a text node, not transformable): the module shows it as a markups
    # point labelled with the text, at this position (mm) under `label_parent`.
    label_position: Optional[Tuple[float, float, float]] = None
    label_parent: Optional[str] = None
    # A model of points (`is_point_like`): the module gives it one vertex per point again
    # each time the connector updates it (`vertex_per_point`).
    point_like: bool = False


def metadata_from_attributes(attributes: Mapping[str, str]) -> Dict[str, str]:
    """Node attributes -> the message metadata they came from (``OpenIGTLink.`` stripped)."""
    return {k[len(ATTRIBUTE_PREFIX):]: v for k, v in attributes.items()
            if k.startswith(ATTRIBUTE_PREFIX)}


def link_metadata(poses: Mapping[str, str], robot: str, link: str) -> Dict[str, str]:
    """The metadata of a robot link's transform node: its robot's TDATA (whose metadata
    `poses` is) makes one node per link but carries one metadata for all, so the module
    gives each link node what its own TRANSFORM would have carried."""
    metadata = {k: v for k, v in poses.items() if k in (KEY_FRAME, KEY_PARENT, KEY_UNITS)}
    metadata.update({KEY_ROLE: Role.ROBOT_LINK.value, KEY_ROBOT: robot, KEY_LINK: link})
    return metadata


def is_point_like(metadata: Mapping[str, str]) -> bool:
    """Whether a model node holds points drawn one by one: a point cloud subscriber's
    model or a POINTS / PointStamped marker's. The daemon sends their points as ONE
    polyvertex cell (protocol/polydata.py: OpenIGTLinkIO's converter crashes on a second
    vertex cell), of which the converter keeps the first point only: the module then
    gives each point its vertex again (`vertex_per_point`)."""
    role = metadata.get(KEY_ROLE)
    if role == Role.SUBSCRIBER.value:
        return metadata.get(KEY_TYPE) in POINT_CLOUD_TYPES
    if role == Role.MARKER.value:
        return metadata.get(KEY_MARKER_TYPE) in POINT_MARKER_TYPES
    return False


def vertex_per_point(npoints: int) -> Tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """The (offsets, connectivity) of a vtkCellArray of one vertex per point, for
    ``vtkCellArray.SetData``: offsets 0..n, connectivity 0..n-1 (no loop per point)."""
    return np.arange(npoints + 1, dtype=np.int64), np.arange(npoints, dtype=np.int64)


def robot_folder(robot: str) -> str:
    return f"robot {robot}"


def marker_folder(topic: str) -> str:
    return f"markers {topic}"


def stale_marker_nodes(nodes: Mapping[str, Mapping[str, str]],
                       live_by_topic: Mapping[str, Sequence[str]]) -> List[str]:
    """Marker nodes to remove: of `nodes` (node name = device -> its metadata), those of a
    role "marker" whose topic's latest list of live devices (`live_by_topic`, from the
    topic's ``ros2.markers``) does not hold them (DELETE, DELETEALL, lifetime expiry)."""
    stale = []
    for device, metadata in nodes.items():
        if metadata.get(KEY_ROLE) != Role.MARKER.value:
            continue
        live = live_by_topic.get(metadata.get(KEY_TOPIC, ""))
        if live is not None and device not in live:
            stale.append(device)
    return sorted(stale)


def _parse_colour(text: str) -> Optional[Tuple[Rgb, float]]:
    parts = text.replace(",", " ").split()
    try:
        values = [float(p) for p in parts]
    except ValueError:
        return None
    if len(values) not in (3, 4) or not all(0.0 <= v <= 1.0 for v in values):
        return None
    return (values[0], values[1], values[2]), (values[3] if len(values) == 4 else 1.0)


def model_colour(metadata: Mapping[str, str],
                 rgba_mean: Optional[Sequence[float]] = None) -> Tuple[Rgb, float]:
    """Colour and opacity of a model: metadata first, then the mean of the POLYDATA's RGBA
    point attribute (what the daemon sends for URDF materials), else light grey."""
    for key in _COLOUR_KEYS:
        if key in metadata:
            parsed = _parse_colour(metadata[key])
            if parsed is not None:
                return parsed
    if rgba_mean is not None and len(rgba_mean) >= 3:
        rgb = tuple(min(1.0, max(0.0, float(v))) for v in rgba_mean[:3])
        alpha = float(rgba_mean[3]) if len(rgba_mean) > 3 else 1.0
        return (rgb[0], rgb[1], rgb[2]), min(1.0, max(0.0, alpha))
    return DEFAULT_COLOUR, 1.0


def point_colours_differ(metadata: Mapping[str, str],
                         rgba: Optional[npt.ArrayLike] = None) -> bool:
    """Whether a model is shown with its "RGBA" point colours rather than one display
    colour: the array ((N, 3 or 4), 0..1) holds more than one distinct colour, or the
    daemon says so (``ros2.point_colors`` = ``1``, before the array is there). A mesh of
    one colour keeps its display colour: that colour, from `model_colour`."""
    if metadata.get(KEY_POINT_COLORS) == "1":
        return True
    rows = _rgba_rows(rgba)
    return rows is not None and bool(np.any(rows[1:] != rows[0]))


def _rgba_rows(rgba: Optional[npt.ArrayLike]) -> Optional[np.ndarray]:
    """The colour rows of an "RGBA" array, or None when there are none."""
    rows = None if rgba is None else np.asarray(rgba, dtype=np.float64)
    return rows if rows is not None and rows.ndim == 2 and len(rows) else None


def _link_device(robot: str, link: str,
                 link_devices: Optional[Mapping[Tuple[str, str], str]]) -> Optional[str]:
    if link_devices and (robot, link) in link_devices:
        return link_devices[(robot, link)]
    try:  # the daemon's deterministic name (a collision would lengthen the hash)
        return device_name_for(NameKey.robot_link(robot, link))
    except NamingError:
        return None


def plan_node(device: str, metadata: Mapping[str, str], *,
              rgba: Optional[npt.ArrayLike] = None,
              link_devices: Optional[Mapping[Tuple[str, str], str]] = None) -> NodePlan:
    """What to do with the node of `device`, given its metadata (see the module doc) and
    its model's "RGBA" point array (`rgba`, (N, 4), 0..1) if it has one. `link_devices`
    ((robot, link) -> device, from create_robot replies) wins over names computed here."""
    rows = _rgba_rows(rgba)
    rgba_mean = None if rows is None else [float(v) for v in rows.mean(axis=0)]
    role = metadata.get(KEY_ROLE, "")
    robot = metadata.get(KEY_ROBOT, "")
    link = metadata.get(KEY_LINK, "")
    if role == Role.ROBOT_LINK.value and robot and link:
        return NodePlan(device, "robot_link", f"{robot} {link}", folder=robot_folder(robot))
    if role == Role.ROBOT_VISUAL.value and robot and link:
        colour, opacity = model_colour(metadata, rgba_mean)
        index = metadata.get(KEY_VISUAL, "0")
        name = f"{robot} {link}" + (f" visual {index}" if index not in ("", "0") else "")
        return NodePlan(device, "robot_visual", name,
                        parent_device=_link_device(robot, link, link_devices),
                        folder=robot_folder(robot), colour=colour, opacity=opacity,
                        point_colours=point_colours_differ(metadata, rgba))
    if role == Role.ROBOT_POSES.value and robot:
        return NodePlan(device, "robot_poses", f"{robot} link poses",
                        folder=robot_folder(robot))
    if role == Role.ROBOT_DESCRIPTION.value and robot:
        return NodePlan(device, "robot_description", f"{robot} URDF",
                        folder=robot_folder(robot))
    if role == Role.MARKER.value and KEY_POSITION in metadata:
        try:
            x, y, z = (float(v) for v in metadata[KEY_POSITION].split())
        except ValueError:
            x = y = z = 0.0
        colour, opacity = model_colour(metadata)
        return NodePlan(device, "marker_text", f"{metadata.get(KEY_TOPIC, '?')} text "
                        f"{metadata.get(KEY_MARKER_NS, '')}/{metadata.get(KEY_MARKER_ID, '?')}",
                        folder=marker_folder(metadata.get(KEY_TOPIC, "?")), colour=colour,
                        opacity=opacity, label_position=(x, y, z),
                        label_parent=metadata.get(KEY_PARENT_DEVICE) or None)
    if role == Role.MARKER.value:
        colour, opacity = model_colour(metadata, rgba_mean)
        topic = metadata.get(KEY_TOPIC, "?")
        ns = metadata.get(KEY_MARKER_NS, "")
        name = (f"{topic} {ns + '/' if ns else ''}{metadata.get(KEY_MARKER_ID, '?')} "
                f"({metadata.get(KEY_MARKER_TYPE, '?')})")
        return NodePlan(device, "marker", name,
                        parent_device=metadata.get(KEY_PARENT_DEVICE) or None,
                        folder=marker_folder(topic), colour=colour, opacity=opacity,
                        point_colours=point_colours_differ(metadata, rgba),
                        point_like=is_point_like(metadata))
    if role == Role.MARKER_FRAME.value:
        return NodePlan(device, "marker_frame",
                        f"markers {metadata.get(KEY_PARENT, '?')} -> "
                        f"{metadata.get(KEY_CHILD, '?')}", folder=MARKERS_FOLDER)
    if role == Role.MARKER_TOPIC.value:
        return NodePlan(device, "marker_topic", f"markers of {metadata.get(KEY_TOPIC, '?')}",
                        folder=MARKERS_FOLDER)
    if role == Role.TF_LOOKUP.value:
        return NodePlan(device, "tf_lookup",
                        f"tf {metadata.get(KEY_PARENT, '?')} -> {metadata.get(KEY_CHILD, '?')}",
                        folder="ROS2 tf")
    if role == Role.SUBSCRIBER.value:
        kind = metadata.get(KEY_TYPE, "")
        return NodePlan(device, "subscriber",
                        f"{metadata.get(KEY_TOPIC, device)}" + (f" ({kind})" if kind else ""),
                        folder="ROS2 topics", point_like=is_point_like(metadata))
    if role == Role.PARAMETER_CLIENT.value:
        return NodePlan(device, "parameters", f"parameters of {metadata.get(KEY_NODE, '?')}",
                        folder="ROS2 parameters")
    return NodePlan(device, role or "other", device)


def describe_bridges(result: Mapping[str, Any]) -> List[str]:
    """list_bridges' result (``{"bridges": [{"kind": ...}], ...}``, protocol/README.md) ->
    one readable line per bridge, for the module's list."""
    lines: List[str] = []
    bridges = result.get("bridges")
    items = [b for b in bridges if isinstance(b, dict)] if isinstance(bridges, list) else []
    for b in items:
        kind = str(b.get("kind", "?"))
        if "topic" in b:
            what = f"{b['topic']} [{b.get('type', '?')}]"
        elif "parent" in b and "child" in b:
            what = f"{b['parent']} -> {b['child']}"
        elif "name" in b:
            what = str(b["name"])
        elif "node" in b:
            what = str(b["node"])
        elif "service" in b:
            what = str(b["service"])
        elif "action" in b:
            what = str(b["action"])
        else:
            what = "?"
        device = f" as {b['device']}" if b.get("device") else ""
        stale = f" (STALE: {b['stale']})" if b.get("stale") else ""
        lines.append(f"{kind}: {what}{device}{stale}")
    return lines


def stale_lines(resources: Iterable[Any]) -> List[str]:
    """A client's resources -> one line per stale stream (its publisher gone, or silent
    past its period), for the module's warning label; empty while all are live."""
    return [f"{r.topic} is stale: {r.stale}" for r in resources
            if getattr(r, "stale", "") and hasattr(r, "topic")]


def robot_status_lines(robots: Sequence[Any]) -> List[str]:
    """What the module shows under its robot controls: per robot its load progress (meshes
    received of expected) and each warning of its latest load. `robots` are
    `slicer_client.resources.Robot` objects (any with name, progress() and warnings)."""
    lines: List[str] = []
    for robot in robots:
        received, expected = robot.progress()
        if expected is None:
            lines.append(f"{robot.name}: waiting for its description")
        elif received < expected:
            lines.append(f"{robot.name}: {received} of {expected} meshes received (loading)")
        else:
            lines.append(f"{robot.name}: {received} of {expected} meshes received")
        lines.extend(f"  warning: {warning}" for warning in robot.warnings)
    return lines

"""What "Send to ROS" does with a Slicer node, without Slicer: the ROS types a node can
become, and how its data reaches the daemon through 3D Slicer's OpenIGTLink connector.

The connector (SlicerOpenIGTLink, vtkMRMLIGTLConnectorNode.cxx: its device-type table
and MRMLNodeToIGTL) sends a vtkMRMLModelNode as POLYDATA (the model's polydata) and a
vtkMRMLMarkupsFiducialNode as POINT (one element per control point, NAME = its label,
positions as stored); it has no converter for curve or line markups. So:

* a model -> a model node named as the publisher's device, holding the model's surface in
  world coordinates, triangulated (the daemon refuses triangle strips);
* point-list markups -> a point-list node of that name with the control points' world
  positions and labels -> POINT;
* a curve -> for ``nav_msgs/Path``, a model node with the curve's interpolated polyline
  (``GetCurveWorld``) -> POLYDATA lines; for PoseArray / PointStamped its control points;
* a line -> its two control points as POINT.

Node kinds are checked most specific first (a closed curve is a curve).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, Optional, Tuple

__all__ = ["KIND_ORDER", "SEND_TYPES", "SendPlan", "plan_send"]

MODEL = "vtkMRMLModelNode"
POINT_LIST = "vtkMRMLMarkupsFiducialNode"
CURVE = "vtkMRMLMarkupsCurveNode"
LINE = "vtkMRMLMarkupsLineNode"
MESH = "shape_msgs/msg/Mesh"
MARKER = "visualization_msgs/msg/Marker"
POSE_ARRAY = "geometry_msgs/msg/PoseArray"
POINT_STAMPED = "geometry_msgs/msg/PointStamped"
PATH = "nav_msgs/msg/Path"

# The node kinds "Send to ROS" takes, most specific first, and their ROS types (default
# first).
KIND_ORDER: Tuple[str, ...] = (CURVE, LINE, POINT_LIST, MODEL)
SEND_TYPES: Dict[str, Tuple[str, ...]] = {
    MODEL: (MESH, MARKER),
    POINT_LIST: (POSE_ARRAY, POINT_STAMPED, PATH),
    CURVE: (PATH, POSE_ARRAY, POINT_STAMPED),
    LINE: (PATH, POSE_ARRAY, POINT_STAMPED),
}


@dataclass(frozen=True)
class SendPlan:
    """``ros_type`` to publish; ``outgoing_class``: the connector node that carries it;
    ``source``: "surface" (a model's polydata), "curve" (a curve's polyline) or
    "control_points"; ``labels_topic``: where labels go (point types only)."""

    kind: str
    ros_type: str
    outgoing_class: str
    source: str
    labels_topic: Optional[str]


def plan_send(kind: str, topic: str, ros_type: Optional[str] = None) -> SendPlan:
    """The plan for a node of ``kind`` (one of `KIND_ORDER`) sent on ``topic``;
    ``ros_type`` None takes the kind's default. `ValueError` says what is possible."""
    types = SEND_TYPES.get(kind)
    if types is None:
        raise ValueError(f"Send to ROS takes a model or markups (point list, line, curve), "
                         f"not a {kind}")
    chosen = ros_type or types[0]
    if chosen not in types:
        raise ValueError(f"a {kind} goes to ROS as one of {', '.join(types)}, not {chosen}")
    if kind == MODEL:
        return SendPlan(kind, chosen, MODEL, "surface", None)
    labels = f"{topic.rstrip('/')}/labels" if chosen in (POSE_ARRAY, POINT_STAMPED) else None
    if kind == CURVE and chosen == PATH:
        return SendPlan(kind, chosen, MODEL, "curve", None)
    return SendPlan(kind, chosen, POINT_LIST, "control_points", labels)

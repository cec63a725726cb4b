"""Which codec serves which ROS type: the reference's type pairs, then generic JSON."""

from __future__ import annotations

from functools import cache

from bridge.codecs.base import TypeCodec
from bridge.codecs.geometry import PoseArrayCodec, PoseCodec, WrenchCodec
from bridge.codecs.image import ImageCodec
from bridge.codecs.json_codec import GenericJsonCodec
from bridge.codecs.pointcloud import PointCloud2Codec, PointCloudCodec
from bridge.codecs.registry import resolve_type
from bridge.codecs.scalars import (
    BoolCodec,
    EmptyCodec,
    Float64Codec,
    Int64Codec,
    MultiArrayCodec,
    StringCodec,
)
from bridge.codecs.sensors import JointStateCodec, JoyCodec
from bridge.codecs.slicer_data import MarkerCodec, MeshCodec, PathCodec, PointStampedCodec

__all__ = ["SPECIFIC_CODECS", "codec_for", "specific_types"]

_S, _T, _I, _P = "STRING", "TRANSFORM", "IMAGE", "POLYDATA"

SPECIFIC_CODECS: dict[str, TypeCodec] = {c.ros_type: c for c in (
    EmptyCodec("std_msgs/msg/Empty", _S),
    StringCodec("std_msgs/msg/String", _S),
    BoolCodec("std_msgs/msg/Bool", _S),
    Int64Codec("std_msgs/msg/Int64", _S),
    Float64Codec("std_msgs/msg/Float64", _S),
    MultiArrayCodec("std_msgs/msg/Int64MultiArray", _S, base="int64"),
    MultiArrayCodec("std_msgs/msg/Float64MultiArray", _S, base="double"),
    PoseCodec("geometry_msgs/msg/Pose", _T),
    PoseCodec("geometry_msgs/msg/PoseStamped", _T),
    PoseCodec("geometry_msgs/msg/TransformStamped", _T),
    WrenchCodec("geometry_msgs/msg/Wrench", _S),
    WrenchCodec("geometry_msgs/msg/WrenchStamped", _S),
    PoseArrayCodec("geometry_msgs/msg/PoseArray", _S),
    JointStateCodec("sensor_msgs/msg/JointState", _S),
    JoyCodec("sensor_msgs/msg/Joy", _S),
    ImageCodec("sensor_msgs/msg/Image", _I),
    PointCloud2Codec("sensor_msgs/msg/PointCloud2", _P),
    PointCloudCodec("sensor_msgs/msg/PointCloud", _P),
    # Slicer models and markups -> ROS (slicer_data.py).
    MeshCodec("shape_msgs/msg/Mesh", _P),
    MarkerCodec("visualization_msgs/msg/Marker", _S),
    PointStampedCodec("geometry_msgs/msg/PointStamped", _S),
    PathCodec("nav_msgs/msg/Path", _S),
)}


@cache
def codec_for(ros_type: str) -> TypeCodec:
    """The codec of a message type (any spelling `resolve_type` accepts): a specific one for
    the reference's types, else the generic JSON codec. `CodecError` if not installed."""
    canonical = resolve_type(ros_type)
    codec = SPECIFIC_CODECS.get(canonical)
    if codec is None:
        codec = GenericJsonCodec(canonical, _S)
    _ = codec.message_class  # fail now, not in a callback, if the class cannot load
    return codec


def specific_types() -> tuple[str, ...]:
    """The ROS types with a dedicated codec, sorted."""
    return tuple(sorted(SPECIFIC_CODECS))

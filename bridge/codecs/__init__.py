"""ROS message <-> OpenIGTLink body conversion for every type pair, plus generic JSON/YAML.

Public API::

    codec = codec_for("PoseStamped")          # any spelling resolve_type accepts
    body = codec.to_igtl(msg)                   # or codec.encode(msg) -> Encoded(...)
    msg = codec.from_igtl(body, stamp=(sec, ns), frame_id="map", metadata={...})
    value = codec.to_value(msg)                 # JSON-able "Slicer value"
    msg = codec.from_value(value, stamp=..., frame_id=...)
    text = codec.to_yaml(msg)                   # ros2 topic echo style

    resolve_type("vtkMRMLROS2SubscriberStringNode") -> "std_msgs/msg/String"
    message_to_dict / dict_to_message / message_to_json / json_to_message / message_to_yaml

Every failure is a `CodecError` (a protocol.errors.ProtocolError) with field, expected, got.
See README.md in this folder for the type table, units and metadata.
"""

from bridge.codecs.base import (
    KEY_ENCODING,
    KEY_FORMAT,
    KEY_LABELS,
    KEY_SHAPE,
    Encoded,
    TypeCodec,
)
from bridge.codecs.catalog import SPECIFIC_CODECS, codec_for, specific_types
from bridge.codecs.errors import CodecError
from bridge.codecs.generic import (
    dict_to_message,
    json_to_message,
    message_from_json,
    message_to_dict,
    message_to_json,
    message_to_yaml,
)
from bridge.codecs.registry import (
    REFERENCE_SHORT_NAMES,
    installed_types,
    message_class,
    resolve_type,
    ros_type_of,
)

__all__ = [
    "KEY_ENCODING",
    "KEY_FORMAT",
    "KEY_LABELS",
    "KEY_SHAPE",
    "REFERENCE_SHORT_NAMES",
    "SPECIFIC_CODECS",
    "CodecError",
    "Encoded",
    "TypeCodec",
    "codec_for",
    "dict_to_message",
    "installed_types",
    "json_to_message",
    "message_class",
    "message_from_json",
    "message_to_dict",
    "message_to_json",
    "message_to_yaml",
    "resolve_type",
    "ros_type_of",
    "specific_types",
]

"""What a received OpenIGTLink message means as a Python value (a subscriber's last value).

Driven by the message's metadata (``ros2.type``, ``ros2.format``) as the daemon writes it
(bridge/codecs/README.md): TRANSFORM -> 4x4 numpy matrix in mm; STRING -> str, or bool / int
/ float for std_msgs scalars, or the parsed JSON for ``ros2.format=json``; IMAGE -> numpy
pixels; POLYDATA and anything else -> the body itself.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from protocol.messages import Image, Message, String, Transform
from protocol.naming import KEY_FORMAT, KEY_TYPE

__all__ = ["value_from_message", "value_from_text"]

_TRUE = ("true", "1", "yes", "on")


def value_from_text(text: str, ros_type: str, text_format: str = "") -> Any:
    """A STRING body -> the value its ROS type means (the reference's Slicer types)."""
    if ros_type == "std_msgs/msg/Empty":
        return None
    if ros_type == "std_msgs/msg/Bool":
        return text.strip().lower() in _TRUE
    if ros_type == "std_msgs/msg/Int64":
        return int(text)
    if ros_type == "std_msgs/msg/Float64":
        return float(text)
    if text_format == "json":
        return json.loads(text)
    return text


def value_from_message(message: Message) -> Any:
    body = message.body
    if isinstance(body, Transform):
        return np.array(body.matrix, dtype=np.float64)
    if isinstance(body, String):
        return value_from_text(body.text, message.metadata.get(KEY_TYPE, ""),
                               message.metadata.get(KEY_FORMAT, ""))
    if isinstance(body, Image):
        return body.pixels
    return body

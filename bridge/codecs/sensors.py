"""sensor_msgs JointState and Joy <-> STRING JSON (the reference gives vtkTables)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from bridge.codecs.base import KEY_FORMAT, Body, TypeCodec, json_body, parse_json_text, string_text
from bridge.codecs.errors import CodecError
from bridge.codecs.generic import numeric_array

__all__ = ["JointStateCodec", "JoyCodec"]

_JOINT_ARRAYS = ("position", "velocity", "effort")


def _object(value: Any, where: str, keys: tuple[str, ...]) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise CodecError(field=where, expected="an object with " + ", ".join(keys),
                         got=type(value).__name__)
    unknown = sorted(set(value) - set(keys))
    if unknown:
        raise CodecError(field=f"{where}.{unknown[0]}", expected="one of " + ", ".join(keys),
                         got="an unknown key")
    return value


@dataclass(frozen=True)
class JointStateCodec(TypeCodec):
    """JointState <-> STRING JSON ``{"name": [...], "position": [...], "velocity": [...],
    "effort": [...]}`` (ROS units: rad or m, rad/s or m/s, N·m or N; no change: joint
    values are not Slicer lengths). Each array is empty or as long as ``name``."""

    def _to_value(self, msg: Any) -> Any:
        return {"name": list(msg.name), "position": msg.position.tolist(),
                "velocity": msg.velocity.tolist(), "effort": msg.effort.tolist()}

    def _to_igtl(self, msg: Any) -> tuple[Body, dict[str, str]]:
        return json_body(self._to_value(msg)), {KEY_FORMAT: "json"}

    def _from_igtl(self, body: Body, metadata: dict[str, str]) -> Any:
        return self._build(parse_json_text(string_text(body, self.ros_type)), "text")

    def _from_value(self, value: Any) -> Any:
        return self._build(value, "value")

    def _build(self, value: Any, where: str) -> Any:
        spec = _object(value, where, ("name",) + _JOINT_ARRAYS)
        names = spec.get("name", [])
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            raise CodecError(field=f"{where}.name", expected="a list of strings",
                             got=repr(names)[:60])
        msg = self.message_class()
        msg.name = list(names)
        for key in _JOINT_ARRAYS:
            arr = numeric_array(spec.get(key, []), f"{where}.{key}", "double")
            if arr.size not in (0, len(names)):
                raise CodecError(field=f"{where}.{key}", expected=f"0 or {len(names)} numbers "
                                 "(one per name)", got=f"{arr.size} numbers")
            getattr(msg, key).frombytes(arr.tobytes())
        return msg


@dataclass(frozen=True)
class JoyCodec(TypeCodec):
    """Joy <-> STRING JSON ``{"axes": [float...], "buttons": [int...]}``."""

    def _to_value(self, msg: Any) -> Any:
        return {"axes": msg.axes.tolist(), "buttons": msg.buttons.tolist()}

    def _to_igtl(self, msg: Any) -> tuple[Body, dict[str, str]]:
        return json_body(self._to_value(msg)), {KEY_FORMAT: "json"}

    def _from_igtl(self, body: Body, metadata: dict[str, str]) -> Any:
        return self._build(parse_json_text(string_text(body, self.ros_type)), "text")

    def _from_value(self, value: Any) -> Any:
        return self._build(value, "value")

    def _build(self, value: Any, where: str) -> Any:
        spec = _object(value, where, ("axes", "buttons"))
        msg = self.message_class()
        axes = numeric_array(spec.get("axes", []), f"{where}.axes", "float")
        buttons = numeric_array(spec.get("buttons", []), f"{where}.buttons", "int32")
        msg.axes.frombytes(axes.astype("=f4").tobytes())
        msg.buttons.frombytes(buttons.astype("=i4").tobytes())
        return msg


"""geometry_msgs: Pose, PoseStamped, TransformStamped (TRANSFORM, mm), Wrench and
WrenchStamped (STRING JSON of 6 numbers), PoseArray (STRING JSON list of 4x4 matrices, mm).

Units and rotations go through protocol.conversions only (metres <-> mm, quaternion <->
matrix, matrix validation). Values from Slicer are validated: NaN/inf, non-4x4, a last row
other than 0 0 0 1, a non-orthonormal rotation or a reflection raise `CodecError`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from bridge.codecs.base import (
    KEY_FORMAT,
    KEY_SHAPE,
    Body,
    TypeCodec,
    json_body,
    parse_json_text,
    string_text,
)
from bridge.codecs.errors import CodecError
from bridge.codecs.generic import numeric_array
from bridge.codecs.slicer_data import pose_array_from_points
from protocol.conversions import (
    ConversionError,
    matrix_to_pose,
    metres_to_mm,
    mm_to_metres,
    pose_to_matrix,
    quaternion_to_rotation,
    rotation_to_quaternion,
    validate_matrix,
)
from protocol.messages import Point as PointBody
from protocol.messages import Transform
from protocol.naming import KEY_CHILD, KEY_PARENT, KEY_UNITS, UNITS_MM

__all__ = [
    "PoseArrayCodec",
    "PoseCodec",
    "WrenchCodec",
    "checked_matrix",
    "matrix_to_pose_msg",
    "pose_msg_to_matrix",
]


def _finite(values: tuple[float, ...], field: str) -> None:
    # Per message on the hot path: plain floats, no numpy.
    if not all(math.isfinite(v) for v in values):
        raise CodecError(field=field, expected="finite numbers", got=repr(list(values)))


def pose_msg_to_matrix(position: Any, orientation: Any, where: str) -> np.ndarray:
    """A Point/Vector3 (m) and Quaternion -> 4x4 matrix in mm, or `CodecError` naming
    ``where.position``/``where.orientation``."""
    t = (position.x, position.y, position.z)
    q = (orientation.x, orientation.y, orientation.z, orientation.w)
    _finite(t, f"{where}.position" if where != "transform" else "transform.translation")
    _finite(q, f"{where}.orientation" if where != "transform" else "transform.rotation")
    try:
        return pose_to_matrix(t, q)
    except ConversionError as exc:  # a zero quaternion, or a translation beyond float32
        if exc.field == "translation":
            name = "transform.translation" if where == "transform" else f"{where}.position"
        else:
            name = "transform.rotation" if where == "transform" else f"{where}.orientation"
        raise CodecError(field=name, expected=exc.expected, got=exc.got) from None


def checked_matrix(value: Any, field: str) -> np.ndarray:
    """A 4x4 rigid transform in mm from JSON/body values, or `CodecError` naming ``field``."""
    if isinstance(value, (list, tuple)):
        value = numeric_array(value, field, "double", ndim=2)
    try:
        return validate_matrix(value, field=field)
    except ConversionError as exc:
        raise CodecError(field=exc.field, expected=exc.expected, got=exc.got) from None


def matrix_to_pose_msg(matrix_mm: np.ndarray) -> tuple[list[float], list[float]]:
    """A validated 4x4 mm matrix -> (translation m, quaternion xyzw) as Python floats."""
    t, q = matrix_to_pose(matrix_mm)
    return [float(x) for x in t], [float(x) for x in q]


def _set_pose(pose: Any, t: list[float], q: list[float]) -> None:
    pose.position.x, pose.position.y, pose.position.z = t
    o = pose.orientation
    o.x, o.y, o.z, o.w = q


def _set_transform(tf: Any, t: list[float], q: list[float]) -> None:
    tf.translation.x, tf.translation.y, tf.translation.z = t
    r = tf.rotation
    r.x, r.y, r.z, r.w = q


@dataclass(frozen=True)
class PoseCodec(TypeCodec):
    """Pose / PoseStamped / TransformStamped <-> TRANSFORM (4x4, translation in mm).

    Value: the 4x4 matrix in mm as nested lists (rows). TransformStamped's
    ``child_frame_id`` travels as metadata ``ros2.child`` (and header.frame_id as
    ``ros2.parent``); back, ``frame_id`` comes from the caller and ``child_frame_id`` from
    metadata ``ros2.child``.
    """

    def _matrix(self, msg: Any) -> np.ndarray:
        if self.ros_type.endswith("/TransformStamped"):
            tr = msg.transform
            return pose_msg_to_matrix(tr.translation, tr.rotation, "transform")
        pose = msg.pose if hasattr(msg, "pose") else msg
        return pose_msg_to_matrix(pose.position, pose.orientation,
                                  "pose" if hasattr(msg, "pose") else "value")

    def _to_igtl(self, msg: Any) -> tuple[Body, dict[str, str]]:
        meta = {KEY_UNITS: UNITS_MM}
        if self.ros_type.endswith("/TransformStamped"):
            if msg.header.frame_id:
                meta[KEY_PARENT] = msg.header.frame_id
            if msg.child_frame_id:
                meta[KEY_CHILD] = msg.child_frame_id
        return Transform(matrix=self._matrix(msg)), meta

    def _build(self, matrix: np.ndarray, child: str = "") -> Any:
        t, q = matrix_to_pose_msg(matrix)
        msg = self.message_class()
        if self.ros_type.endswith("/TransformStamped"):
            _set_transform(msg.transform, t, q)
            msg.child_frame_id = child
        elif hasattr(msg, "pose"):
            _set_pose(msg.pose, t, q)
        else:
            _set_pose(msg, t, q)
        return msg

    def _from_igtl(self, body: Body, metadata: dict[str, str]) -> Any:
        if not isinstance(body, Transform):
            raise CodecError(field="body", expected=f"an OpenIGTLink TRANSFORM (for "
                             f"{self.ros_type})", got=type(body).__name__)
        return self._build(checked_matrix(np.asarray(body.matrix, dtype=np.float64), "matrix"),
                           metadata.get(KEY_CHILD, ""))

    def _to_value(self, msg: Any) -> Any:
        return self._matrix(msg).tolist()

    def _from_value(self, value: Any) -> Any:
        child = ""
        if isinstance(value, dict) and self.ros_type.endswith("/TransformStamped"):
            unknown = sorted(set(value) - {"matrix", "child_frame_id"})
            if unknown:
                raise CodecError(field=f"value.{unknown[0]}",
                                 expected="matrix or child_frame_id", got="an unknown key")
            child = value.get("child_frame_id", "")
            if not isinstance(child, str):
                raise CodecError(field="value.child_frame_id", expected="a string",
                                 got=type(child).__name__)
            return self._build(checked_matrix(value.get("matrix"), "value.matrix"), child)
        return self._build(checked_matrix(value, "value"), child)


@dataclass(frozen=True)
class WrenchCodec(TypeCodec):
    """Wrench / WrenchStamped <-> STRING JSON ``[fx, fy, fz, tx, ty, tz]`` (N, N·m; the
    reference's vtkDoubleArray[6]). Not lengths: no unit change."""

    def _six(self, msg: Any) -> list[float]:
        w = msg.wrench if hasattr(msg, "wrench") else msg
        return [float(w.force.x), float(w.force.y), float(w.force.z),
                float(w.torque.x), float(w.torque.y), float(w.torque.z)]

    def _to_igtl(self, msg: Any) -> tuple[Body, dict[str, str]]:
        return json_body(self._six(msg)), {KEY_FORMAT: "json", KEY_SHAPE: "6"}

    def _from_igtl(self, body: Body, metadata: dict[str, str]) -> Any:
        return self._build(parse_json_text(string_text(body, self.ros_type)), "text")

    def _to_value(self, msg: Any) -> Any:
        return self._six(msg)

    def _from_value(self, value: Any) -> Any:
        return self._build(value, "value")

    def _build(self, value: Any, where: str) -> Any:
        arr = numeric_array(value, where, "double")
        if arr.size != 6:
            raise CodecError(field=where, expected="6 numbers fx, fy, fz, tx, ty, tz",
                             got=f"{arr.size} numbers")
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:
            raise CodecError(field=f"{where}[{int(bad[0])}]", expected="a finite number",
                             got=repr(float(arr[int(bad[0])])))
        msg = self.message_class()
        w = msg.wrench if hasattr(msg, "wrench") else msg
        w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y, w.torque.z = (
            float(x) for x in arr)
        return msg


@dataclass(frozen=True)
class PoseArrayCodec(TypeCodec):
    """PoseArray <-> STRING JSON list of 4x4 matrices (mm, rows), the reference's
    "collection of matrices". Vectorised over the poses with numpy. From Slicer, a POINT
    body (markups) is accepted too: one pose per point, identity orientation."""

    def _matrices(self, msg: Any) -> np.ndarray:
        n = len(msg.poses)
        if n == 0:
            return np.zeros((0, 4, 4))
        # One pass over the Python objects to gather numbers, then numpy for the rest.
        raw = np.array([(p.position.x, p.position.y, p.position.z, p.orientation.x,
                         p.orientation.y, p.orientation.z, p.orientation.w)
                        for p in msg.poses], dtype=np.float64)
        bad = np.argwhere(~np.isfinite(raw))
        if bad.size:
            i, j = int(bad[0][0]), int(bad[0][1])
            part = "position" if j < 3 else "orientation"
            raise CodecError(field=f"poses[{i}].{part}", expected="finite numbers",
                             got=repr(raw[i].tolist()))
        try:
            rot = quaternion_to_rotation(raw[:, 3:])
        except ConversionError as exc:
            raise CodecError(field="poses.orientation", expected=exc.expected,
                             got=exc.got) from None
        out = np.zeros((n, 4, 4))
        out[:, :3, :3] = rot
        out[:, :3, 3] = metres_to_mm(raw[:, :3])
        out[:, 3, 3] = 1.0
        return out

    def _to_igtl(self, msg: Any) -> tuple[Body, dict[str, str]]:
        mats = self._matrices(msg)
        return json_body(mats.tolist()), {KEY_FORMAT: "json", KEY_UNITS: UNITS_MM,
                                          KEY_SHAPE: f"{len(mats)}x4x4"}

    def _from_igtl(self, body: Body, metadata: dict[str, str]) -> Any:
        if isinstance(body, PointBody):  # Slicer markups: one pose per point
            return pose_array_from_points(self.message_class, body)
        return self._build(parse_json_text(string_text(body, self.ros_type)), "text")

    def _to_value(self, msg: Any) -> Any:
        return self._matrices(msg).tolist()

    def _from_value(self, value: Any) -> Any:
        return self._build(value, "value")

    def _build(self, value: Any, where: str) -> Any:
        from geometry_msgs.msg import Pose

        arr = numeric_array(value, where, "double", ndim=None)
        if arr.size == 0:
            return self.message_class()
        if arr.ndim != 3 or arr.shape[1:] != (4, 4):
            raise CodecError(field=where, expected="a list of 4x4 matrices",
                             got=f"shape {arr.shape}")
        for i in range(arr.shape[0]):  # validation names the bad matrix
            checked_matrix(arr[i], f"{where}[{i}]")
        quats = rotation_to_quaternion(arr[:, :3, :3])
        trans = mm_to_metres(arr[:, :3, 3])
        msg = self.message_class()
        poses = []
        for t, q in zip(trans.tolist(), quats.tolist()):
            p = Pose()
            _set_pose(p, t, q)
            poses.append(p)
        msg.poses = poses
        return msg


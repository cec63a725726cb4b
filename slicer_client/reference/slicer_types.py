"""What a reference subscriber's ``GetLastMessage()`` returns and its publisher's
``Publish()`` takes: the reference SlicerROS2's Slicer type for each of its names.

The name a node was made with decides, as in the reference, where ``IntArray`` and
``IntTable`` are the same ROS type:

| names | Slicer value | ROS type |
|---|---|---|
| Empty, String, Bool, Int, Double (Int64, Float, Float64) | "", str, bool, int, float | std_msgs |
| IntArray, DoubleArray (FloatArray) | vtkIntArray, vtkDoubleArray | Int64/Float64MultiArray, 1-D |
| IntTable, DoubleTable (IntNArray) | vtkTable, one column per array | the same, 2-D |
| Pose, Transform | vtkMatrix4x4, mm | geometry_msgs Pose, Transform |
| Wrench | vtkDoubleArray of 6 | geometry_msgs/Wrench |
| UInt8Image | vtkTypeUInt8Array (a row per tuple) | sensor_msgs/Image mono8 |
| PointCloud, PointCloud2 | vtkPoints, mm | sensor_msgs PointCloud, PointCloud2 |
| any other (PoseStamped, PoseArray, JointState, pkg/msg/Type) | a message object | that type |

Plain objects with the same methods stand in for VTK's where vtk does not import
(vtk_values.py). Every value except images and point clouds is made from the subscriber's
message stream (the whole message, lossless JSON); those two come from their IMAGE and
POLYDATA streams, which carry them whole already.
"""

from __future__ import annotations

import base64
import re
from typing import Any, Dict, List, Mapping, Optional, Tuple

import numpy as np

from protocol.messages import Image, Message, PolyData, String, Transform
from slicer_client.matrices import fill_vtk, is_vtk_matrix
from slicer_client.reference.messages import (MessageObject, MessageTypes, MessageValueError,
                                              array_of_vector6, matrix_of_pose, pose_of_matrix,
                                              vector6_of)
from slicer_client.reference.vtk_values import (SlicerValues, array_values, is_data_array,
                                                is_table, table_columns)

__all__ = ["Publication", "SlicerType", "slicer_type_for"]

# What a value becomes on the wire: ("message", whole message JSON) or ("value", the
# daemon's value form, for images and clouds).
Publication = Tuple[str, Any]

_CLASS_NAME = re.compile(r"vtkMRMLROS2(?:Subscriber|Publisher)([A-Za-z0-9]+)Node\Z")


class SlicerType:
    """One name's Slicer value: made from a whole message (`whole`) or from its native
    stream (IMAGE / POLYDATA; and, where no whole message comes, as over 3D Slicer's
    connector, the STRING / TRANSFORM of the simple types), and turned back into what
    `publish` takes."""

    whole = True

    def __init__(self, values: SlicerValues, ros_type: str) -> None:
        self.values = values
        self.ros_type = ros_type

    def from_ros(self, data: Mapping[str, Any]) -> Any:
        raise NotImplementedError

    def from_native(self, message: Message) -> Any:
        raise MessageValueError(
            f"GetLastMessage: a {self.ros_type} comes whole only in the daemon's message "
            f"stream, which this client's transport does not carry; read it with "
            f"slicer_client.connect()")

    def to_publish(self, value: Any) -> Publication:
        raise NotImplementedError

    def blank(self) -> Any:
        raise NotImplementedError


class _Empty(SlicerType):
    def from_ros(self, data: Mapping[str, Any]) -> Any:
        return ""

    def from_native(self, message: Message) -> Any:
        return ""

    def to_publish(self, value: Any) -> Publication:
        return "message", {}

    def blank(self) -> Any:
        return ""


class _Scalar(SlicerType):
    """std_msgs String, Bool, Int64, Float64: their one ``data`` field."""

    def __init__(self, values: SlicerValues, ros_type: str, kind: type) -> None:
        super().__init__(values, ros_type)
        self.kind = kind

    def from_ros(self, data: Mapping[str, Any]) -> Any:
        return self.kind(data["data"])

    def from_native(self, message: Message) -> Any:
        """Its STRING text, as the daemon writes it (bridge/codecs/scalars.py): lossless."""
        body = message.body
        if not isinstance(body, String):
            raise MessageValueError(f"GetLastMessage: expected a STRING for "
                                    f"{self.ros_type}, got {message.type_name}")
        text = body.text
        if self.kind is str:
            return text
        if self.kind is bool:
            return text.strip().lower() == "true"
        return self.kind(text.strip())

    def to_publish(self, value: Any) -> Publication:
        kind = self.kind
        ok = (isinstance(value, str) if kind is str else
              isinstance(value, (bool, np.bool_, int, np.integer)) if kind is bool else
              not isinstance(value, bool) and isinstance(value, (int, np.integer))
              if kind is int else
              not isinstance(value, bool) and isinstance(value, (int, float, np.number)))
        if not ok or (kind is int and not -(2**63) <= int(value) < 2**63):
            raise MessageValueError(f"Publish: expected {_KIND_WORDS[kind]} for "
                                    f"{self.ros_type}, got {value!r}")
        return "message", {"data": kind(value)}

    def blank(self) -> Any:
        return self.kind()


_KIND_WORDS = {str: "a string", bool: "true or false", int: "an integer in int64's range",
               float: "a number"}


class _Numbers(SlicerType):
    """Int64MultiArray (`integer`) or Float64MultiArray."""

    def __init__(self, values: SlicerValues, ros_type: str, integer: bool) -> None:
        super().__init__(values, ros_type)
        self.integer = integer


class _Array(_Numbers):
    """1-D: a vtkIntArray / vtkDoubleArray."""

    def from_ros(self, data: Mapping[str, Any]) -> Any:
        return self.values.filled_array(list(data.get("data", [])), integer=self.integer)

    def to_publish(self, value: Any) -> Publication:
        items = _numbers(value, "Publish", self.integer)
        return "message", {"layout": {"dim": [{"label": "x", "size": len(items), "stride": 1}],
                                      "data_offset": 0}, "data": items}

    def blank(self) -> Any:
        return self.values.int_array() if self.integer else self.values.double_array()


class _Table(_Numbers):
    """2-D: a vtkTable with one array per column."""

    def from_ros(self, data: Mapping[str, Any]) -> Any:
        dims = list(data.get("layout", {}).get("dim", []))
        table = self.values.table()
        if len(dims) != 2:
            return table  # as the reference: only a 2-D array fills a table
        rows, cols = int(dims[0]["size"]), int(dims[1]["size"])
        offset = int(data.get("layout", {}).get("data_offset", 0))
        flat = list(data.get("data", []))
        for j in range(cols):
            table.AddColumn(self.values.filled_array(
                [flat[offset + i * cols + j] for i in range(rows)], integer=self.integer))
        return table

    def to_publish(self, value: Any) -> Publication:
        if is_table(value):
            columns = [_numbers(c, "Publish", self.integer) for c in table_columns(value)]
            rows = len(columns[0]) if columns else 0
            if any(len(c) != rows for c in columns):
                raise MessageValueError("Publish: expected table columns of one length, got "
                                        f"{[len(c) for c in columns]}")
            grid = [[c[i] for c in columns] for i in range(rows)]
        else:
            grid = [_numbers(row, "Publish", self.integer) for row in value]
        rows, cols = len(grid), len(grid[0]) if grid else 0
        return "message", {"layout": {"dim": [{"label": "x", "size": rows, "stride": cols},
                                              {"label": "y", "size": cols, "stride": 1}],
                                      "data_offset": 0},
                           "data": [v for row in grid for v in row]}

    def blank(self) -> Any:
        return self.values.table()


class _Matrix(SlicerType):
    """geometry_msgs Pose / Transform: a 4x4 matrix in mm."""

    def __init__(self, values: SlicerValues, ros_type: str, where: str, how: str) -> None:
        super().__init__(values, ros_type)
        self.where, self.how = where, how

    def from_ros(self, data: Mapping[str, Any]) -> Any:
        return matrix_of_pose(self.values, data, self.where, self.how)

    def from_native(self, message: Message) -> Any:
        """Its TRANSFORM, already a 4x4 matrix in mm."""
        body = message.body
        if not isinstance(body, Transform):
            raise MessageValueError(f"GetLastMessage: expected a TRANSFORM for "
                                    f"{self.ros_type}, got {message.type_name}")
        return fill_vtk(np.asarray(body.matrix), self.values.matrix())

    def to_publish(self, value: Any) -> Publication:
        return "message", pose_of_matrix(value, self.where, self.how, path="Publish")

    def blank(self) -> Any:
        return self.values.matrix()


class _Vector6(SlicerType):
    """geometry_msgs Wrench: an array of 6 (force x y z, torque x y z)."""

    def __init__(self, values: SlicerValues, ros_type: str, first: str, second: str) -> None:
        super().__init__(values, ros_type)
        self.first, self.second = first, second

    def from_ros(self, data: Mapping[str, Any]) -> Any:
        return array_of_vector6(self.values, data, self.first, self.second)

    def to_publish(self, value: Any) -> Publication:
        six = _numbers(value, "Publish", False)
        if len(six) != 6:
            raise MessageValueError(f"Publish: expected 6 values for {self.ros_type}, got "
                                    f"{len(six)}")
        return "message", vector6_of(six, self.first, self.second)

    def blank(self) -> Any:
        return self.values.filled_array([0.0] * 6, integer=False)


class _Object(SlicerType):
    """Any other type: a message object (messages.py). A type with exactly one Pose or
    Transform field (PoseStamped, TransformStamped) also publishes a bare matrix, as the
    reference's first releases took."""

    def __init__(self, values: SlicerValues, ros_type: str, types: MessageTypes) -> None:
        super().__init__(values, ros_type)
        self.types = types

    def from_ros(self, data: Mapping[str, Any]) -> Any:
        return self.types.from_ros(self.ros_type, data)

    def to_publish(self, value: Any) -> Publication:
        if isinstance(value, MessageObject):
            if value.GetROSType() != self.ros_type:
                raise MessageValueError(f"Publish: expected a {self.ros_type} message, got a "
                                        f"{value.GetROSType()} one")
            return "message", value.to_ros()
        if isinstance(value, Mapping):
            return "message", dict(value)
        matrix_field = self._matrix_field()
        if matrix_field is not None and _matrix_like(value):
            message = self.types.new(self.ros_type)
            message._fields[matrix_field] = self.types.checked(
                message._description.field(matrix_field), value, f"Publish: {matrix_field}")
            return "message", message.to_ros()
        raise MessageValueError(f"Publish: expected a {self.ros_type} message object (from "
                                f"GetBlankMessage), got {type(value).__name__}")

    def _matrix_field(self) -> Optional[str]:
        description = self.types.message_class(self.ros_type)._description
        matrices = [f.name for f in description.fields if f.array is None and f.type in (
            "geometry_msgs/msg/Pose", "geometry_msgs/msg/Transform")]
        return matrices[0] if len(matrices) == 1 else None

    def blank(self) -> Any:
        return self.types.new(self.ros_type)


class _UInt8Image(SlicerType):
    """sensor_msgs/Image as the reference's UInt8Image: a vtkTypeUInt8Array with one tuple
    per row (its components: the row's bytes)."""

    whole = False

    def from_native(self, message: Message) -> Any:
        body = message.body
        if not isinstance(body, Image):
            return None
        pixels = np.ascontiguousarray(body.pixels)
        rows = pixels.shape[-3] if pixels.ndim >= 3 else 1
        flat = pixels.reshape(rows, -1).view(np.uint8)
        array = self.values.uint8_array()
        array.SetNumberOfComponents(flat.shape[1])
        array.SetNumberOfTuples(rows)
        for i, byte in enumerate(flat.reshape(-1).tolist()):
            array.SetValue(i, byte)
        return array

    def to_publish(self, value: Any) -> Publication:
        width, height = value.GetNumberOfComponents(), value.GetNumberOfTuples()
        data = bytes(int(v) for v in array_values(value))
        return "value", {"encoding": "mono8", "height": height, "width": width,
                         "data": base64.b64encode(data).decode("ascii")}

    def blank(self) -> Any:
        return self.values.uint8_array()


class _Pixels(SlicerType):
    """sensor_msgs/Image by any other name: the pixels as a numpy array (rows, columns,
    channels), as the Pythonic API gives them."""

    whole = False

    def from_native(self, message: Message) -> Any:
        body = message.body
        return np.asarray(body.pixels)[0] if isinstance(body, Image) else None

    def to_publish(self, value: Any) -> Publication:
        pixels = np.ascontiguousarray(value, dtype=np.uint8)
        channels = 1 if pixels.ndim == 2 else pixels.shape[2]
        encoding = {1: "mono8", 3: "rgb8", 4: "rgba8"}.get(channels)
        if encoding is None or pixels.ndim not in (2, 3):
            raise MessageValueError(f"Publish: expected uint8 pixels (rows, columns[, 1, 3 or "
                                    f"4 channels]), got shape {pixels.shape}")
        return "value", {"encoding": encoding, "height": pixels.shape[0],
                         "width": pixels.shape[1],
                         "data": base64.b64encode(pixels.tobytes()).decode("ascii")}

    def blank(self) -> Any:
        return np.zeros((0, 0), dtype=np.uint8)


class _Points(SlicerType):
    """sensor_msgs PointCloud / PointCloud2: vtkPoints in mm."""

    whole = False

    def from_native(self, message: Message) -> Any:
        body = message.body
        points = self.values.points()
        if isinstance(body, PolyData):
            for x, y, z in np.asarray(body.points, dtype=np.float64).reshape(-1, 3).tolist():
                points.InsertNextPoint(x, y, z)
        return points

    def to_publish(self, value: Any) -> Publication:
        if hasattr(value, "GetNumberOfPoints"):
            xyz = [value.GetPoint(i) for i in range(value.GetNumberOfPoints())]
        else:
            xyz = np.asarray(value, dtype=np.float64).reshape(-1, 3).tolist()
        return "value", {"points": [list(map(float, p)) for p in xyz]}

    def blank(self) -> Any:
        return self.values.points()


def _matrix_like(value: Any) -> bool:
    if is_vtk_matrix(value) or hasattr(value, "GetMatrixTransformToParent"):
        return True
    try:
        return bool(np.shape(value) == (4, 4))  # np.shape of Any is typed Any
    except ValueError:
        return False


def _numbers(value: Any, where: str, integer: bool) -> List[Any]:
    items = array_values(value) if is_data_array(value) else list(np.asarray(value).reshape(-1)
                                                                  .tolist())
    out: List[Any] = []
    for i, v in enumerate(items):
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise MessageValueError(f"{where}: expected numbers, got {v!r} at {i}")
        if integer and float(v) != int(v):
            raise MessageValueError(f"{where}: expected integers, got {v!r} at {i}")
        out.append(int(v) if integer else float(v))
    return out


# The reference's names (its class-name stems) -> how their values are made.
_BY_NAME: Dict[str, Any] = {
    "Empty": lambda v, t, _: _Empty(v, t),
    "String": lambda v, t, _: _Scalar(v, t, str),
    "Bool": lambda v, t, _: _Scalar(v, t, bool),
    "Int": lambda v, t, _: _Scalar(v, t, int),
    "Int64": lambda v, t, _: _Scalar(v, t, int),
    "Double": lambda v, t, _: _Scalar(v, t, float),
    "Float": lambda v, t, _: _Scalar(v, t, float),
    "Float64": lambda v, t, _: _Scalar(v, t, float),
    "IntArray": lambda v, t, _: _Array(v, t, True),
    "DoubleArray": lambda v, t, _: _Array(v, t, False),
    "FloatArray": lambda v, t, _: _Array(v, t, False),
    "IntTable": lambda v, t, _: _Table(v, t, True),
    "IntNArray": lambda v, t, _: _Table(v, t, True),
    "DoubleTable": lambda v, t, _: _Table(v, t, False),
    "Pose": lambda v, t, _: _Matrix(v, t, "position", "orientation"),
    "Transform": lambda v, t, _: _Matrix(v, t, "translation", "rotation"),
    "Wrench": lambda v, t, _: _Vector6(v, t, "force", "torque"),
    "UInt8Image": lambda v, t, _: _UInt8Image(v, t),
    "PointCloud": lambda v, t, _: _Points(v, t),
    "PointCloud2": lambda v, t, _: _Points(v, t),
}


def slicer_type_for(name: str, ros_type: str, types: MessageTypes, values: SlicerValues, *,
                    native_type: str = "") -> SlicerType:
    """The Slicer type of a node made with `name` (a short name, a reference class name or
    ``pkg/msg/Type``) for `ros_type`. `native_type`: the IGTL type its native stream
    carries, for a type the daemon streams whole only natively (an image, a cloud)."""
    match = _CLASS_NAME.match(name.strip())
    stem = match.group(1) if match else name.strip()
    make = _BY_NAME.get(stem)
    if make is not None:
        return make(values, ros_type, types)  # type: ignore[no-any-return]
    if native_type == "IMAGE":
        return _Pixels(values, ros_type)
    if native_type == "POLYDATA":
        return _Points(values, ros_type)
    return _Object(values, ros_type, types)


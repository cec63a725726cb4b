"""Message objects for any ROS type, built at run time from the daemon's description of it
(`describe_type`), with the reference SlicerROS2's accessor names.

The reference generates one VTK class per message type at build time
(``MRML/CodeGeneration``): ``vtkGeometryMsgsPoseArray`` with ``GetHeader()``,
``SetPoses(...)``, ``GetPoses()``. Here the same classes are made when a type is first
used, for every installed type the daemon knows, custom packages included:

* a field ``frame_id`` gets ``GetFrameId()`` / ``SetFrameId(value)`` (words capitalised);
* a nested message is an object of its own class (``GetHeader().GetStamp().SetSec(1)``),
  except the reference's VTK equivalents: ``geometry_msgs`` Pose and Transform are 4x4
  matrices in mm (a vtkMatrix4x4 in Slicer), Twist and Wrench arrays of 6 values;
* a sequence or fixed array is a tuple (of values, objects or matrices); setters take any
  sequence, numpy array or VTK data array;
* constants are class attributes (``vtkActionMsgsGoalStatus.STATUS_ACCEPTED``).

`to_ros` and `from_ros` convert between objects and the generic JSON of a whole message in
ROS units (metres, quaternions, base64 for byte arrays): what the daemon's message stream
carries and what ``publish`` with ``message`` takes.
"""

from __future__ import annotations

import base64
import binascii
import threading
from typing import Any, Callable, ClassVar, Dict, List, Mapping, Type, cast

import numpy as np

from protocol.commands import FieldDescription, MessageDescription, TypeDescription
from protocol.conversions import ConversionError, matrix_to_pose, pose_to_matrix
from slicer_client.matrices import MatrixError, as_numpy, fill_vtk, is_vtk_matrix
from slicer_client.reference.vtk_values import SlicerValues, array_values, is_data_array

__all__ = ["MessageObject", "MessageTypes", "MessageValueError", "accessor_name",
           "vtk_class_name"]

Describe = Callable[[str, str], TypeDescription]

# The reference's VTK equivalents of message types (its CodeGeneration/configForCodegen.py
# vtk_equivalent_types): fields of these types are a matrix or an array of 6, not objects.
_MATRIX_FIELDS = {"geometry_msgs/msg/Pose": ("position", "orientation"),
                  "geometry_msgs/msg/Transform": ("translation", "rotation")}
_VECTOR6_FIELDS = {"geometry_msgs/msg/Twist": ("linear", "angular"),
                   "geometry_msgs/msg/Wrench": ("force", "torque")}
_BYTE_TYPES = ("uint8", "byte", "char")
_INT_TYPES = ("byte", "char", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64",
              "uint64")
_FLOAT_TYPES = ("float32", "float64")


class MessageValueError(ValueError):
    """A value cannot be set into, or sent as, a message field; names the field, what was
    expected and what came."""


def accessor_name(field: str) -> str:
    """``frame_id`` -> ``FrameId``: the reference's getter/setter stem for a field."""
    return "".join(word.capitalize() for word in field.split("_"))


def vtk_class_name(ros_type: str) -> str:
    """``geometry_msgs/msg/PoseArray`` -> ``vtkGeometryMsgsPoseArray`` and
    ``turtlesim/srv/Spawn_Request`` -> ``vtkTurtlesimSpawnRequest``, as the reference names
    its generated classes."""
    package, _, name = ros_type.split("/")
    return "vtk" + accessor_name(package) + name.replace("_", "")


class MessageObject:
    """Base of the run-time message classes; each subclass holds one ROS type."""

    __slots__ = ("_fields",)
    _description: ClassVar[MessageDescription]
    _types: ClassVar[MessageTypes]

    def __init__(self) -> None:
        self._fields: Dict[str, Any] = self._types._blank_fields(self._description)

    @classmethod
    def _of(cls, fields: Dict[str, Any]) -> "MessageObject":
        """An instance holding `fields` (every field of its type, or `_FieldsFromRos`)."""
        obj = cls.__new__(cls)
        obj._fields = fields
        return obj

    @classmethod
    def GetROSType(cls) -> str:  # noqa: N802
        return cls._description.type

    def GetClassName(self) -> str:  # noqa: N802
        return type(self).__name__

    def to_ros(self) -> Dict[str, Any]:
        """This message as generic JSON in ROS units (what ``publish`` takes)."""
        return self._types.to_ros(self)

    def __eq__(self, other: object) -> bool:
        return type(other) is type(self) and self.to_ros() == other.to_ros()

    __hash__ = None  # type: ignore[assignment]  # mutable

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.to_ros()})"


class _FieldsFromRos(dict):  # type: ignore[type-arg]
    """A message object's fields, each converted from the message's generic JSON the first
    time it is read (or replaced when set): an observer that reads the pose of a
    PoseStamped at a display's rate converts the pose, not the header too."""

    __slots__ = ("_types", "_description", "_data")

    def __init__(self, types: MessageTypes, description: MessageDescription,
                 data: Mapping[str, Any]) -> None:
        super().__init__()
        self._types, self._description, self._data = types, description, data

    def __missing__(self, name: str) -> Any:
        f = self._description.field(name)  # KeyError for a name the type does not have
        raw = self._data[name] if name in self._data else self._description.default.get(name)
        value = self[name] = self._types._field_from_ros(f, raw, name)
        return value


class MessageTypes:
    """The run-time classes of one daemon's types, made once each. `describe(type, kind)`
    asks the daemon (the client's cached `describe_type`)."""

    def __init__(self, describe: Describe, values: SlicerValues) -> None:
        self._describe = describe
        self.values = values
        self._messages: Dict[str, MessageDescription] = {}
        self._classes: Dict[str, Type[MessageObject]] = {}
        self._lock = threading.Lock()

    # --- types ----------------------------------------------------------------------------
    def description(self, type_name: str, kind: str = "message") -> TypeDescription:
        """The daemon's description of a type; its message types become known here."""
        described = self._describe(type_name, kind)
        with self._lock:
            for name, message in described.messages.items():
                self._messages.setdefault(name, message)
        return described

    def message_class(self, ros_type: str) -> Type[MessageObject]:
        """The class of a message type (``pkg/msg/Type``, or a service or action part such
        as ``turtlesim/srv/Spawn_Request``), described first if need be."""
        cls = self._classes.get(ros_type)
        if cls is not None:
            return cls
        description = self.message(ros_type)
        with self._lock:
            cls = self._classes.get(ros_type)
            if cls is None:
                cls = self._make_class(description)
                self._classes[ros_type] = cls
        return cls

    def message(self, ros_type: str) -> MessageDescription:
        """The description of one message type (or service or action part)."""
        found = self._messages.get(ros_type)
        if found is None:
            self.description(ros_type)  # a part is only known through its interface
            found = self._messages.get(ros_type)
            if found is None:
                raise MessageValueError(f"{ros_type}: expected a message type the daemon "
                                        f"describes, got none by that name")
        return found

    def new(self, ros_type: str) -> MessageObject:
        """A message of `ros_type` with every field at its default (a blank message)."""
        return self.message_class(ros_type)()

    def _make_class(self, description: MessageDescription) -> Type[MessageObject]:
        namespace: Dict[str, Any] = {"__slots__": (), "_description": description,
                                     "_types": self}
        for f in description.fields:
            stem = accessor_name(f.name)
            namespace[f"Get{stem}"] = _getter(f.name)
            namespace[f"Set{stem}"] = _setter(self, f)
        for name, value in description.constants.items():
            namespace.setdefault(name, value)
        # type() with 3 arguments is typed as plain `type`; its only base is MessageObject.
        return cast(Type[MessageObject],
                    type(vtk_class_name(description.type), (MessageObject,), namespace))

    # --- blank values ------------------------------------------------------------------------
    def _blank_fields(self, description: MessageDescription) -> Dict[str, Any]:
        return {f.name: self._field_from_ros(f, description.default.get(f.name), f.name)
                for f in description.fields}

    # --- JSON in ROS units -> objects --------------------------------------------------------
    def from_ros(self, ros_type: str, data: Mapping[str, Any]) -> MessageObject:
        """A message object from the generic JSON of a whole message (a field it lacks
        takes its default)."""
        cls = self.message_class(ros_type)
        if not isinstance(data, Mapping):
            raise MessageValueError(f"{ros_type}: expected an object of its fields, got "
                                    f"{type(data).__name__}")
        # Each field converted when first read (a subscriber's GetLastMessage runs this at a
        # display's rate on 3D Slicer's main thread, and its observer reads one field).
        return cls._of(_FieldsFromRos(self, cls._description, data))

    def _field_from_ros(self, f: FieldDescription, raw: Any, path: str) -> Any:
        if f.array is None:
            return self._single_from_ros(f.type, raw, path)
        if f.type in _BYTE_TYPES and isinstance(raw, str):
            try:
                return tuple(base64.b64decode(raw, validate=True))
            except (binascii.Error, ValueError):
                raise MessageValueError(f"{path}: expected base64 bytes, got {raw[:20]!r}") \
                    from None
        return tuple(self._single_from_ros(f.type, item, f"{path}[{i}]")
                     for i, item in enumerate(raw or ()))

    def _single_from_ros(self, type_name: str, raw: Any, path: str) -> Any:
        if "/" not in type_name:
            return float(raw) if type_name in _FLOAT_TYPES and raw is not None else raw
        if type_name in _MATRIX_FIELDS:
            where, how = _MATRIX_FIELDS[type_name]
            try:
                return matrix_of_pose(self.values, raw, where, how)
            except (KeyError, TypeError, ValueError):
                raise MessageValueError(
                    f"{path}: expected a {type_name} ({where} x y z, {how} x y z w), got "
                    f"{str(raw)[:80]}") from None
        if type_name in _VECTOR6_FIELDS:
            return array_of_vector6(self.values, raw, *_VECTOR6_FIELDS[type_name])
        return self.from_ros(type_name, raw)

    def for_yaml(self, ros_type: str, data: Mapping[str, Any]) -> Dict[str, Any]:
        """The generic JSON of a message as ``ros2 topic echo`` shows it: byte arrays as
        lists of numbers instead of base64 (the daemon's own YAML does the same)."""
        description = self.message(ros_type)
        out: Dict[str, Any] = {}
        for f in description.fields:
            raw = data.get(f.name)
            if f.array is not None and f.type in _BYTE_TYPES and isinstance(raw, str):
                out[f.name] = list(base64.b64decode(raw))
            elif "/" in f.type and f.array is None and isinstance(raw, Mapping):
                out[f.name] = self.for_yaml(f.type, raw)
            elif "/" in f.type and isinstance(raw, list):
                out[f.name] = [self.for_yaml(f.type, item) for item in raw]
            else:
                out[f.name] = raw
        return out

    # --- objects -> JSON in ROS units --------------------------------------------------------
    def to_ros(self, obj: MessageObject) -> Dict[str, Any]:
        description = obj._description
        return {f.name: self._field_to_ros(f, obj._fields[f.name], f.name)
                for f in description.fields}

    def _field_to_ros(self, f: FieldDescription, value: Any, path: str) -> Any:
        if f.array is None:
            return self._single_to_ros(f.type, value, path)
        if f.type in _BYTE_TYPES:
            return base64.b64encode(bytes(int(v) for v in value)).decode("ascii")
        return [self._single_to_ros(f.type, item, f"{path}[{i}]") for i, item in
                enumerate(value)]

    def _single_to_ros(self, type_name: str, value: Any, path: str) -> Any:
        if "/" not in type_name:
            return value
        if type_name in _MATRIX_FIELDS:
            return pose_of_matrix(value, *_MATRIX_FIELDS[type_name], path=path)
        if type_name in _VECTOR6_FIELDS:
            six = array_values(value) if is_data_array(value) else list(value)
            if len(six) != 6:  # the reference sends zeros for anything but 6 values
                six = [0.0] * 6
            return vector6_of(six, *_VECTOR6_FIELDS[type_name])
        if isinstance(value, MessageObject):
            return value.to_ros()
        if isinstance(value, Mapping):  # already generic JSON
            return dict(value)
        raise MessageValueError(f"{path}: expected a {vtk_class_name(type_name)} object, got "
                                f"{type(value).__name__}")

    # --- setters --------------------------------------------------------------------------
    def checked(self, f: FieldDescription, value: Any, path: str) -> Any:
        """A value for field `f` as the object keeps it, or `MessageValueError`."""
        if f.array is None:
            return self._checked_single(f.type, value, path, f)
        items = _sequence(value, path)
        if f.array == "fixed" and len(items) != f.size:
            raise MessageValueError(f"{path}: expected {f.size} values, got {len(items)}")
        if f.array == "sequence" and f.size is not None and len(items) > f.size:
            raise MessageValueError(f"{path}: expected at most {f.size} values, got "
                                    f"{len(items)}")
        return tuple(self._checked_single(f.type, item, f"{path}[{i}]", f)
                     for i, item in enumerate(items))

    def _checked_single(self, type_name: str, value: Any, path: str,
                        f: FieldDescription) -> Any:
        if type_name in _INT_TYPES:
            if isinstance(value, (bytes, str)) and len(value) == 1:
                value = ord(value)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer, float)) \
                    or float(value) != int(value):
                raise MessageValueError(f"{path}: expected an integer, got {value!r}")
            return int(value)
        if type_name in _FLOAT_TYPES:
            if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
                raise MessageValueError(f"{path}: expected a number, got {value!r}")
            return float(value)
        if type_name == "bool":
            if not isinstance(value, (bool, np.bool_, int)):
                raise MessageValueError(f"{path}: expected true or false, got {value!r}")
            return bool(value)
        if type_name in ("string", "wstring"):
            if not isinstance(value, str):
                raise MessageValueError(f"{path}: expected a string, got {value!r}")
            if f.string_max is not None and len(value) > f.string_max:
                raise MessageValueError(f"{path}: expected at most {f.string_max} "
                                        f"characters, got {len(value)}")
            return value
        if type_name in _MATRIX_FIELDS:
            if not is_vtk_matrix(value):
                try:
                    value = fill_vtk(as_numpy(value, field=path, rigid=False),
                                     self.values.matrix())
                except MatrixError as error:
                    raise MessageValueError(str(error)) from None
            return value
        if type_name in _VECTOR6_FIELDS:
            if not is_data_array(value):
                value = self.values.filled_array(_sequence(value, path), integer=False)
            return value
        cls = self.message_class(type_name)
        if isinstance(value, cls):
            return value
        if isinstance(value, Mapping):
            return self.from_ros(type_name, value)
        raise MessageValueError(f"{path}: expected a {cls.__name__}, got "
                                f"{type(value).__name__}")


def _getter(name: str) -> Callable[[MessageObject], Any]:
    def get(self: MessageObject) -> Any:
        return self._fields[name]
    get.__name__ = f"Get{accessor_name(name)}"
    return get


def _setter(types: MessageTypes, f: FieldDescription) -> Callable[[MessageObject, Any], None]:
    def set_(self: MessageObject, value: Any) -> None:
        self._fields[f.name] = types.checked(f, value, f"{type(self).__name__}.{f.name}")
    set_.__name__ = f"Set{accessor_name(f.name)}"
    return set_


def _sequence(value: Any, path: str) -> List[Any]:
    if is_data_array(value):
        return array_values(value)
    if isinstance(value, (str, bytes, bytearray)) or not hasattr(value, "__iter__"):
        if isinstance(value, (bytes, bytearray)):
            return list(value)
        raise MessageValueError(f"{path}: expected a sequence, got {type(value).__name__}")
    return list(value)


# --- the reference's VTK equivalents, one conversion each way (messages and slicer_types) ---
def matrix_of_pose(values: SlicerValues, data: Mapping[str, Any], where: str,
                   how: str) -> Any:
    """A Pose (``where`` position, ``how`` orientation) or Transform dict in metres -> a
    4x4 matrix in mm."""
    matrix = pose_to_matrix([data[where][k] for k in "xyz"], [data[how][k] for k in "xyzw"])
    return fill_vtk(matrix, values.matrix())


def pose_of_matrix(value: Any, where: str, how: str, *, path: str) -> Dict[str, Any]:
    """A 4x4 matrix in mm (rotation orthonormal within the protocol's tolerance) -> a
    Pose or Transform dict in metres, with the nearest quaternion."""
    try:
        translation, quaternion = matrix_to_pose(as_numpy(value, field=path, rigid=False))
    except (ConversionError, MatrixError) as error:
        raise MessageValueError(f"{path}: {error}") from None
    return {where: dict(zip("xyz", map(float, translation))),
            how: dict(zip("xyzw", map(float, quaternion)))}


def array_of_vector6(values: SlicerValues, data: Mapping[str, Any], first: str,
                     second: str) -> Any:
    """A Twist or Wrench dict -> an array of its 6 values."""
    return values.filled_array([data[first][k] for k in "xyz"]
                               + [data[second][k] for k in "xyz"], integer=False)


def vector6_of(six: List[Any], first: str, second: str) -> Dict[str, Any]:
    return {first: dict(zip("xyz", map(float, six[:3]))),
            second: dict(zip("xyz", map(float, six[3:])))}

"""ROS interface type names: the one grammar every part of the project resolves them with.

Accepted spellings of a message type: ``pkg/msg/Type`` (canonical), ``pkg/Type``,
``pkg.msg.Type``, a short name of the reference SlicerROS2 (``PoseStamped``, ``Int``), a
reference node class name (``vtkMRMLROS2SubscriberStringNode``), and, where the caller can
look installed packages up (the daemon, `bridge.codecs.registry`), any other bare message
name found in exactly one package. Services: ``pkg/srv/Type`` or ``pkg/Type``; actions:
``pkg/action/Type`` or ``pkg/Type``.
"""

from __future__ import annotations

import difflib
import re
from typing import Callable, Iterable, Optional, Sequence

from protocol.commands.errors import OutOfRangeError, UnknownTypeError

__all__ = ["REFERENCE_SERVICE_NAMES", "REFERENCE_TYPE_NAMES", "PackagesOf",
           "check_message_type", "resolve_action_type", "resolve_message_type",
           "resolve_service_type", "unknown_type"]

# A bare message name -> the installed packages that define it.
PackagesOf = Callable[[str], Sequence[str]]

# The reference SlicerROS2's short names (and its class-name stems) -> ROS message type.
# Several share a type (a vtkTable and a vtkDoubleArray both travel as Float64MultiArray).
REFERENCE_TYPE_NAMES: dict[str, str] = {
    "Empty": "std_msgs/msg/Empty",
    "String": "std_msgs/msg/String",
    "Bool": "std_msgs/msg/Bool",
    "Int": "std_msgs/msg/Int64",
    "Int64": "std_msgs/msg/Int64",
    "Double": "std_msgs/msg/Float64",
    "Float": "std_msgs/msg/Float64",
    "Float64": "std_msgs/msg/Float64",
    "IntArray": "std_msgs/msg/Int64MultiArray",
    "IntTable": "std_msgs/msg/Int64MultiArray",
    "IntNArray": "std_msgs/msg/Int64MultiArray",
    "Int64MultiArray": "std_msgs/msg/Int64MultiArray",
    "DoubleArray": "std_msgs/msg/Float64MultiArray",
    "FloatArray": "std_msgs/msg/Float64MultiArray",
    "DoubleTable": "std_msgs/msg/Float64MultiArray",
    "Float64MultiArray": "std_msgs/msg/Float64MultiArray",
    "Pose": "geometry_msgs/msg/Pose",
    "PoseStamped": "geometry_msgs/msg/PoseStamped",
    "PoseArray": "geometry_msgs/msg/PoseArray",
    "Transform": "geometry_msgs/msg/Transform",
    "TransformStamped": "geometry_msgs/msg/TransformStamped",
    "Wrench": "geometry_msgs/msg/Wrench",
    "WrenchStamped": "geometry_msgs/msg/WrenchStamped",
    "Point": "geometry_msgs/msg/Point",
    "PointStamped": "geometry_msgs/msg/PointStamped",
    "JointState": "sensor_msgs/msg/JointState",
    "Joy": "sensor_msgs/msg/Joy",
    "JoyV2": "sensor_msgs/msg/Joy",
    "Image": "sensor_msgs/msg/Image",
    "UInt8Image": "sensor_msgs/msg/Image",
    "PointCloud": "sensor_msgs/msg/PointCloud",
    "PointCloud2": "sensor_msgs/msg/PointCloud2",
}
# The reference's service client class names (``vtkMRMLROS2ServiceClient<Name>Node``): the
# services its build generates a client for, and its hand-written SetBool client.
REFERENCE_SERVICE_NAMES: dict[str, str] = {
    **{name: f"rosbag2_interfaces/srv/{name}" for name in (
        "Burst", "GetRate", "IsPaused", "Pause", "Play", "PlayNext", "Resume", "Seek",
        "SetRate", "Snapshot", "SplitBagfile", "Stop", "TogglePaused")},
    **{name: f"moveit_msgs/srv/{name}" for name in (
        "GetPositionFK", "GetPositionIK", "GetCartesianPath")},
    "Spawn": "turtlesim/srv/Spawn",
    "SetBoolString": "std_srvs/srv/SetBool",
}
_PKG = r"[a-z][a-z0-9_]*"
_NAME = r"[A-Z][A-Za-z0-9]*"
_SPELLINGS = (re.compile(rf"({_PKG})/msg/({_NAME})\Z"), re.compile(rf"({_PKG})/({_NAME})\Z"),
              re.compile(rf"({_PKG})\.msg\.({_NAME})\Z"))
_SERVICE = re.compile(rf"({_PKG})/(?:srv/)?({_NAME})\Z")
_ACTION = re.compile(rf"({_PKG})/(?:action/)?({_NAME})\Z")
_BARE = re.compile(rf"{_NAME}\Z")
_CLASS_NAME = re.compile(r"vtkMRMLROS2(?:Subscriber|Publisher)([A-Za-z0-9]+)Node\Z")
_SERVICE_CLASS_NAME = re.compile(r"vtkMRMLROS2ServiceClient([A-Za-z0-9]+)Node\Z")
_EXPECTED = "pkg/msg/Type, pkg/Type, or a short name such as String or PoseStamped"


def resolve_message_type(text: str, field: str = "type", *,
                         packages_of: Optional[PackagesOf] = None,
                         known: Iterable[str] = ()) -> str:
    """Any accepted spelling (see the module) -> ``pkg/msg/Type``; `UnknownTypeError`
    naming `field` otherwise, with the closest of the short names and ``known`` (the
    caller's installed names). A bare name other than a short name needs `packages_of`."""
    if not isinstance(text, str):
        raise OutOfRangeError(field, _EXPECTED, type(text).__name__)
    given = text.strip()
    stem = _stem(given)
    if stem in REFERENCE_TYPE_NAMES:
        return REFERENCE_TYPE_NAMES[stem]
    for spelling in _SPELLINGS:
        full = spelling.match(given)
        if full:
            return f"{full.group(1)}/msg/{full.group(2)}"
    found = _by_package(stem, "msg", packages_of, field)
    if found is not None:
        return found
    raise unknown_type(field, _EXPECTED, given, (*REFERENCE_TYPE_NAMES, *known))


def check_message_type(text: str, field: str = "type") -> None:
    """Refuse what no look-up could make a message type. A bare name that is not a short
    name (``Float32``) passes: only the daemon can look it up among its installed
    packages (`resolve_message_type` with `packages_of`), so a client or a request's parse
    leaves it to the daemon."""
    if isinstance(text, str) and _BARE.match(_stem(text.strip())):
        return
    resolve_message_type(text, field)


def unknown_type(field: str, expected: str, given: str,
                 known: Iterable[str]) -> UnknownTypeError:
    """The error for a type name that names no type, with the closest of ``known``."""
    close = difflib.get_close_matches(given, list(known), n=1, cutoff=0.6)
    hint = f" (did you mean {close[0]}?)" if close else ""
    return UnknownTypeError(field, expected, f"{given!r}{hint}")


def _stem(given: str) -> str:
    """The type part of a reference node class name (``vtkMRMLROS2SubscriberStringNode``
    -> ``String``), else the name as given."""
    class_match = _CLASS_NAME.match(given)
    return class_match.group(1) if class_match else given


def _by_package(stem: str, kind: str, packages_of: Optional[PackagesOf],
                field: str) -> Optional[str]:
    """``pkg/<kind>/stem`` if exactly one installed package defines the bare name `stem`;
    None if none does (or nothing can look them up); an ambiguous name raises."""
    if packages_of is None or not _BARE.match(stem):
        return None
    packages = tuple(packages_of(stem))
    if len(packages) > 1:
        raise OutOfRangeError(field, "an unambiguous name; spell one of "
                              + ", ".join(f"{p}/{kind}/{stem}" for p in packages), repr(stem))
    return f"{packages[0]}/{kind}/{stem}" if packages else None


def resolve_service_type(text: str, field: str = "type", *,
                         packages_of: Optional[PackagesOf] = None) -> str:
    """``pkg/srv/Type``, ``pkg/Type``, a reference service client class name
    (``vtkMRMLROS2ServiceClientSpawnNode``) or its stem (``Spawn``) -> ``pkg/srv/Type``;
    with `packages_of` (services installed by bare name), any bare name defined by exactly
    one package."""
    given = text.strip() if isinstance(text, str) else None
    full = _SERVICE.match(given) if given is not None else None
    if full:
        return f"{full.group(1)}/srv/{full.group(2)}"
    expected = "a service type pkg/srv/Type or a reference service client class name"
    if given is None:
        raise OutOfRangeError(field, expected, repr(text))
    class_match = _SERVICE_CLASS_NAME.match(given)
    stem = class_match.group(1) if class_match else given
    if stem in REFERENCE_SERVICE_NAMES:
        return REFERENCE_SERVICE_NAMES[stem]
    found = _by_package(stem, "srv", packages_of, field)
    if found is not None:
        return found
    raise OutOfRangeError(field, expected, repr(text))


def resolve_action_type(text: str, field: str = "type") -> str:
    """``pkg/action/Type`` or ``pkg/Type`` -> ``pkg/action/Type``."""
    full = _ACTION.match(text.strip()) if isinstance(text, str) else None
    if full:
        return f"{full.group(1)}/action/{full.group(2)}"
    raise OutOfRangeError(field, "an action type pkg/action/Type", repr(text))

"""Hypothesis strategies for every op, derived from the op classes themselves: each field's
strategy comes from its type (``bool``, ``QoS``, ``Stamp``, ``X | None``, ``tuple[str, ...]``
...), its values from what its name means where the type cannot say (a ``topic`` is a ROS
name, a ``parent`` a tf frame), and a few ops override one field where the parser allows
less than the name suggests (a range, a type family). Each op's own examples
(`Op.examples`) are drawn too. A new op needs nothing here unless a field of a new kind
has no strategy: `strategy_for` then fails naming the op and the field."""

from __future__ import annotations

import math
import types
import typing
from dataclasses import MISSING, fields
from typing import Any, Callable, Optional, Union

from hypothesis import strategies as st

from protocol import commands as c
from protocol.commands import Op, ParameterValue

__all__ = ["NoStrategyError", "json_values", "strategy_for"]

# ---------------------------------------------------------------- values

_ident = st.from_regex(r"[A-Za-z_][A-Za-z0-9_]{0,12}", fullmatch=True)
ros_names = st.builds(
    lambda lead, parts: lead + "/".join(parts), st.sampled_from(["", "/"]),
    st.lists(_ident, min_size=1, max_size=4))
frames = st.text(min_size=1, max_size=30).filter(
    lambda s: "\x00" not in s and s.strip() == s and s != "")
param_names = st.from_regex(r"[A-Za-z_][A-Za-z0-9_.]{0,20}", fullmatch=True)
robot_names = st.from_regex(r"[A-Za-z_][A-Za-z0-9_]{0,15}", fullmatch=True)
msg_types = st.sampled_from(
    ["String", "PoseStamped", "Int", "IntTable", "geometry_msgs/msg/Pose", "std_msgs/Bool",
     "vtkMRMLROS2SubscriberStringNode", "vtkMRMLROS2PublisherPoseStampedNode",
     "sensor_msgs/msg/PointCloud2"])
srv_types = st.sampled_from(["std_srvs/srv/SetBool", "turtlesim/Spawn", "std_srvs/srv/Trigger"])
action_types = st.sampled_from(["control_msgs/action/FollowJointTrajectory",
                                "control_msgs/GripperCommand"])
finite = st.floats(allow_nan=False, allow_infinity=False, width=64)
json_scalars = st.none() | st.booleans() | st.integers(-(2**53), 2**53) | finite | st.text(
    max_size=20)
json_values = st.recursive(
    json_scalars,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner,
                                                                max_size=4),
    max_leaves=12)
json_objects = st.dictionaries(st.text(max_size=8), json_values, max_size=4)
qos = st.builds(c.QoS, depth=st.integers(1, 10_000),
                reliability=st.sampled_from(["reliable", "best_effort"]),
                durability=st.sampled_from(["volatile", "transient_local"]))
stamps = st.builds(c.Stamp, sec=st.integers(0, 2**32 - 1), nanosec=st.integers(0, 999_999_999))

_i64 = st.integers(-(2**63), 2**63 - 1)
param_values = st.one_of(
    st.just(ParameterValue("not_set")),
    st.builds(ParameterValue, st.just("bool"), st.booleans()),
    st.builds(ParameterValue, st.just("integer"), _i64),
    st.builds(ParameterValue, st.just("double"), finite),
    st.builds(ParameterValue, st.just("string"), st.text(max_size=20)),
    st.builds(ParameterValue, st.just("byte_array"), st.lists(st.integers(0, 255), max_size=5)),
    st.builds(ParameterValue, st.just("bool_array"), st.lists(st.booleans(), max_size=5)),
    st.builds(ParameterValue, st.just("integer_array"), st.lists(_i64, max_size=5)),
    st.builds(ParameterValue, st.just("double_array"), st.lists(finite, max_size=5)),
    st.builds(ParameterValue, st.just("string_array"), st.lists(st.text(max_size=5), max_size=5)),
)


def _rigid(angle: float, tx: float) -> tuple[tuple[float, ...], ...]:
    cs, sn = math.cos(angle), math.sin(angle)
    return ((cs, -sn, 0.0, tx), (sn, cs, 0.0, -tx), (0.0, 0.0, 1.0, 2.0 * tx),
            (0.0, 0.0, 0.0, 1.0))


matrices = st.builds(_rigid, st.floats(-3.14, 3.14), st.floats(-1e4, 1e4))
robot_sources = st.one_of(
    st.builds(c.RobotSource, st.just("parameter"), node=ros_names, parameter=param_names),
    st.builds(c.RobotSource, st.just("topic"), topic=ros_names),
    st.builds(c.RobotSource, st.just("file"), path=st.text(min_size=1, max_size=40)),
)
goal_ids = st.uuids().map(lambda u: u.hex)
bag_paths = st.from_regex(r"[A-Za-z0-9_ .-]{1,30}", fullmatch=True).map(
    lambda name: f"/data/{name}.mcap")


def _joint_values(min_size: int) -> st.SearchStrategy[Any]:
    return st.dictionaries(st.text(min_size=1, max_size=20), finite, min_size=min_size,
                           max_size=5).map(lambda d: tuple(d.items()))


# ---------------------------------------------------------------- by type

# A field's strategy by its type alone (after `X | None` and `tuple[X, ...]` are unwrapped).
BY_TYPE: dict[Any, st.SearchStrategy[Any]] = {
    bool: st.booleans(),
    c.QoS: qos,
    c.Stamp: stamps,
    ParameterValue: param_values,
    c.RobotSource: robot_sources,
    c.Matrix4: matrices,
    dict[str, Any]: json_objects,
    Any: json_values,
    tuple[tuple[str, float], ...]: _joint_values(0),
    dict[str, ParameterValue]: st.dictionaries(param_names, param_values, min_size=1,
                                               max_size=4),
}

# ---------------------------------------------------------------- by name

# What a string or number holds, by the field's name, where its type cannot say. For a
# `tuple[str, ...]` field the strategy is its items'.
BY_NAME: dict[str, st.SearchStrategy[Any]] = {
    **dict.fromkeys(("topic", "node", "service", "action", "labels_topic", "topics"),
                    ros_names),
    **dict.fromkeys(("parent", "child", "frame", "fixed_frame"), frames),
    "name": robot_names, "obstacle": robot_names, "names": param_names,
    "goal_id": goal_ids, "path": bag_paths,
    "format": st.sampled_from(["yaml", "json"]),
    "kind": st.sampled_from(c.INTERFACE_KINDS),
    "compression": st.sampled_from(c.COMPRESSIONS),
    "nonce": st.from_regex(r"[0-9a-f]{32,64}", fullmatch=True),
    "proof": st.from_regex(r"[0-9a-f]{64}", fullmatch=True),
    "rate_hz": st.floats(0.001, 10_000.0),
    "heartbeat": st.floats(0.1, 60.0),
    "display_hz": st.floats(c.DISPLAY_HZ_MIN, c.DISPLAY_HZ_MAX),
    "timeout": st.floats(0.01, 300.0),
    "result_timeout": st.floats(0.01, 86_400.0),
    "goal_timeout": st.floats(0.01, 86_400.0),
    "resolution": st.floats(0.001, 1.0),
    "duration_s": st.floats(0.1, 100.0),
    "offset": st.floats(0.0, c.MAX_SEEK_S),
    "rate": st.floats(0.0, c.MAX_PLAYBACK_RATE, exclude_min=True),
}

# ---------------------------------------------------------------- by op

# Where one op's parser allows less (or other) than the field's name says.
BY_OP: dict[type[Op], dict[str, st.SearchStrategy[Any]]] = {
    **{cls: {"type": msg_types} for cls in (c.CreateSubscriber, c.CreatePublisher)},
    **{cls: {"type": srv_types} for cls in (c.CallService, c.AdvertiseService,
                                            c.ServiceRequest)},
    **{cls: {"type": action_types} for cls in (c.SendGoal, c.AdvertiseAction, c.ActionGoal,
                                               c.ActionDecide)},
    **{cls: {"name": param_names} for cls in (c.ServerDeclareParameter, c.ServerSetParameter,
                                              c.ServerUndeclareParameter)},
    c.LookupTransform: {"timeout": st.floats(0.0, 60.0)},
    c.ActionGoal: {"type": action_types, "timeout": st.floats(0.01, 86_400.0)},
    c.ActionDecide: {"type": action_types, "timeout": st.floats(0.01, 3_600.0)},
    c.CreateRobot: {"tf_prefix": st.sampled_from(["", "PSM1/"]),
                    "namespace": st.sampled_from(["", "/PSM1", "arm"])},
    # The fixed frame is kept as tf holds it (no leading '/').
    c.CreateMarkerSubscriber: {
        "type": st.sampled_from(["Marker", "MarkerArray", "nav_msgs/msg/Path",
                                 "geometry_msgs/PolygonStamped", "PointStamped"]),
        "fixed_frame": frames.filter(lambda s: not s.startswith("/"))},
    c.SetObstacle: {"type": st.sampled_from(sorted(c.OBSTACLE_TYPES))},
    c.PublishDistance: {"rate_hz": st.floats(0.0, 1000.0)},
    c.PlanMotion: {"positions": _joint_values(1),
                   "preview": st.integers(0, c.MAX_PLAN_PREVIEW)},
    c.ExecuteMotion: {"positions": _joint_values(1), "timeout": st.floats(0.1, 300.0)},
    c.DescribeType: {"type": st.sampled_from(["PoseArray", "geometry_msgs/msg/PoseStamped",
                                              "vtkMRMLROS2ServiceClientSpawnNode",
                                              "control_msgs/action/GripperCommand"])},
}

# Requests whose fields exclude each other (the parser refuses the mix).
VALID: dict[type[Op], Callable[[Any], bool]] = {
    c.Publish: lambda r: r.message is None or r.value is None,
    c.SetObstacle: lambda r: r.frame is None or r.type == "Mesh",
    c.CreateSubscriber: lambda r: r.native or r.messages,
}


class NoStrategyError(TypeError):
    """A field of an op whose values nothing here can draw."""


def _optional(hint: Any) -> Optional[Any]:
    """X for ``X | None`` (or ``Optional[X]``), else None."""
    if typing.get_origin(hint) in (Union, types.UnionType):
        args = typing.get_args(hint)
        if len(args) == 2 and type(None) in args:
            return next(a for a in args if a is not type(None))
    return None


def _field_strategy(cls: type[Op], name: str, hint: Any,
                    default: Any) -> st.SearchStrategy[Any]:
    inner = _optional(hint)
    if inner is not None:
        return st.none() | _field_strategy(cls, name, inner, MISSING)
    named = BY_OP.get(cls, {}).get(name)
    if named is not None:
        return named
    if hint in BY_TYPE:
        return BY_TYPE[hint]
    if typing.get_origin(hint) is tuple and typing.get_args(hint)[1:] == (Ellipsis,) \
            and name in BY_NAME:
        return st.lists(BY_NAME[name], max_size=4).map(tuple)
    if name in BY_NAME:
        return BY_NAME[name]
    if hint is str:  # free text: empty only where the field's default is
        return st.text(min_size=0 if default == "" else 1, max_size=30)
    raise NoStrategyError(f"{cls.__name__} ({cls.op}): no strategy for field {name!r} of "
                          f"type {hint!r}: give its name one in BY_NAME, or the op one in "
                          f"BY_OP (tests/protocol/op_strategies.py)")


def _keep_bridge() -> st.SearchStrategy[Op]:
    """A kind a client may keep, and its remove op's request naming one bridge of it."""
    kinds = {kind: k for kind, k in c.bridge_kinds().items() if not k.bridge.per_connection}
    return st.sampled_from(sorted(kinds)).flatmap(
        lambda kind: strategy_for(kinds[kind].remove).map(
            lambda removal: c.KeepBridge(kind=kind, bridge=removal)))


# Ops whose fields depend on each other: drawn whole.
WHOLE: dict[type[Op], Callable[[], st.SearchStrategy[Op]]] = {c.KeepBridge: _keep_bridge}


def strategy_for(cls: type[Op]) -> st.SearchStrategy[Op]:
    """Requests of op ``cls``: its examples, and requests built from its fields."""
    if cls in WHOLE:
        return WHOLE[cls]()
    hints = typing.get_type_hints(cls)
    built: st.SearchStrategy[Op] = st.builds(cls, **{
        f.name: _field_strategy(cls, f.name, hints[f.name], f.default) for f in fields(cls)})
    valid = VALID.get(cls)
    if valid is not None:
        built = built.filter(valid)
    examples = [c.parse_request(cls.op, c.dumps(dict(e.args))) for e in cls.examples]
    return st.sampled_from(examples) | built if examples else built

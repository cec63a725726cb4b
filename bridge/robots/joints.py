"""A loaded robot's joints as a client may drive them: the table `describe_robot_joints`
replies with, and the positions `set_robot_joints` publishes (checked against the URDF).

Pure: a `JointSpec` mapping in, plain values out; no ROS import.

Rules (the URDF's, as robot_state_publisher and MoveIt read them):

* a client sets *actuated* joints: revolute, prismatic, continuous, not a mimic;
* revolute and prismatic positions must lie in ``[lower, upper]`` of their ``<limit>``;
  continuous joints are unlimited (a ``<limit>`` on one gives only effort/velocity);
* a mimic joint is ``multiplier * leader + offset`` (chains followed); it is added to the
  message, and a leader value that drives a mimic outside the mimic's own limits is
  refused naming both.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import TYPE_CHECKING, Any

from protocol.commands import OutOfRangeError

if TYPE_CHECKING:  # bridge.robots.description loads yourdfpy and trimesh (about 80 MB)
    from bridge.robots.description import JointSpec

__all__ = ["LIMIT_TOLERANCE", "describe_joints", "joint_positions"]

# Positions this close outside a limit are clamped, not refused: a slider at its end or a
# value that went through float32 must not be refused for rounding.
LIMIT_TOLERANCE = 1e-9


def _limited(joint: JointSpec) -> bool:
    return joint.type in ("revolute", "prismatic") and joint.limits is not None


def describe_joints(joints: Mapping[str, JointSpec]) -> list[dict[str, Any]]:
    """Every joint in URDF order: name, type, parent/child links, ``actuated``, ``lower``
    / ``upper`` (None for continuous and fixed joints), ``velocity`` / ``effort`` (None if
    not given) and ``mimic`` ({joint, multiplier, offset} or None)."""
    out = []
    for joint in joints.values():
        limits = joint.limits
        limited = _limited(joint)
        out.append({
            "name": joint.name, "type": joint.type, "parent": joint.parent,
            "child": joint.child, "actuated": joint.moves and joint.mimic is None,
            "lower": limits.lower if limited and limits is not None else None,
            "upper": limits.upper if limited and limits is not None else None,
            "velocity": limits.velocity if limits is not None else None,
            "effort": limits.effort if limits is not None else None,
            "mimic": None if joint.mimic is None else {
                "joint": joint.mimic.joint, "multiplier": joint.mimic.multiplier,
                "offset": joint.mimic.offset},
        })
    return out


def _check_limit(joint: JointSpec, value: float, field: str, why: str = "") -> float:
    if not _limited(joint):
        return value
    assert joint.limits is not None
    lower, upper = joint.limits.lower, joint.limits.upper
    if value < lower - LIMIT_TOLERANCE or value > upper + LIMIT_TOLERANCE:
        raise OutOfRangeError(field, f"a position in [{lower:g}, {upper:g}] (the URDF "
                              f"<limit> of {joint.type} joint {joint.name!r}){why}",
                              f"{value:g}")
    return min(max(value, lower), upper)


def joint_positions(joints: Mapping[str, JointSpec],
                    requested: Iterable[tuple[str, float]]) -> dict[str, float]:
    """The positions to publish for ``requested`` (joint, value) pairs: the given actuated
    joints, then the mimic joints that follow them. `OutOfRangeError` (field
    ``positions.<joint>``) names an unknown, fixed or mimic joint, a non-finite value or a
    position outside the joint's (or a mimic's) limits."""
    out: dict[str, float] = {}
    for name, value in requested:
        field = f"positions.{name}"
        joint = joints.get(name)
        if joint is None:
            movable = [j.name for j in joints.values() if j.moves and j.mimic is None]
            raise OutOfRangeError(field, "an actuated joint of this robot: "
                                  + (", ".join(movable) or "none"), repr(name))
        if not joint.moves:
            raise OutOfRangeError(field, "a moving joint (revolute, prismatic or continuous)",
                                  f"{joint.type} joint {name!r}")
        if joint.mimic is not None:
            raise OutOfRangeError(field, f"an actuated joint: {name!r} mimics "
                                  f"{joint.mimic.joint!r}, set that one", repr(name))
        if not math.isfinite(value):
            raise OutOfRangeError(field, "a finite position", repr(value))
        out[name] = _check_limit(joint, float(value), field)
    # Mimic joints, in URDF order; a chain (a mimic of a mimic) resolves leader first.
    pending = [j for j in joints.values() if j.mimic is not None and j.moves]
    progress = True
    while pending and progress:
        progress = False
        for joint in list(pending):
            assert joint.mimic is not None
            leader = joint.mimic.joint
            if leader not in out:
                if leader not in joints or not any(
                        leader == j.name for j in pending):  # its leader was not set
                    pending.remove(joint)
                continue
            value = joint.mimic.multiplier * out[leader] + joint.mimic.offset
            root = leader
            while joints[root].mimic is not None:
                root = joints[root].mimic.joint  # type: ignore[union-attr]
            out[joint.name] = _check_limit(
                joint, value, f"positions.{root}",
                f"; {joint.name!r} mimics {leader!r} as {joint.mimic.multiplier:g} * "
                f"{leader} + {joint.mimic.offset:g}")
            pending.remove(joint)
            progress = True
    return out

"""Joint sliders for a loaded robot, without Slicer: which joints get a slider, their range
in the units a Slicer user reads (degrees, millimetres), and the joint state they make.

Input: the ``joints`` table of the daemon's ``describe_robot_joints`` reply
(`Robot.joints()`). One slider per actuated joint (moving, not a mimic). A mimic joint has
no slider: it follows its leader (``multiplier * leader + offset``, chains followed), and
its own limits narrow the leader's slider so that no slider position drives a mimic out
of its limits (the daemon would refuse it). Continuous joints slide over one turn.

Units: revolute and continuous joints in degrees (`math.degrees` / `math.radians`),
prismatic joints in millimetres (`protocol.conversions`, the project's one place for
lengths). The joint state goes out in radians and metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

from protocol.conversions import metres_to_mm, mm_to_metres

__all__ = ["JointSlider", "joint_sliders", "slider_positions"]

_TURN_DEG = 180.0  # a continuous joint's slider: -180..180 degrees


@dataclass(frozen=True)
class JointSlider:
    """One slider: joint ``name`` of ``kind`` (revolute, continuous, prismatic), its range
    in display units (``unit``: "deg" or "mm"), the mimic joints that follow it."""

    name: str
    kind: str
    minimum: float
    maximum: float
    unit: str
    followers: Tuple[str, ...] = ()

    @property
    def initial(self) -> float:
        """Where the slider starts: 0 if the range holds it, else the range's middle."""
        if self.minimum <= 0.0 <= self.maximum:
            return 0.0
        return 0.5 * (self.minimum + self.maximum)

    def to_ros(self, value: float) -> float:
        """A slider value -> the joint position (radians or metres)."""
        if self.unit == "mm":
            return float(mm_to_metres(value))
        return math.radians(value)

    def from_ros(self, position: float) -> float:
        """A joint position (radians or metres) -> the slider value."""
        if self.unit == "mm":
            return float(metres_to_mm(position))
        return math.degrees(position)


def _compose(joints: Mapping[str, Mapping[str, Any]], name: str
             ) -> Optional[Tuple[str, float, float]]:
    """(root, k, b): position(name) = k * position(root) + b, following the mimic chain."""
    chain: List[Tuple[float, float]] = []
    seen = {name}
    current = joints[name]
    while current.get("mimic"):
        mimic = current["mimic"]
        leader = str(mimic["joint"])
        if leader not in joints or leader in seen:
            return None
        chain.append((float(mimic["multiplier"]), float(mimic["offset"])))
        seen.add(leader)
        name, current = leader, joints[leader]
    k, b = 1.0, 0.0
    for mult, off in chain:  # leaf first: x_leaf = m1 * x1 + o1, x1 = m2 * x2 + o2...
        b = b + k * off
        k = k * mult
    return name, k, b


def joint_sliders(table: Sequence[Mapping[str, Any]]) -> List[JointSlider]:
    """The sliders for a ``describe_robot_joints`` joint table, in URDF order."""
    joints = {str(j["name"]): j for j in table}
    ranges: Dict[str, List[float]] = {}
    followers: Dict[str, List[str]] = {}
    for name, joint in joints.items():
        if not joint.get("actuated"):
            continue
        if joint["type"] == "continuous" or joint.get("lower") is None:
            ranges[name] = [-math.pi, math.pi] if joint["type"] != "prismatic" else [-0.1, 0.1]
        else:
            ranges[name] = [float(joint["lower"]), float(joint["upper"])]
        followers[name] = []
    for name, joint in joints.items():
        if not joint.get("mimic") or joint["type"] == "fixed":
            continue
        found = _compose(joints, name)
        if found is None or found[0] not in ranges:
            continue
        root, k, b = found
        followers[root].append(name)
        if joint.get("lower") is None or k == 0.0:
            continue
        low, high = sorted(((float(joint["lower"]) - b) / k, (float(joint["upper"]) - b) / k))
        span = ranges[root]
        span[0], span[1] = max(span[0], low), min(span[1], high)
        if span[0] > span[1]:  # no leader value keeps this mimic in its limits
            span[1] = span[0]
    out = []
    for name, (low, high) in ranges.items():
        kind = str(joints[name]["type"])
        unit = "mm" if kind == "prismatic" else "deg"
        if unit == "mm":
            low_d, high_d = float(metres_to_mm(low)), float(metres_to_mm(high))
        else:
            low_d, high_d = math.degrees(low), math.degrees(high)
        if kind == "continuous":
            low_d, high_d = -_TURN_DEG, _TURN_DEG
        out.append(JointSlider(name, kind, low_d, high_d, unit, tuple(followers[name])))
    return out


def slider_positions(sliders: Sequence[JointSlider],
                     values: Mapping[str, float]) -> Dict[str, float]:
    """Slider values (display units) -> joint positions for ``set_robot_joints``; a value
    outside its slider's range is clamped to it (a slider cannot go beyond its ends)."""
    by_name = {s.name: s for s in sliders}
    out: Dict[str, float] = {}
    for name, value in values.items():
        slider = by_name.get(name)
        if slider is None:
            raise KeyError(f"no slider for joint {name!r}: the sliders are "
                           + ", ".join(by_name))
        clamped = min(max(float(value), slider.minimum), slider.maximum)
        out[name] = slider.to_ros(clamped)
    return out

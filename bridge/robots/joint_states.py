"""Joint states -> the tf a state publisher sends: which joints a message moves (mimics
following their source), their parent -> child transforms, and those as tf frames (metres,
x y z w quaternions). No ROS import: the state publisher node (bridge/robots/state_publisher.py)
publishes what this computes, and the player (bridge/playback) stores it in its tf buffer.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from bridge.robots.description import RobotDescription
from bridge.robots.kinematics import Kinematics
from protocol.conversions import rotation_to_quaternion

__all__ = ["JointFrame", "JointStateTracker", "joint_frames"]

F64 = npt.NDArray[np.float64]


@dataclass(frozen=True)
class JointFrame:
    """One joint's transform as tf carries it: parent link -> child link (prefixed)."""

    parent: str
    child: str
    translation: tuple[float, float, float]
    rotation: tuple[float, float, float, float]  # x, y, z, w


def joint_frames(description: RobotDescription, transforms: Mapping[str, F64],
                 frame_prefix: str = "") -> list[JointFrame]:
    """One `JointFrame` per joint of ``transforms`` (4x4, metres), frame ids prefixed."""
    names = list(transforms)
    if not names:
        return []
    matrices = np.stack([transforms[n] for n in names])
    quats = rotation_to_quaternion(matrices[:, :3, :3]).reshape(-1, 4)  # x, y, z, w
    out = []
    for name, matrix, q in zip(names, matrices, quats):
        joint = description.joints[name]
        out.append(JointFrame(frame_prefix + joint.parent, frame_prefix + joint.child,
                              (float(matrix[0, 3]), float(matrix[1, 3]), float(matrix[2, 3])),
                              (float(q[0]), float(q[1]), float(q[2]), float(q[3]))))
    return out


class JointStateTracker:
    """The positions joint states gave so far, and the transforms each new state moves."""

    def __init__(self, description: RobotDescription,
                 warn_once: Callable[[str, str], None]) -> None:
        self.description = description
        self.kinematics = Kinematics(description)
        self.positions: dict[str, float] = {}
        self._warn_once = warn_once  # (key, text): said once per key

    def update(self, names: Sequence[str], positions: Sequence[float]) -> dict[str, F64]:
        """Take one joint state; the parent -> child transforms (metres) of the moving
        joints it names and of the mimic joints that follow them ({} if it moves none)."""
        if len(names) != len(positions):
            self._warn_once("lengths", f"joint state with {len(names)} names and "
                            f"{len(positions)} positions ignored")
            return {}
        joints = self.description.joints
        named: list[str] = []
        for name, value in zip(names, positions):
            joint = joints.get(name)
            if joint is None or not joint.moves:
                continue
            if not math.isfinite(value):
                self._warn_once(f"nan:{name}", f"joint {name!r}: non-finite position ignored")
                continue
            self.positions[name] = float(value)
            named.append(name)
        if not named:
            return {}
        wanted = set(named)
        # Mimic joints follow their (possibly chained) source.
        for name, joint in joints.items():
            source = joint.mimic
            while source is not None and source.joint not in wanted:
                source = joints[source.joint].mimic
            if source is not None and joint.moves:
                wanted.add(name)
        return self.kinematics.joint_transforms(
            self.positions, [n for n in self.kinematics.moving_joints if n in wanted])

"""Forward kinematics of a `RobotDescription`: link poses and joint transforms, in METRES.

Joint ``j`` takes its parent link's frame to its child's: ``T_j(q) = origin_j @ M_j(q)``,
where ``M_j`` rotates by ``q`` about the unit axis (revolute, continuous) or translates by
``q`` along it (prismatic), and is the identity for fixed joints. Floating and planar joints
are held at their origin (`parse_urdf` warns about them). A mimic joint's position is
``multiplier * q(source) + offset``, chains of mimics included.

The per-joint matrices are computed for all joints at once (batched Rodrigues), and link
poses are composed one tree level at a time, so a wide robot costs a few numpy calls and a
10,000-link chain stays linear.
"""

from __future__ import annotations

import math
from typing import Iterable, Mapping, Optional

import numpy as np
import numpy.typing as npt

from bridge.robots.description import RobotDescription
from bridge.robots.errors import RobotError

__all__ = ["Kinematics"]

F64 = npt.NDArray[np.float64]

_FIXED, _ROTATE, _SLIDE = 0, 1, 2
_KIND = {"revolute": _ROTATE, "continuous": _ROTATE, "prismatic": _SLIDE}


class Kinematics:
    """Forward kinematics for one robot description (immutable after construction)."""

    def __init__(self, description: RobotDescription) -> None:
        self.description = description
        joints = description.joints
        # Links and joints in breadth-first order from the root: parents before children.
        self.link_names: tuple[str, ...]
        self.joint_names: tuple[str, ...]
        link_order = [description.root_link]
        joint_order: list[str] = []
        depth_of_link = {description.root_link: 0}
        head = 0
        while head < len(link_order):
            link = link_order[head]
            head += 1
            for joint_name in description.child_joints.get(link, ()):
                child = joints[joint_name].child
                joint_order.append(joint_name)
                link_order.append(child)
                depth_of_link[child] = depth_of_link[link] + 1
        self.link_names = tuple(link_order)
        self.joint_names = tuple(joint_order)
        self._link_index = {name: i for i, name in enumerate(link_order)}
        self._joint_index = {name: i for i, name in enumerate(joint_order)}

        count = len(joint_order)
        self._origins = np.empty((count, 4, 4))
        self._axes = np.empty((count, 3))
        self._kind = np.zeros(count, dtype=np.int8)
        self._parent_link = np.empty(count, dtype=np.int64)
        self._child_link = np.empty(count, dtype=np.int64)
        for i, name in enumerate(joint_order):
            j = joints[name]
            self._origins[i] = j.origin
            self._axes[i] = j.axis
            self._kind[i] = _KIND.get(j.type, _FIXED)
            self._parent_link[i] = self._link_index[j.parent]
            self._child_link[i] = self._link_index[j.child]
        # Joints grouped by the depth of their child link; BFS order keeps depths sorted.
        depths = np.array([depth_of_link[joints[n].child] for n in joint_order], dtype=np.int64)
        bounds = np.flatnonzero(np.diff(depths)) + 1
        self._levels = [lvl for lvl in np.split(np.arange(count), bounds) if len(lvl)]

        self._moving = np.flatnonzero(self._kind != _FIXED)
        self.fixed_joints = tuple(joint_order[i] for i in np.flatnonzero(self._kind == _FIXED))
        self.moving_joints = tuple(joint_order[i] for i in self._moving)
        self.actuated_joints = tuple(n for n in self.moving_joints if joints[n].mimic is None)
        # Mimic joints in an order where every source is computed before its mimics.
        self._mimics: list[tuple[int, int, float, float]] = []
        done: set[str] = set()
        for name in joint_order:
            chain = []
            current: Optional[str] = name
            while current is not None and current not in done and joints[current].mimic:
                chain.append(current)
                mimic = joints[current].mimic
                current = mimic.joint if mimic is not None else None
            for mimic_name in reversed(chain):
                m = joints[mimic_name].mimic
                assert m is not None
                self._mimics.append((self._joint_index[mimic_name], self._joint_index[m.joint],
                                     m.multiplier, m.offset))
                done.add(mimic_name)

    # ------------------------------------------------------------------ positions

    def positions_vector(self, joint_positions: Mapping[str, float]) -> F64:
        """Joint positions in `joint_names` order: given ones used, mimics computed, others 0.

        Names the robot does not have are ignored (a joint state may cover several robots).
        """
        q = np.zeros(len(self.joint_names))
        index = self._joint_index
        for name, value in joint_positions.items():
            i = index.get(name)
            if i is None:
                continue
            try:
                v = float(value)
            except (TypeError, ValueError):
                raise RobotError(f"joint_positions[{name!r}]", "a number", value) from None
            if not math.isfinite(v):
                raise RobotError(f"joint_positions[{name!r}]", "a finite number", v)
            q[i] = v
        for target, source, multiplier, offset in self._mimics:
            q[target] = multiplier * q[source] + offset
        return q

    # ------------------------------------------------------------------ transforms

    def local_transforms(self, q: F64) -> F64:
        """(J, 4, 4) parent->child transforms of every joint for positions ``q``."""
        motion: F64 = np.broadcast_to(np.eye(4), (len(q), 4, 4)).copy()
        rot = np.flatnonzero(self._kind == _ROTATE)
        if len(rot):
            a = self._axes[rot]
            theta = q[rot]
            c, s = np.cos(theta), np.sin(theta)
            x, y, z = a[:, 0], a[:, 1], a[:, 2]
            t = 1.0 - c
            # Rodrigues: R = c I + s [a]x + (1 - c) a a^T, for all rotating joints at once.
            motion[rot, 0, 0] = c + t * x * x
            motion[rot, 0, 1] = t * x * y - s * z
            motion[rot, 0, 2] = t * x * z + s * y
            motion[rot, 1, 0] = t * x * y + s * z
            motion[rot, 1, 1] = c + t * y * y
            motion[rot, 1, 2] = t * y * z - s * x
            motion[rot, 2, 0] = t * x * z - s * y
            motion[rot, 2, 1] = t * y * z + s * x
            motion[rot, 2, 2] = c + t * z * z
        slide = np.flatnonzero(self._kind == _SLIDE)
        if len(slide):
            motion[slide, :3, 3] = self._axes[slide] * q[slide, None]
        return self._origins @ motion  # np.matmul, typed by numpy's operator stubs

    def joint_transforms(self, joint_positions: Mapping[str, float],
                         joints: Optional[Iterable[str]] = None) -> dict[str, F64]:
        """Parent->child 4x4 transforms (metres) of ``joints`` (default: every moving one).

        What a state publisher sends on /tf; fixed joints are in `fixed_joint_transforms`.
        """
        local = self.local_transforms(self.positions_vector(joint_positions))
        names = self.moving_joints if joints is None else joints
        out = {}
        for name in names:
            i = self._joint_index.get(name)
            if i is not None:
                out[name] = local[i]
        return out

    def fixed_joint_transforms(self) -> dict[str, F64]:
        """Parent->child transforms of the joints that never move (for /tf_static)."""
        return {name: self._origins[self._joint_index[name]].copy()
                for name in self.fixed_joints}

    def link_pose_array(self, joint_positions: Mapping[str, float]) -> F64:
        """(L, 4, 4) poses of every link in the root frame, in `link_names` order."""
        local = self.local_transforms(self.positions_vector(joint_positions))
        poses = np.empty((len(self.link_names), 4, 4))
        poses[0] = np.eye(4)
        for level in self._levels:
            poses[self._child_link[level]] = np.matmul(poses[self._parent_link[level]],
                                                       local[level])
        return poses

    def link_poses(self, joint_positions: Mapping[str, float]) -> dict[str, F64]:
        """Pose (4x4, metres) of every link in the root link's frame."""
        poses = self.link_pose_array(joint_positions)
        return {name: poses[i] for i, name in enumerate(self.link_names)}

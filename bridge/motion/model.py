"""A robot's kinematic model on pinocchio, built from the description the daemon loaded.

The pinocchio model is built from `bridge.robots.RobotDescription` (the project's one URDF
parser), not by pinocchio's own URDF reader, so both agree on every joint: revolute and
prismatic joints about their unit axis, continuous joints as unlimited revolute ones (one
angle, as `bridge.robots.Kinematics` has them), fixed joints folded into the next joint's
placement, floating and planar joints held at their origin (as `parse_urdf` warns).

Mimic joints are pinocchio joints of their own whose position is tied to their leader's:
the solver's variables are the ACTUATED joints only (``theta``), and the configuration is
``q = A @ theta + b``; a frame Jacobian in ``theta`` is ``J(q) @ A``.

Every link is a BODY frame; its pose is ``data.oMf[frame]`` in the root link's frame, in
METRES.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping, Optional

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from bridge.motion.errors import MotionInputError
from bridge.robots.description import JointSpec, RobotDescription
from bridge.robots.model import RobotModel

__all__ = ["MotionModel"]

F64 = npt.NDArray[np.float64]


@dataclass(frozen=True)
class _Mimic:
    joint: str
    leader: str
    multiplier: float
    offset: float


def _se3(matrix: F64) -> pin.SE3:
    return pin.SE3(np.ascontiguousarray(matrix[:3, :3]), np.ascontiguousarray(matrix[:3, 3]))


def _joint_model(joint: JointSpec) -> pin.JointModel:
    axis = np.asarray(joint.axis, dtype=np.float64)
    if joint.type == "prismatic":
        return pin.JointModelPrismaticUnaligned(axis)
    return pin.JointModelRevoluteUnaligned(axis)  # revolute and continuous


class MotionModel:
    """pinocchio's model of one robot, its actuated joints and their limits.

    ``joint_names``: the actuated joints (moving, not mimics), the order of ``theta``;
    ``lower`` / ``upper``: their limits, mimics' own limits folded in (continuous: +-inf).
    Not thread-safe (one pinocchio ``Data``): one query at a time per model.
    """

    def __init__(self, robot: RobotModel) -> None:
        self.robot = robot
        description = robot.description
        self.name = description.name
        model = pin.Model()
        model.name = description.name
        # Each link hangs from a pinocchio joint at a fixed placement in that joint's frame.
        where: dict[str, tuple[int, F64]] = {description.root_link: (0, np.eye(4))}
        pin_joint: dict[str, int] = {}
        for joint_name in robot.kinematics.joint_names:  # parents before children
            joint = description.joints[joint_name]
            parent_id, placement = where[joint.parent]
            origin = placement @ joint.origin
            if joint.moves:
                jid = model.addJoint(parent_id, _joint_model(joint), _se3(origin), joint_name)
                pin_joint[joint_name] = jid
                where[joint.child] = (jid, np.eye(4))
            else:
                where[joint.child] = (parent_id, origin)
        self.link_names = tuple(robot.kinematics.link_names)
        self._frame: dict[str, int] = {}
        for link in self.link_names:
            jid, placement = where[link]
            parent_frame = model.getFrameId(model.names[jid]) if jid else 0
            self._frame[link] = model.addFrame(
                pin.Frame(link, jid, parent_frame, _se3(placement), pin.FrameType.BODY))
        self.model = model
        self.data = model.createData()
        self._link_joint = {link: where[link][0] for link in self.link_names}

        # theta (actuated) -> q: A (nq x n), b (nq).
        self.joint_names = tuple(n for n in robot.kinematics.joint_names
                                 if n in pin_joint and description.joints[n].mimic is None)
        index = {name: i for i, name in enumerate(self.joint_names)}
        nq, n = model.nq, len(self.joint_names)
        self._a = np.zeros((nq, n))
        self._b = np.zeros(nq)
        lower = np.full(n, -math.inf)
        upper = np.full(n, math.inf)
        self.continuous = np.zeros(n, dtype=bool)
        for name, jid in pin_joint.items():
            row = model.joints[jid].idx_q
            joint = description.joints[name]
            multiplier, offset, leader = self._leader_of(description, name)
            if leader is not None:
                self._a[row, index[leader]] = multiplier
            self._b[row] = offset
            if joint.type == "continuous" and leader == name:
                self.continuous[index[name]] = True
            if joint.type == "continuous" or joint.limits is None or leader is None:
                continue
            # This joint's limits bound its leader: lower <= m * theta + o <= upper.
            low = (joint.limits.lower - offset) / multiplier if multiplier else -math.inf
            high = (joint.limits.upper - offset) / multiplier if multiplier else math.inf
            if multiplier < 0:
                low, high = high, low
            i = index[leader]
            lower[i] = max(lower[i], low)
            upper[i] = min(upper[i], high)
        self.lower = lower
        self.upper = upper
        self.mimics = tuple(
            _Mimic(name, *self._mimic_terms(description, name))
            for name in pin_joint if description.joints[name].mimic is not None)

    @staticmethod
    def _leader_of(description: RobotDescription, name: str
                   ) -> tuple[float, float, Optional[str]]:
        """(multiplier, offset, actuated leader) with q(name) = m * q(leader) + o; the
        leader None when the chain ends at a joint that does not move (q = o)."""
        multiplier, offset = 1.0, 0.0
        joint = description.joints[name]
        while joint.mimic is not None:
            offset += multiplier * joint.mimic.offset
            multiplier *= joint.mimic.multiplier
            joint = description.joints[joint.mimic.joint]
        if not joint.moves:
            return 0.0, offset, None
        return multiplier, offset, joint.name

    @classmethod
    def _mimic_terms(cls, description: RobotDescription, name: str
                     ) -> tuple[str, float, float]:
        multiplier, offset, leader = cls._leader_of(description, name)
        return leader or "", multiplier, offset

    # ------------------------------------------------------------------ joints

    def frame_id(self, link: str, field: str = "tip") -> int:
        """pinocchio's frame of ``link``; an unknown link is a `MotionInputError`."""
        frame = self._frame.get(link)
        if frame is None:
            shown = ", ".join(self.link_names[:12]) + (" ..." if len(self.link_names) > 12
                                                       else "")
            raise MotionInputError(field, f"a link of robot {self.name!r} ({shown})", link)
        return frame

    def moves_frame(self, frame: int) -> npt.NDArray[np.bool_]:
        """Which actuated joints move ``frame`` (those on its chain from the root, or leading
        a mimic on it): the others are left where they are by a solve for that frame."""
        joint = self.model.frames[frame].parentJoint
        rows = [self.model.joints[j].idx_q for j in self.model.supports[joint] if j > 0]
        return np.asarray(np.any(self._a[rows] != 0.0, axis=0), dtype=bool) if rows else \
            np.zeros(len(self.joint_names), dtype=bool)

    def theta_of(self, positions: Mapping[str, float], field: str = "seed") -> F64:
        """Actuated joint positions in `joint_names` order; joints not given are 0 (or the
        nearest limit), names of other robots' joints are ignored."""
        theta = np.zeros(len(self.joint_names))
        for i, name in enumerate(self.joint_names):
            if name in positions:
                value = float(positions[name])
                if not math.isfinite(value):
                    raise MotionInputError(f"{field}[{name!r}]", "a finite number", value)
                theta[i] = value
        return np.clip(theta, self.lower, self.upper)

    def positions_of(self, theta: F64) -> dict[str, float]:
        """Actuated joint positions by name (continuous joints wrapped to (-pi, pi])."""
        wrapped = np.where(self.continuous, np.mod(theta + math.pi, 2 * math.pi) - math.pi,
                           theta)
        return {name: float(v) for name, v in zip(self.joint_names, wrapped)}

    def configuration(self, theta: F64) -> F64:
        """pinocchio's q for actuated positions ``theta`` (mimics computed)."""
        return self._a @ theta + self._b

    def within_limits(self, theta: F64, tolerance: float = 1e-9) -> bool:
        return bool(np.all(theta >= self.lower - tolerance)
                    and np.all(theta <= self.upper + tolerance))

    def random_theta(self, rng: np.random.Generator) -> F64:
        """Uniform within the limits (continuous joints: one turn)."""
        low = np.where(np.isfinite(self.lower), self.lower, -math.pi)
        high = np.where(np.isfinite(self.upper), self.upper, math.pi)
        return rng.uniform(low, high)

    # ------------------------------------------------------------------ kinematics

    def update(self, theta: F64) -> None:
        """Forward kinematics of every frame for ``theta`` (into ``self.data``)."""
        pin.framesForwardKinematics(self.model, self.data, self.configuration(theta))

    def pose(self, frame: int) -> pin.SE3:
        """A frame's pose after `update` (metres, root link frame)."""
        return self.data.oMf[frame]

    def link_pose(self, theta: F64, link: str) -> F64:
        """4x4 pose (metres) of ``link`` in the root link's frame."""
        frame = self.frame_id(link)
        self.update(theta)
        return np.array(self.data.oMf[frame].homogeneous)

    def link_poses(self, theta: F64) -> dict[str, F64]:
        self.update(theta)
        return {link: np.array(self.data.oMf[f].homogeneous) for link, f in self._frame.items()}

    def jacobian(self, theta: F64, frame: int) -> F64:
        """The frame's 6 x n Jacobian in ``theta`` (LOCAL: the frame's own axes), after
        `update` for the same ``theta``."""
        q = self.configuration(theta)
        pin.computeJointJacobians(self.model, self.data, q)
        local = pin.getFrameJacobian(self.model, self.data, frame, pin.ReferenceFrame.LOCAL)
        # eigenpy hands a 6x1 Jacobian (one joint) back as a vector: shape it again.
        return np.asarray(np.reshape(local, (6, -1)) @ self._a, dtype=np.float64)

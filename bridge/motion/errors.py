"""Typed errors of motion (inverse kinematics, collision geometry, obstacles).

Each names the ``field``, what was ``expected`` and what it ``got`` (`ProtocolError`); the
daemon turns them into error replies and keeps serving::

    MotionError               base of this package's errors
    +-- MotionInputError      a request's value cannot be used: NaN target, unknown tip link
    +-- NoCollisionGeometry   a collision query on a robot none of whose links has geometry
    +-- ObstacleError         an obstacle mesh that is empty, degenerate or too large

A target that cannot be reached is not an exception: `bridge.motion.ik.solve_ik` returns an
`IkResult` whose ``failure`` says why (unreachable, a joint limit, a collision).
"""

from __future__ import annotations

from protocol.errors import ProtocolError

__all__ = ["MotionError", "MotionInputError", "NoCollisionGeometry", "ObstacleError"]


class MotionError(ProtocolError):
    """Base of the errors of inverse kinematics and collision checking."""


class MotionInputError(MotionError):
    """A value given to a motion query cannot be used (the target, the tip link, a seed)."""


class NoCollisionGeometry(MotionError):
    """A collision or distance query on a robot with no collision geometry (nor visuals)."""


class ObstacleError(MotionError):
    """An obstacle mesh that cannot be used: no triangles, degenerate, or too large."""

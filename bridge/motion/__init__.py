"""Motion: kinematics and collisions of a loaded robot on pinocchio and coal.

What the daemon calls::

    model = MotionModel(robot_model)              # a bridge.robots.RobotModel (its URDF)
    result = solve_ik(model, target_m, "tool_flange", seed=current_positions)
    result.positions if result.ok else result.failure   # unreachable / joint_limit / collision
    world = CollisionWorld(model)                  # links' collision geometry (or visuals)
    world.set_obstacle("skull", vertices_m, triangles, pose_m)
    world.distances("tool_flange", positions)      # metres to each obstacle

Lengths are METRES here (ROS's unit); the op and the client speak millimetres, converted
by `protocol.conversions` at the edge. pinocchio and coal (~80 MB of wheels) are imported
with the first robot a motion query touches, never at daemon start.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "bridge.motion.errors": ("MotionError", "MotionInputError", "NoCollisionGeometry",
                             "ObstacleError"),
    "bridge.motion.model": ("MotionModel",),
    "bridge.motion.ik": ("IkFailure", "IkOptions", "IkResult", "solve_ik"),
    "bridge.motion.collisions": ("CollisionWorld", "Contact"),
}
_MODULE_OF = {name: module for module, names in _EXPORTS.items() for name in names}


def __getattr__(name: str) -> Any:
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module 'bridge.motion' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)


__all__ = sorted(_MODULE_OF)

"""Motion ops: inverse kinematics of a loaded robot (a read: the robot does not move)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from protocol.commands.errors import TooLargeError
from protocol.commands.fields import (MAX_NAME, MISSING, ROBOT_NAME, Args, check_float,
                                      check_str)
from protocol.commands.op import Op, Resource
from protocol.commands.results import Answered, SolveIkResult
from protocol.commands.robots import MAX_JOINTS
from protocol.commands.values import Matrix4, matrix_from

__all__ = ["SolveIk"]


@dataclass(frozen=True)
class SolveIk(Op, Answered[SolveIkResult], op="solve_ik", writes=False):
    """Joint positions putting link ``tip`` of loaded robot ``name`` at ``target`` (a rigid
    4x4 in mm, rows, in the robot's root link frame), within the URDF's limits, starting
    from ``seed`` (joint -> position; omitted: the robot's current joint state, else 0).

    It is a read: nothing is published, the robot does not move. A target no joint
    positions reach is answered ``"solved": false`` with ``failure`` (``reason``
    unreachable, joint_limit or collision, the joints or the link and obstacle) and the
    best residual (mm, degrees); the client raises `IkFailedError` from it."""

    name: str
    tip: str
    target: Matrix4
    seed: tuple[tuple[str, float], ...] | None = None
    collisions: bool = True  # avoid the robot's obstacles (when it has any)

    def resources(self) -> tuple[Resource, ...]:
        return ()  # the URDF the robot already read (judged at create_robot)

    def to_args(self) -> dict[str, Any]:
        out = super().to_args()
        if self.seed is not None:
            out["seed"] = dict(self.seed)
        return out

    @classmethod
    def from_args(cls, a: Args) -> SolveIk:
        seed = None
        if a.raw("seed", False) is not MISSING:
            raw = a.req_obj_raw("seed")
            if len(raw) > MAX_JOINTS:
                raise TooLargeError(a.path("seed"), f"at most {MAX_JOINTS} joints",
                                    str(len(raw)))
            pairs = []
            for joint, value in raw.items():
                path = f"{a.path('seed')}.{joint}"
                check_str(joint, path, MAX_NAME, False, None, "")
                pairs.append((joint, check_float(value, path, float("-inf"), float("inf"),
                                                 False)))
            seed = tuple(pairs)
        return cls(name=a.req_str("name", max_len=64, pattern=ROBOT_NAME,
                                  desc="a robot name of letters, digits and _"),
                   tip=a.req_str("tip"),
                   target=matrix_from(a.any("target"), a.path("target")),
                   seed=seed, collisions=a.opt_bool("collisions", True))

"""Motion ops: inverse kinematics of a loaded robot (a read: the robot does not move), the
obstacles it must avoid (Slicer models published to ROS) and its distances to them."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from protocol.commands.errors import TooLargeError
from protocol.commands.fields import (MAX_NAME, MISSING, ROBOT_NAME, Args, check_float,
                                      check_str)
from protocol.commands.errors import OutOfRangeError
from protocol.commands.fields import ROS_NAME, ROS_NAME_DESC
from protocol.commands.op import Op, Resource, TopicUse
from protocol.commands.results import Answered, SolveIkResult
from protocol.commands.robots import MAX_JOINTS
from protocol.commands.values import Matrix4, matrix_from

__all__ = ["MAX_OBSTACLES", "OBSTACLE_TYPES", "ObstacleDistances", "PublishDistance",
           "RemoveObstacle", "SetObstacle", "SolveIk"]

MAX_OBSTACLES = 16  # per robot: each one a subscription and a bounding-volume hierarchy
# The types a Slicer model reaches ROS as (publish_model): short name -> ROS type.
OBSTACLE_TYPES = {"Marker": "visualization_msgs/msg/Marker", "Mesh": "shape_msgs/msg/Mesh"}
_ROBOT_DESC = "a robot name of letters, digits and _"
_OBSTACLE_DESC = "an obstacle name of letters, digits and _"


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


def _robot(a: Args) -> str:
    return a.req_str("name", max_len=64, pattern=ROBOT_NAME, desc=_ROBOT_DESC)


def _obstacle(a: Args) -> str:
    return a.req_str("obstacle", max_len=64, pattern=ROBOT_NAME, desc=_OBSTACLE_DESC)


@dataclass(frozen=True)
class SetObstacle(Op, op="set_obstacle", ros_names=("topic",), writes=False):
    """Make the model published on ``topic`` an obstacle of robot ``name``: a Slicer model
    sent to ROS (``publish_model``) as a visualization_msgs/Marker TRIANGLE_LIST (placed in
    its frame_id, by tf, at every query: it follows its transforms) or a shape_msgs/Mesh
    (in ``frame``, default the robot's root link). Each new message replaces the mesh.
    Robot links touching it fail solve_ik; distances to it are measured. Setting the same
    name again replaces it; at most `MAX_OBSTACLES` per robot."""

    name: str
    obstacle: str
    topic: str
    type: str = "Marker"
    frame: str | None = None

    @property
    def ros_type(self) -> str:
        return OBSTACLE_TYPES[self.type]

    def resources(self) -> tuple[Resource, ...]:
        return (TopicUse("topic", self.topic, self.ros_type),)

    @classmethod
    def from_args(cls, a: Args) -> SetObstacle:
        kind = a.choice("type", tuple(OBSTACLE_TYPES), "Marker")
        frame = a.opt_str("frame")
        if frame is not None and kind != "Mesh":
            raise OutOfRangeError(a.path("frame"), "no frame for a Marker (it names its own)",
                                  repr(frame))
        return cls(name=_robot(a), obstacle=_obstacle(a),
                   topic=a.req_str("topic", pattern=ROS_NAME, desc=ROS_NAME_DESC),
                   type=kind, frame=frame)


@dataclass(frozen=True)
class RemoveObstacle(Op, op="remove_obstacle", writes=False):
    """Forget obstacle ``obstacle`` of robot ``name`` (its subscription ends)."""

    name: str
    obstacle: str

    def resources(self) -> tuple[Resource, ...]:
        return ()

    @classmethod
    def from_args(cls, a: Args) -> RemoveObstacle:
        return cls(name=_robot(a), obstacle=_obstacle(a))


@dataclass(frozen=True)
class ObstacleDistances(Op, op="obstacle_distances", writes=False):
    """At the robot's current joint state: the minimum distance (mm) from ``link`` to each
    obstacle with the nearest points (mm, root link frame), and every link-obstacle pair in
    contact. A read."""

    name: str
    link: str

    def resources(self) -> tuple[Resource, ...]:
        return ()

    @classmethod
    def from_args(cls, a: Args) -> ObstacleDistances:
        return cls(name=_robot(a), link=a.req_str("link"))


@dataclass(frozen=True)
class PublishDistance(Op, op="publish_distance", ros_names=("topic",), writes=True):
    """Publish the minimum distance from ``link`` to ``obstacle`` as std_msgs/Float64 in
    METRES on ``topic``, ``rate_hz`` times a second at the robot's current joint state (for
    virtual fixtures and haptics; a client reads it as any topic). One per topic: the same
    topic again replaces it, ``rate_hz`` 0 stops it. A write (a ROS publisher)."""

    name: str
    link: str
    obstacle: str
    topic: str
    rate_hz: float = 50.0

    def resources(self) -> tuple[Resource, ...]:
        return (TopicUse("topic", self.topic, "std_msgs/msg/Float64", writes=True),)

    @classmethod
    def from_args(cls, a: Args) -> PublishDistance:
        rate = a.opt_float("rate_hz", 50.0, low=0.0, high=1000.0)
        return cls(name=_robot(a), link=a.req_str("link"), obstacle=_obstacle(a),
                   topic=a.req_str("topic", pattern=ROS_NAME, desc=ROS_NAME_DESC),
                   rate_hz=float(rate if rate is not None else 50.0))

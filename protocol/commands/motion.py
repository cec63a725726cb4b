"""Motion ops: inverse kinematics of a loaded robot (a read: the robot does not move), the
obstacles it must avoid (Slicer models published to ROS) and its distances to them."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional

from protocol.commands.errors import OutOfRangeError
from protocol.commands.fields import MISSING, ROBOT_NAME, ROS_NAME, ROS_NAME_DESC, Args
from protocol.commands.op import ActionUse, Example, FrameUse, Op, Resource, TopicUse
from protocol.commands.results import (Answered, Result, SendGoalResult, SolveIkResult,
                                       read_field)
from protocol.commands.robots import joint_values
from protocol.commands.values import Matrix4, matrix_from

__all__ = ["DEFAULT_TRAJECTORY_ACTION", "FOLLOW_JOINT_TRAJECTORY", "MAX_OBSTACLES",
           "MAX_PLAN_PREVIEW", "OBSTACLE_TYPES", "ExecuteMotion", "ExecuteMotionResult",
           "ObstacleDistances", "ObstacleDistancesResult", "ObstacleRemoved", "ObstacleSet",
           "PlanMotion", "PlanMotionResult", "PublishDistance", "PublishDistanceResult",
           "RemoveObstacle", "SetObstacle", "SolveIk"]

FOLLOW_JOINT_TRAJECTORY = "control_msgs/action/FollowJointTrajectory"
# ros2_control's joint trajectory controller's action (and the demo's).
DEFAULT_TRAJECTORY_ACTION = "/joint_trajectory_controller/follow_joint_trajectory"
MAX_PLAN_PREVIEW = 200  # configurations of a plan's preview (each: every link's pose)
_MAX_RESOLUTION = 1.0  # rad (or m) between two checked configurations, at most

MAX_OBSTACLES = 16  # per robot: each one a subscription and a bounding-volume hierarchy
# The types a Slicer model reaches ROS as (publish_model): short name -> ROS type.
OBSTACLE_TYPES = {"Marker": "visualization_msgs/msg/Marker", "Mesh": "shape_msgs/msg/Mesh"}
_ROBOT_DESC = "a robot name of letters, digits and _"
_OBSTACLE_DESC = "an obstacle name of letters, digits and _"


@dataclass(frozen=True)
class ObstacleSet(Result):
    """An obstacle of a robot: the topic it comes from, its type, and the robot's links
    its contacts are checked against."""

    name: str
    obstacle: str
    topic: str
    type: str
    links: tuple[str, ...]


@dataclass(frozen=True)
class ObstacleRemoved(Result):
    name: str
    obstacle: str


@dataclass(frozen=True)
class ObstacleDistancesResult(Result):
    """At the robot's current joint state: the distances from ``link`` to each obstacle
    (with the nearest points), the link-obstacle pairs in contact, and the obstacles not
    placed in the robot's frame (and why)."""

    name: str
    link: str
    positions: dict[str, float]
    distances: tuple[dict[str, Any], ...]
    contacts: tuple[dict[str, Any], ...]
    unplaced: tuple[dict[str, Any], ...]


@dataclass(frozen=True)
class PublishDistanceResult(Result):
    """Whether the distance is now published on ``topic`` (at ``rate_hz``), or stopped."""

    name: str
    topic: str
    publishing: bool
    rate_hz: Optional[float] = None


@dataclass(frozen=True)
class PlanMotionResult(Result):
    """A joint-space path: the joints that move, the start and goal positions, the path's
    configurations (of those joints), how many were checked and whether all are clear
    (else the first ``collision``: link, obstacle, step, fraction, positions), the
    obstacles not placed, the motion's duration, and ``preview`` (each link's pose, mm,
    at some configurations) when asked."""

    name: str
    joints: tuple[str, ...]
    start: dict[str, float]
    goal: dict[str, float]
    path: tuple[tuple[float, ...], ...]
    resolution: float
    checked: int
    clear: bool
    collision: Optional[dict[str, Any]]
    unplaced: tuple[dict[str, Any], ...]
    duration_s: float
    preview: Optional[tuple[dict[str, Any], ...]] = None


@dataclass(frozen=True)
class ExecuteMotionResult(SendGoalResult):
    """The goal sent (a `SendGoalResult`), and the plan it follows: the joints, the
    configurations checked, the resolution, the motion's duration, the obstacles not
    placed."""

    name: str
    joints: tuple[str, ...]
    checked: int
    resolution: float
    duration_s: float
    unplaced: tuple[dict[str, Any], ...]

    @classmethod
    def read(cls, a: Args) -> ExecuteMotionResult:
        goal = SendGoalResult.read(a)
        return cls(**{f: getattr(goal, f) for f in goal.__dataclass_fields__},
                   name=read_field(a, "name", str),
                   joints=read_field(a, "joints", tuple[str, ...]),
                   checked=read_field(a, "checked", int),
                   resolution=read_field(a, "resolution", float),
                   duration_s=read_field(a, "duration_s", float),
                   unplaced=read_field(a, "unplaced", tuple[dict[str, Any], ...]))


@dataclass(frozen=True)
class SolveIk(Op, Answered[SolveIkResult], op="solve_ik", writes=False):
    """Joint positions putting link ``tip`` of loaded robot ``name`` at ``target`` (a rigid
    4x4 in mm, rows, in the robot's root link frame), within the URDF's limits, starting
    from ``seed`` (joint -> position; omitted: the robot's current joint state, else 0).

    It is a read: nothing is published, the robot does not move. A target no joint
    positions reach is answered ``"solved": false`` with ``failure`` (``reason``
    unreachable, joint_limit or collision, the joints or the link and obstacle) and the
    best residual (mm, degrees); the client raises `IkFailedError` from it."""

    examples = (Example(
        {"name": "r", "tip": "tool",
         "target": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}),)

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
        seed = joint_values(a, "seed") if a.raw("seed", False) is not MISSING else None
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
class SetObstacle(Op, op="set_obstacle", result=ObstacleSet, ros_names=("topic",), writes=False,
                  content=("frames",)):
    """Make the model published on ``topic`` an obstacle of robot ``name``: a Slicer model
    sent to ROS (``publish_model``) as a visualization_msgs/Marker TRIANGLE_LIST (placed in
    its frame_id, by tf, at every query: it follows its transforms) or a shape_msgs/Mesh
    (in ``frame``, default the robot's root link). Each new message replaces the mesh.
    Robot links touching it fail solve_ik; distances to it are measured. Setting the same
    name again replaces it; at most `MAX_OBSTACLES` per robot. Its frame is judged by the
    frame globs (a Marker's as it arrives: a denied one leaves the obstacle unplaced)."""

    examples = (Example(
        {"name": "r", "obstacle": "skull", "topic": "/skull"},
        {("topic", "topic", "/skull")}),)

    name: str
    obstacle: str
    topic: str
    type: str = "Marker"
    frame: str | None = None

    @property
    def ros_type(self) -> str:
        return OBSTACLE_TYPES[self.type]

    def resources(self) -> tuple[Resource, ...]:
        uses: list[Resource] = [TopicUse("topic", self.topic, self.ros_type)]
        if self.frame:
            uses.append(FrameUse("frame", self.frame, client_frame=False))
        return tuple(uses)

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
class RemoveObstacle(Op, op="remove_obstacle", result=ObstacleRemoved, writes=False):
    """Forget obstacle ``obstacle`` of robot ``name`` (its subscription ends)."""

    examples = (Example({"name": "r", "obstacle": "skull"}),)

    name: str
    obstacle: str

    def resources(self) -> tuple[Resource, ...]:
        return ()

    @classmethod
    def from_args(cls, a: Args) -> RemoveObstacle:
        return cls(name=_robot(a), obstacle=_obstacle(a))


@dataclass(frozen=True)
class ObstacleDistances(Op, op="obstacle_distances", result=ObstacleDistancesResult, writes=False):
    """At the robot's current joint state: the minimum distance (mm) from ``link`` to each
    obstacle with the nearest points (mm, root link frame), and every link-obstacle pair in
    contact. A read."""

    examples = (Example({"name": "r", "link": "tool"}),)

    name: str
    link: str

    def resources(self) -> tuple[Resource, ...]:
        return ()

    @classmethod
    def from_args(cls, a: Args) -> ObstacleDistances:
        return cls(name=_robot(a), link=a.req_str("link"))


@dataclass(frozen=True)
class PublishDistance(Op, op="publish_distance", result=PublishDistanceResult,
                      ros_names=("topic",), writes=True):
    """Publish the minimum distance from ``link`` to ``obstacle`` as std_msgs/Float64 in
    METRES on ``topic``, ``rate_hz`` times a second at the robot's current joint state (for
    virtual fixtures and haptics; a client reads it as any topic). One per topic: the same
    topic again replaces it, ``rate_hz`` 0 stops it. A write (a ROS publisher)."""

    examples = (Example(
        {"name": "r", "link": "tool", "obstacle": "skull", "topic": "/d"},
        {("topic", "topic", "/d")}),)

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


def _resolution(a: Args) -> float:
    value = a.opt_float("resolution", 0.01, low=0.0, high=_MAX_RESOLUTION, low_open=True)
    return float(value if value is not None else 0.01)


@dataclass(frozen=True)
class PlanMotion(Op, op="plan_motion", result=PlanMotionResult, writes=False):
    """A joint-space path of robot ``name`` from its current joint state to ``positions``
    (actuated joints; the others stay), a straight line within the URDF's limits, checked
    for contact with the robot's obstacles at every ``resolution`` (rad or m: the largest
    joint step between two checked configurations). A read: for a preview."""

    examples = (Example({"name": "r", "positions": {"j": 0.5}}),)

    name: str
    positions: tuple[tuple[str, float], ...]
    resolution: float = 0.01
    # Also each link's pose (mm, the root link's frame) at this many configurations picked
    # evenly along the path, both ends included: what a preview of the motion draws.
    preview: int = 0

    def resources(self) -> tuple[Resource, ...]:
        return ()

    def to_args(self) -> dict[str, Any]:
        out = super().to_args()
        out["positions"] = dict(self.positions)
        return out

    @classmethod
    def from_args(cls, a: Args) -> PlanMotion:
        return cls(name=_robot(a), positions=joint_values(a, "positions"),
                   resolution=_resolution(a),
                   preview=int(a.opt_int("preview", 0, low=0, high=MAX_PLAN_PREVIEW) or 0))


@dataclass(frozen=True)
class ExecuteMotion(Op, Answered[SendGoalResult], op="execute_motion", ros_names=("action",),
                    writes=True):
    """Plan as `PlanMotion` does, then, if the path is clear, send it as a goal to the
    robot's control_msgs/FollowJointTrajectory ``action`` (as `SendGoal`: feedback and
    result come as goal events, ``goal_id`` the client may choose, ``timeout`` for the
    server to accept); refused with ``REJECTED`` naming the link, the obstacle and where on
    the path when it is not. ``duration_s``: the motion's time (omitted: from the URDF's
    velocity limits, at half of them, at least 1 s). A write: it moves the robot."""

    examples = (Example(
        {"name": "r", "positions": {"j": 0.5}, "action": "/arm/fjt"},
        {("action", "action", "/arm/fjt")}),)

    name: str
    positions: tuple[tuple[str, float], ...]
    action: str = DEFAULT_TRAJECTORY_ACTION
    resolution: float = 0.01
    duration_s: float | None = None
    timeout: float = 4.0
    result_timeout: float | None = None
    goal_id: str | None = None

    def resources(self) -> tuple[Resource, ...]:
        return (ActionUse("action", self.action, FOLLOW_JOINT_TRAJECTORY, writes=True),)

    def to_args(self) -> dict[str, Any]:
        out = super().to_args()
        out["positions"] = dict(self.positions)
        return out

    @classmethod
    def from_args(cls, a: Args) -> ExecuteMotion:
        return cls(name=_robot(a), positions=joint_values(a, "positions"),
                   action=a.opt_str("action", DEFAULT_TRAJECTORY_ACTION, pattern=ROS_NAME,
                                    desc=ROS_NAME_DESC) or DEFAULT_TRAJECTORY_ACTION,
                   resolution=_resolution(a),
                   duration_s=a.opt_float("duration_s", None, low=0.0, high=3600.0,
                                          low_open=True),
                   timeout=float(a.opt_float("timeout", 4.0, low=0.0, high=300.0,
                                             low_open=True) or 4.0),
                   result_timeout=a.opt_float("result_timeout", None, low=0.0,
                                              high=86_400.0, low_open=True),
                   goal_id=a.opt_str("goal_id", None, max_len=64))

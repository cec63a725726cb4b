"""Robot ops: a URDF from a parameter, a latched topic or a file, as models and link
transforms."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Optional, cast

from protocol.commands.errors import TooLargeError
from protocol.commands.fields import (MAX_NAME, ROBOT_NAME, ROS_NAME, ROS_NAME_DESC, Args,
                                      check_float, check_str)
from protocol.commands.op import (Bridge, Example, FileUse, FrameUse, NameResolver, Op,
                                  ParameterUse, Resource, TopicUse)
from protocol.commands.results import (Answered, DescribeRobotJointsResult, Result,
                                       SetRobotJointsResult)
from protocol.commands.values import RobotSource

__all__ = ["JOINT_STATE_TYPE", "MAX_JOINTS", "CreateRobot", "DescribeRobotJoints",
           "ListRobots", "ListRobotsResult", "RemoveRobot", "RemovedRobot", "CreatedRobot",
           "RobotSummary", "SetRobotJoints", "joint_values"]


@dataclass(frozen=True)
class CreatedRobot(Result):
    """A robot as `create_robot` answers: its state (``reason`` while it waits or failed),
    where its description comes from, its URDF's name and root link (null until loaded),
    and its devices: a POLYDATA per visual, every link's pose in one TDATA on
    ``poses_device`` (each element named by its link's ``device``), the links withheld (and
    why), and the load's warnings."""

    name: str
    state: str
    source: RobotSource
    fixed_frame: Optional[str]
    tf_prefix: str
    robot: Optional[str]
    root_link: Optional[str]
    description_device: str
    links: tuple[dict[str, Any], ...]
    visuals: tuple[dict[str, Any], ...]
    withheld: tuple[dict[str, Any], ...]
    warnings: tuple[str, ...]
    reason: Optional[str] = None
    poses_device: str = ""


@dataclass(frozen=True)
class RobotSummary(Result):
    """A robot as `list_robots` and `list_bridges` count it: its devices by number;
    ``unposed``: the links tf cannot place in its fixed frame now, and why."""

    kind: str  # "robot"
    name: str
    state: str
    source: RobotSource
    fixed_frame: Optional[str]
    tf_prefix: str
    links: int
    withheld: int
    visuals: int
    description_device: str
    loads: int
    warnings: int
    namespace: Optional[str] = None
    reason: Optional[str] = None
    unposed: Optional[dict[str, Any]] = None


@dataclass(frozen=True)
class ListRobotsResult(Result):
    robots: tuple[RobotSummary, ...]


@dataclass(frozen=True)
class RemovedRobot(Result):
    """A removed robot and the devices it had."""

    name: str
    devices: tuple[str, ...]

JOINT_STATE_TYPE = "sensor_msgs/msg/JointState"
MAX_JOINTS = 1000  # per set_robot_joints: far above any URDF's joint count
_ROBOT_DESC = "a robot name of letters, digits and _"


def joint_values(a: Args, name: str) -> tuple[tuple[str, float], ...]:
    """The object ``name``: joint -> a finite position (radians, metres), at most
    `MAX_JOINTS` of them, in the order given (set_robot_joints, motion's goals and seeds)."""
    raw = a.req_obj_raw(name)
    if len(raw) > MAX_JOINTS:
        raise TooLargeError(a.path(name), f"at most {MAX_JOINTS} joints", str(len(raw)))
    pairs = []
    for joint, value in raw.items():
        path = f"{a.path(name)}.{joint}"
        check_str(joint, path, MAX_NAME, False, None, "")
        pairs.append((joint, check_float(value, path, float("-inf"), float("inf"), False)))
    return tuple(pairs)


@dataclass(frozen=True)
class CreateRobot(Op, op="create_robot", result=CreatedRobot,
                  ros_names=("source.node", "source.topic"), writes=False,
                  content=("frames", "files"),
                  creates=Bridge("robot", ("name",), section="robots")):
    """Load a robot from its URDF: one model per link visual, placed by tf lookups from
    ``fixed_frame`` (omitted = the URDF's root link) to ``tf_prefix`` + link.

    It reads what its source names (a parameter, a topic or a file) and, when the URDF
    loads, the link frames ``tf_prefix`` + link (judged then, link by link).

    ``wait``: a description not there yet (its node not on the graph, its parameter not
    set, nothing on its topic) leaves the robot waiting for it; False refuses the request
    with ``NOT_FOUND`` naming what is missing. It is how one asks, not what is made: two
    requests that differ only in it create the same robot."""

    examples = (Example(
        {"name": "r", "namespace": "PSM1", "fixed_frame": "world"},
        {("frame", "fixed_frame", "world"),
         ("parameter", "source.parameter", "PSM1/robot_state_publisher.robot_description")}),)

    name: str
    source: RobotSource = RobotSource()
    fixed_frame: str | None = None
    tf_prefix: str = ""
    namespace: str = ""
    wait: bool = field(default=True, compare=False)

    def with_names(self, resolve: NameResolver) -> CreateRobot:
        # Relative source names live in the robot's namespace: placed first, then resolved;
        # only the name its kind reads (the others keep their defaults).
        source = self.placed_source()
        if source.kind == "parameter":
            source = replace(source, node=resolve(source.node, "source.node"))
        elif source.kind == "topic":
            source = replace(source, topic=resolve(source.topic, "source.topic"))
        return replace(self, source=source)

    def placed_source(self) -> RobotSource:
        """The source with the robot's ``namespace`` applied to relative names and to the
        defaults (``{"namespace": "PSM1"}`` reads ``PSM1/robot_state_publisher``); the
        daemon then resolves the names in its own namespace."""
        source = self.source

        def place(name: str, default: str) -> str:
            if self.namespace and (name == default or not name.startswith("/")):
                return f"{self.namespace.rstrip('/')}/{name.lstrip('/')}"
            return name

        if source.kind == "parameter":
            return RobotSource("parameter", node=place(source.node, RobotSource.node),
                               parameter=source.parameter)
        if source.kind == "topic":
            return RobotSource("topic", topic=place(source.topic, RobotSource.topic))
        return source

    def resources(self) -> tuple[Resource, ...]:
        source = self.placed_source()
        uses: list[Resource] = []
        if source.kind == "parameter":
            uses.append(ParameterUse("source.parameter", (source.parameter,), source.node,
                                     "source.node"))
        elif source.kind == "topic":
            uses.append(TopicUse("source.topic", source.topic, "std_msgs/msg/String"))
        else:
            uses.append(FileUse("source.path", source.path))
        if self.fixed_frame:
            uses.append(FrameUse("fixed_frame", self.fixed_frame, client_frame=False))
        return tuple(uses)

    @classmethod
    def from_args(cls, a: Args) -> CreateRobot:
        sub = a.opt_obj("source")
        fixed = a.opt_str("fixed_frame")
        return cls(
            name=a.req_str("name", max_len=64, pattern=ROBOT_NAME,
                           desc="a robot name of letters, digits and _"),
            source=RobotSource.from_args(sub) if sub is not None else RobotSource(),
            fixed_frame=fixed,
            tf_prefix=cast(str, a.opt_str("tf_prefix", "", allow_empty=True)),
            namespace=cast(str, a.opt_str("namespace", "", allow_empty=True, pattern=ROS_NAME,
                                          desc=ROS_NAME_DESC)),
            wait=a.opt_bool("wait", True),
        )


@dataclass(frozen=True)
class RemoveRobot(Op, op="remove_robot", result=RemovedRobot, writes=False, removes="robot"):
    examples = (Example({"name": "r"}),)

    name: str

    def resources(self) -> tuple[Resource, ...]:
        return ()  # judged by who made the bridge

    @classmethod
    def from_args(cls, a: Args) -> RemoveRobot:
        return cls(name=a.req_str("name", max_len=64, pattern=ROBOT_NAME,
                                  desc="a robot name of letters, digits and _"))


@dataclass(frozen=True)
class ListRobots(Op, op="list_robots", result=ListRobotsResult, writes=False):

    examples = (Example({}),)

    def resources(self) -> tuple[Resource, ...]:
        return ()

    @classmethod
    def from_args(cls, a: Args) -> ListRobots:
        return cls()


@dataclass(frozen=True)
class DescribeRobotJoints(Op, Answered[DescribeRobotJointsResult],
                          op="describe_robot_joints", writes=False):
    """The joints of a loaded robot, from its URDF: type, limits, mimic (leader, multiplier,
    offset), whether a client sets it (``actuated``: moving and not a mimic), and the
    joint-states topic its state publisher listens to by default."""

    examples = (Example({"name": "r"}),)

    name: str

    def resources(self) -> tuple[Resource, ...]:
        return ()  # the URDF the robot already read (judged at create_robot)

    @classmethod
    def from_args(cls, a: Args) -> DescribeRobotJoints:
        return cls(name=a.req_str("name", max_len=64, pattern=ROBOT_NAME, desc=_ROBOT_DESC))


@dataclass(frozen=True)
class SetRobotJoints(Op, Answered[SetRobotJointsResult], op="set_robot_joints",
                     ros_names=("topic",),
                     writes=True):
    """Publish one sensor_msgs/JointState for a loaded robot on ``topic`` (relative names
    resolve in the daemon's namespace; `DescribeRobotJoints` gives the robot's). Names and
    limits come from the robot's URDF: an unknown, fixed or mimic joint, or a position
    outside ``[lower, upper]`` is refused naming the joint and its limit (continuous joints
    are unlimited). Mimic joints are added, computed from their leader
    (``multiplier * leader + offset``), and must fall in their own limits too. Only the
    joints given (and their mimics) are in the message: a state publisher keeps the
    others where they were, as robot_state_publisher does."""

    examples = (Example(
        {"name": "r", "positions": {"j": 0.5}, "topic": "/PSM1/joint_states"},
        {("topic", "topic", "/PSM1/joint_states")}),)

    name: str
    positions: tuple[tuple[str, float], ...]
    topic: str = "joint_states"

    def resources(self) -> tuple[Resource, ...]:
        return (TopicUse("topic", self.topic, JOINT_STATE_TYPE, writes=True),)

    def to_args(self) -> dict[str, Any]:
        out = super().to_args()
        out["positions"] = dict(self.positions)
        return out

    @classmethod
    def from_args(cls, a: Args) -> SetRobotJoints:
        return cls(name=a.req_str("name", max_len=64, pattern=ROBOT_NAME, desc=_ROBOT_DESC),
                   positions=joint_values(a, "positions"),
                   topic=cast(str, a.opt_str("topic", "joint_states", pattern=ROS_NAME,
                                             desc=ROS_NAME_DESC)))

"""Robot ops: a URDF from a parameter, a latched topic or a file, as models and link
transforms."""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

from protocol.commands.fields import ROBOT_NAME, ROS_NAME, ROS_NAME_DESC, Args
from protocol.commands.op import (Bridge, FileUse, FrameUse, Op, ParameterUse, Resource,
                                  TopicUse)
from protocol.commands.values import RobotSource

__all__ = ["CreateRobot", "ListRobots", "RemoveRobot"]


@dataclass(frozen=True)
class CreateRobot(Op, op="create_robot", writes=False,
                  creates=Bridge("robot", ("name",), section="robots")):
    """Load a robot from its URDF: one model per link visual, placed by tf lookups from
    ``fixed_frame`` (omitted = the URDF's root link) to ``tf_prefix`` + link.

    It reads what its source names (a parameter, a topic or a file) and, when the URDF
    loads, the link frames ``tf_prefix`` + link (judged then, link by link)."""

    name: str
    source: RobotSource = RobotSource()
    fixed_frame: str | None = None
    tf_prefix: str = ""
    namespace: str = ""

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
        )


@dataclass(frozen=True)
class RemoveRobot(Op, op="remove_robot", writes=False, removes="robot"):
    name: str

    def resources(self) -> tuple[Resource, ...]:
        return ()  # judged by who made the bridge

    @classmethod
    def from_args(cls, a: Args) -> RemoveRobot:
        return cls(name=a.req_str("name", max_len=64, pattern=ROBOT_NAME,
                                  desc="a robot name of letters, digits and _"))


@dataclass(frozen=True)
class ListRobots(Op, op="list_robots", writes=False):

    def resources(self) -> tuple[Resource, ...]:
        return ()

    @classmethod
    def from_args(cls, a: Args) -> ListRobots:
        return cls()

"""Parameter ops: other nodes' parameters (clients, get, set, observe) and the
daemon's own parameter server (``server_*``)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, cast

from protocol.commands.errors import OutOfRangeError
from protocol.commands.fields import MAX_NAME, MAX_TEXT, PARAM_NAME, Args, check_str
from protocol.commands.op import Bridge, Example, Op, ParameterUse, Resource
from protocol.commands.results import (Answered, GetParametersResult, ListParametersResult,
                                       ObserveParametersResult, Result, SetParametersResult)
from protocol.commands.values import ParameterValue

__all__ = ["CreateParameterClient", "GetParameters", "ListParameters", "ObserveParameters",
           "OwnParameter", "OwnParameterUndeclared", "ParameterClientBridge",
           "ParameterClientRemoved", "RemoveParameterClient", "ServerDeclareParameter",
           "ServerGetParameters", "ServerSetParameter", "ServerUndeclareParameter",
           "SetParameters"]


@dataclass(frozen=True)
class ParameterClientBridge(Result):
    """A parameter client, as `create_parameter_client` and `list_bridges` describe it: the
    device its observed changes come on, whether the node answers, what it observes."""

    kind: str  # "parameter_client"
    node: str
    device: str
    ready: bool
    observed: tuple[str, ...]


@dataclass(frozen=True)
class ParameterClientRemoved(Result):
    node: str
    device: str


@dataclass(frozen=True)
class OwnParameter(Result):
    """A parameter of the daemon's own node as it is now; ``existed``: a declaration that
    found it declared already, with the same type (absent for a set)."""

    name: str
    value: ParameterValue
    existed: Optional[bool] = None


@dataclass(frozen=True)
class OwnParameterUndeclared(Result):
    name: str


@dataclass(frozen=True)
class CreateParameterClient(Op, op="create_parameter_client", ros_names=("node",), writes=False,
                            result=ParameterClientBridge,
                            creates=Bridge("parameter_client", ("node",),
                                           section="parameter_clients")):
    """Watch another node's parameters (``/robot_state_publisher`` or ``ns/node``)."""

    examples = (Example({"node": "/n"}),)

    node: str

    def resources(self) -> tuple[Resource, ...]:
        return ()  # the node only; its parameters are judged when read

    @classmethod
    def from_args(cls, a: Args) -> CreateParameterClient:
        return cls(node=a.ros_name("node"))


@dataclass(frozen=True)
class RemoveParameterClient(
        Op, op="remove_parameter_client", ros_names=("node",), writes=False,
        removes="parameter_client", result=ParameterClientRemoved):
    examples = (Example({"node": "/n"}),)

    node: str

    def resources(self) -> tuple[Resource, ...]:
        return ()  # judged by who made the bridge

    @classmethod
    def from_args(cls, a: Args) -> RemoveParameterClient:
        return cls(node=a.ros_name("node"))


@dataclass(frozen=True)
class ListParameters(Op, Answered[ListParametersResult], op="list_parameters", ros_names=("node",),
                     content=("parameters",),
                     writes=False):
    examples = (Example({"node": "/n"}),)

    node: str

    def resources(self) -> tuple[Resource, ...]:
        return ()  # names only; the reply lists those the globs allow

    @classmethod
    def from_args(cls, a: Args) -> ListParameters:
        return cls(node=a.ros_name("node"))


@dataclass(frozen=True)
class GetParameters(Op, Answered[GetParametersResult], op="get_parameters", ros_names=("node",),
                    writes=False):
    """Values of a remote node's parameters (unknown ones come back ``not_set``)."""

    examples = (Example({"node": "/n", "names": ["p"]}, {("parameter", "names", "/n.p")}),)

    node: str
    names: tuple[str, ...]

    def resources(self) -> tuple[Resource, ...]:
        return (ParameterUse("names", self.names, self.node, "node"),)

    @classmethod
    def from_args(cls, a: Args) -> GetParameters:
        return cls(node=a.ros_name("node"), names=a.str_list("names", pattern=PARAM_NAME))


def _param_values(a: Args, name: str) -> dict[str, ParameterValue]:
    raw = a.req_obj_raw(name)
    out: dict[str, ParameterValue] = {}
    for key, value in raw.items():
        path = f"{a.path(name)}.{key}"
        check_str(key, path, MAX_NAME, False, PARAM_NAME, "a parameter name")
        out[key] = ParameterValue.from_json_value(value, path)
    if not out:
        raise OutOfRangeError(a.path(name), "at least one parameter", "an empty object")
    return out


@dataclass(frozen=True)
class SetParameters(Op, Answered[SetParametersResult], op="set_parameters", ros_names=("node",),
                    writes=True):
    """Set a remote node's parameters; the reply gives each one's outcome."""

    examples = (Example(
        {"node": "/n", "values": {"p": {"type": "integer", "value": 1}}},
        {("parameter", "values", "/n.p")}),)

    node: str
    values: dict[str, ParameterValue]

    def resources(self) -> tuple[Resource, ...]:
        return (ParameterUse("values", tuple(self.values), self.node, "node", writes=True),)

    @classmethod
    def from_args(cls, a: Args) -> SetParameters:
        return cls(node=a.ros_name("node"), values=_param_values(a, "values"))


@dataclass(frozen=True)
class ObserveParameters(Op, Answered[ObserveParametersResult],
                        op="observe_parameters", ros_names=("node",), writes=False,
                        content=("parameters",),
                        follows="parameter_client"):
    """Replace the set of a parameter client's parameters whose values are fetched and whose
    changes are pushed to the client (a STRING message under the client's device name);
    ``[]`` stops. ``all_changes``: also push every other parameter of the node that is
    declared or changed from now on (the reference's parameter node keeps those too), as
    far as the parameter globs let a client see it."""

    examples = (Example({"node": "/n", "names": ["p"]}, {("parameter", "names", "/n.p")}),)

    node: str
    names: tuple[str, ...]
    all_changes: bool = False

    def resources(self) -> tuple[Resource, ...]:
        return (ParameterUse("names", self.names, self.node, "node"),)

    @classmethod
    def from_args(cls, a: Args) -> ObserveParameters:
        return cls(node=a.ros_name("node"), names=a.str_list("names", pattern=PARAM_NAME),
                   all_changes=a.opt_bool("all_changes", False))


@dataclass(frozen=True)
class ServerDeclareParameter(Op, op="server_declare_parameter", writes=True, result=OwnParameter):
    """Declare a parameter on the daemon's own ROS node (a parameter server for Slicer)."""

    examples = (Example(
        {"name": "p", "value": {"type": "integer", "value": 1}},
        {("parameter", "name", "OWN.p")}),)

    name: str
    value: ParameterValue
    read_only: bool = False
    description: str = ""

    def resources(self) -> tuple[Resource, ...]:
        return (ParameterUse("name", (self.name,), writes=True),)

    @classmethod
    def from_args(cls, a: Args) -> ServerDeclareParameter:
        return cls(name=a.req_str("name", pattern=PARAM_NAME),
                   value=ParameterValue.from_json_value(a.any("value"), a.path("value")),
                   read_only=a.opt_bool("read_only", False),
                   description=cast(str, a.opt_str("description", "", max_len=MAX_TEXT,
                                                    allow_empty=True)))


@dataclass(frozen=True)
class ServerSetParameter(Op, op="server_set_parameter", writes=True, result=OwnParameter):
    examples = (Example(
        {"name": "p", "value": {"type": "integer", "value": 1}},
        {("parameter", "name", "OWN.p")}),)

    name: str
    value: ParameterValue

    def resources(self) -> tuple[Resource, ...]:
        return (ParameterUse("name", (self.name,), writes=True),)

    @classmethod
    def from_args(cls, a: Args) -> ServerSetParameter:
        return cls(name=a.req_str("name", pattern=PARAM_NAME),
                   value=ParameterValue.from_json_value(a.any("value"), a.path("value")))


@dataclass(frozen=True)
class ServerGetParameters(Op, op="server_get_parameters", writes=False,
                          result=GetParametersResult):
    """Values of the daemon's own parameters; ``names`` omitted or empty = all."""

    examples = (Example({"names": ["p"]}, {("parameter", "names", "OWN.p")}),)

    names: tuple[str, ...] = ()

    def resources(self) -> tuple[Resource, ...]:
        return (ParameterUse("names", self.names),)

    @classmethod
    def from_args(cls, a: Args) -> ServerGetParameters:
        return cls(names=a.str_list("names", pattern=PARAM_NAME, required=False))


@dataclass(frozen=True)
class ServerUndeclareParameter(Op, op="server_undeclare_parameter", writes=True,
                               result=OwnParameterUndeclared):
    examples = (Example({"name": "p"}, {("parameter", "name", "OWN.p")}),)

    name: str

    def resources(self) -> tuple[Resource, ...]:
        return (ParameterUse("name", (self.name,), writes=True),)

    @classmethod
    def from_args(cls, a: Args) -> ServerUndeclareParameter:
        return cls(name=a.req_str("name", pattern=PARAM_NAME))

"""Service ops: calling ROS services, and services a client serves."""

from __future__ import annotations

from dataclasses import dataclass
from dataclasses import field
from typing import Any, cast

from protocol.commands.errors import WrongTypeError
from protocol.commands.fields import MISSING, Args
from protocol.commands.op import Bridge, Example, Op, Resource, ServiceUse
from protocol.commands.results import Answered, CallServiceResult, Result
from protocol.commands.types import resolve_service_type
from protocol.commands.wire import json_type

__all__ = ["AdvertiseService", "CallService", "ServedServiceBridge", "ServiceRequest",
           "UnadvertiseService", "UnadvertisedService"]


@dataclass(frozen=True)
class ServedServiceBridge(Result):
    """A service a client serves, as `advertise_service` and `list_bridges` describe it:
    the device its calls come on and how many it answered."""

    kind: str  # "served_service"
    service: str
    type: str
    device: str
    calls: int


@dataclass(frozen=True)
class UnadvertisedService(Result):
    service: str
    device: str


def _srv_type(a: Args) -> str:
    text = a.req_str("type")
    resolve_service_type(text, a.path("type"))
    return text


@dataclass(frozen=True)
class CallService(Op, Answered[CallServiceResult], op="call_service", ros_names=("service",),
                  content=("parameters",),
                  writes=True):
    """Call a ROS service. Keep ``timeout`` below the client's own command timeout
    (3D Slicer's default is 5 s) so the daemon's TIMEOUT reply arrives first."""

    examples = (Example(
        {"service": "/s", "type": "std_srvs/srv/Trigger"},
        {("service", "service", "/s")}),)

    service: str
    type: str
    request: dict[str, Any] = field(default_factory=dict)
    timeout: float = 4.0

    def resources(self) -> tuple[Resource, ...]:
        return (ServiceUse("service", self.service, self.type, request=self.request),)

    @property
    def ros_type(self) -> str:
        return resolve_service_type(self.type)

    @classmethod
    def from_args(cls, a: Args) -> CallService:
        service, kind = a.ros_name("service"), _srv_type(a)
        raw = a.raw("request", False)
        if raw is MISSING:
            raw = {}
        elif not isinstance(raw, dict):
            raise WrongTypeError(a.path("request"), "an object", json_type(raw))
        return cls(service=service, type=kind, request=raw,
                   timeout=cast(float, a.opt_float("timeout", 4.0, low=0.0, high=300.0,
                                                   low_open=True)))


@dataclass(frozen=True)
class AdvertiseService(Op, op="advertise_service", ros_names=("service",), writes=True,
                       result=ServedServiceBridge,
                       creates=Bridge("served_service", ("service",), per_connection=True)):
    """Offer a ROS service served by this client: each call reaches the client as a
    `ServiceRequest` COMMAND, answered with an RTS_COMMAND reply ``{"response": {...}}``."""

    examples = (Example(
        {"service": "/s", "type": "std_srvs/srv/Trigger"},
        {("service", "service", "/s")}),)

    service: str
    type: str

    def resources(self) -> tuple[Resource, ...]:
        return (ServiceUse("service", self.service, self.type, serves=True),)

    @property
    def ros_type(self) -> str:
        return resolve_service_type(self.type)

    @classmethod
    def from_args(cls, a: Args) -> AdvertiseService:
        return cls(service=a.ros_name("service"), type=_srv_type(a))


@dataclass(frozen=True)
class UnadvertiseService(Op, op="unadvertise_service", ros_names=("service",),
                         result=UnadvertisedService,
                         writes=False, removes="served_service"):
    examples = (Example({"service": "/s"}),)

    service: str

    def resources(self) -> tuple[Resource, ...]:
        return ()  # only the client that serves it may

    @classmethod
    def from_args(cls, a: Args) -> UnadvertiseService:
        return cls(service=a.ros_name("service"))


@dataclass(frozen=True)
class ServiceRequest(Op, op="service_request",
                     ros_names=("service",), writes=False, to_client=True):
    """Sent by the daemon to the client that advertised ``service``: one ROS call to serve
    within ``timeout`` seconds."""

    examples = (Example({"service": "/s", "type": "std_srvs/srv/Trigger", "request": {}}),)

    service: str
    type: str
    request: dict[str, Any] = field(default_factory=dict)
    timeout: float = 4.0

    def resources(self) -> tuple[Resource, ...]:
        return ()  # the daemon sends it; no client may

    @classmethod
    def from_args(cls, a: Args) -> ServiceRequest:
        service, kind = a.ros_name("service"), _srv_type(a)
        return cls(service=service, type=kind, request=a.req_obj_raw("request"),
                   timeout=cast(float, a.opt_float("timeout", 4.0, low=0.0, high=300.0,
                                                   low_open=True)))

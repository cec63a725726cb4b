"""Parameter bridges: clients of other nodes' parameters, and a parameter server for clients.

Parameter clients (the reference's parameter nodes, plus set): one per remote node, named
with or without a namespace (relative names resolve under the daemon's namespace). They use
the node's standard rcl_interfaces services with ``call_async``, awaited on the asyncio loop.
Observed parameters are pushed, never polled: every ``/parameter_events`` message of a
watched node goes to the loop, and the client's device gets one STRING with all its observed
values (JSON with types) whenever one changes. A node that is not there yet is "not ready"
(STATUS NOT_READY on its device); a cheap timer notices when its services appear, and then
the observed values are fetched and streamed.

Parameter server: clients declare typed parameters on the daemon's own node; other ROS nodes
read and set them through the node's standard parameter services (rclpy creates them with
the node; undeclared names are refused). Every change, from either side, is streamed as a
STRING on the server device.

`to_ros_value` / `from_ros_value` are the one place where rcl_interfaces ParameterValue and
`protocol.commands.ParameterValue` meet.
"""

from __future__ import annotations

import asyncio
import logging
import math
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Optional

from rcl_interfaces.msg import Parameter as RosParameter
from rcl_interfaces.msg import ParameterDescriptor, ParameterEvent, ParameterType
from rcl_interfaces.msg import ParameterValue as RosParameterValue
from rcl_interfaces.srv import (GetParameters as GetParametersSrv,
                                GetParameterTypes as GetParameterTypesSrv,
                                ListParameters as ListParametersSrv,
                                SetParameters as SetParametersSrv)
from rclpy.client import Client
from rclpy.exceptions import ParameterException
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_parameter_events

from bridge.core.dispatch import Created, Handler, made_bridge
from bridge.core.hub import Hub, Replier
from bridge.core.content_guards import ContentGuard
from bridge.core.security import parameter_service
from bridge.ros.ros_node import RosNode
from bridge.parameters.watch import ParameterWatch
from bridge.ros.service_calls import call_ros_service, wait_until_ready
from protocol.commands import (CommandError, CommandFailedError, CreateParameterClient, ErrorCode,
                               ForbiddenError, GetParameters, GetParametersResult, ListParameters,
                               ListParametersResult, ObserveParameters, ObserveParametersResult, Op,
                               OutOfRangeError, OwnParameter, OwnParameterUndeclared,
                               ParameterClientBridge, ParameterClientRemoved, ParameterOutcome,
                               ParameterValue, RemoveParameterClient, ServerDeclareParameter,
                               ServerGetParameters, ServerSetParameter, ServerUndeclareParameter,
                               SetParameters, SetParametersResult, dumps, not_json_number)
from protocol.messages import Message, Status, StatusCode, String
from protocol.naming import DeviceNameRegistry, NameKey, metadata_for

log = logging.getLogger(__name__)

_STATUS_NAME = "slicer-ros2-bridge"
_MAX_STRING_BYTES = 0xFFFF  # an OpenIGTLink STRING's limit
# A read of another node's parameters unanswered this long is sent again (see
# services.call_ros_service): well above a loaded node's answer time, well below the timeout.
_RESEND_READS_S = 1.0
# A node's parameter services that set values (see security.PARAMETER_SERVICES).
_SETTING_SERVICES = ("set_parameters", "set_parameters_atomically")

# ---------------------------------------------------------------------------- conversion

_ROS_TYPE: dict[str, int] = {
    "not_set": ParameterType.PARAMETER_NOT_SET,
    "bool": ParameterType.PARAMETER_BOOL,
    "integer": ParameterType.PARAMETER_INTEGER,
    "double": ParameterType.PARAMETER_DOUBLE,
    "string": ParameterType.PARAMETER_STRING,
    "byte_array": ParameterType.PARAMETER_BYTE_ARRAY,
    "bool_array": ParameterType.PARAMETER_BOOL_ARRAY,
    "integer_array": ParameterType.PARAMETER_INTEGER_ARRAY,
    "double_array": ParameterType.PARAMETER_DOUBLE_ARRAY,
    "string_array": ParameterType.PARAMETER_STRING_ARRAY,
}
_KIND: dict[int, str] = {number: kind for kind, number in _ROS_TYPE.items()}


def to_ros_value(value: ParameterValue) -> RosParameterValue:
    """protocol ParameterValue -> rcl_interfaces/msg/ParameterValue."""
    msg = RosParameterValue(type=_ROS_TYPE[value.type])
    if value.type == "not_set":
        return msg
    raw = value.value
    if value.type == "byte_array":
        raw = [bytes([b]) for b in raw]  # rclpy's byte[] holds 1-byte bytes objects
    elif isinstance(raw, tuple):
        raw = list(raw)
    setattr(msg, f"{value.type}_value", raw)
    return msg


def from_ros_value(msg: RosParameterValue, path: str) -> ParameterValue:
    """rcl_interfaces/msg/ParameterValue -> protocol ParameterValue (the type is kept: an
    integer 3 stays apart from a double 3.0). JSON has no NaN or infinity: such a double is
    refused with an error naming `path`."""
    kind = _KIND.get(int(msg.type))
    if kind is None:
        raise CommandFailedError(path, "a known parameter type (0..9)", str(msg.type),
                                 code=ErrorCode.NOT_SUPPORTED)
    if kind == "not_set":
        return ParameterValue("not_set")
    raw = getattr(msg, f"{kind}_value")
    if kind == "byte_array":
        raw = [b[0] if isinstance(b, (bytes, bytearray)) else int(b) for b in raw]
    elif kind.endswith("_array"):
        raw = list(raw)
    if kind in ("double", "double_array"):
        numbers = raw if isinstance(raw, list) else [raw]
        if not all(math.isfinite(x) for x in numbers):
            raise not_json_number(path, repr(raw))
    return ParameterValue(kind, raw)


def _explain_refusal(node: str, name: str, reason: str) -> str:
    """A node's reason for refusing a parameter, made to name it. rclpy nodes answer an
    undeclared name with "Invalid access to undeclared parameter(s): []" (their list is
    always empty), which says neither which parameter nor why."""
    if reason.startswith("Invalid access to undeclared parameter"):
        return (f"{node} has not declared {name!r}: a ROS node takes only the parameters it "
                f"declared")
    return reason


def _rclpy_parameter(name: str, value: ParameterValue) -> Parameter:
    # rclpy leaves from_parameter_msg unannotated.
    return Parameter.from_parameter_msg(  # type: ignore[no-any-return]
        RosParameter(name=name, value=to_ros_value(value)))


# ---------------------------------------------------------------------------- clients


@dataclass
class ParameterClient:
    """A client of one remote node's parameters, streamed on one device."""

    node: str
    key: NameKey
    device: str
    list_client: Client
    get_client: Client
    set_client: Client
    types_client: Client
    ready: Optional[bool] = None  # None until the first check
    made_at: float = 0.0  # loop time of create_parameter_client
    observed: tuple[str, ...] = ()
    # Set: also stream every other parameter a /parameter_events message declares or changes,
    # as far as this guard (from observe_parameters) lets a client see it.
    all_changes: Optional[ContentGuard] = None
    values: dict[str, ParameterValue] = field(default_factory=dict)
    # name -> serial of the last event that changed it: a fetch that started earlier must
    # not overwrite what an event reported meanwhile.
    touched: dict[str, int] = field(default_factory=dict)

    def clients(self) -> tuple[Client, ...]:
        return (self.list_client, self.get_client, self.set_client, self.types_client)


class ParameterBridges:
    """Parameter clients of other nodes, and the daemon node's own parameter server."""

    def __init__(self, ros: RosNode, hub: Hub, names: DeviceNameRegistry, *,
                 request_timeout_s: float = 4.0, ready_wait_s: float = 2.0,
                 check_interval_s: float = 0.5) -> None:
        self._ros = ros
        self._hub = hub
        self._names = names
        self._request_timeout_s = request_timeout_s
        self._ready_wait_s = ready_wait_s
        self._check_interval_s = check_interval_s
        self.clients: dict[str, ParameterClient] = {}
        self.watches: list[ParameterWatch] = []
        self._check_timer: Optional[asyncio.TimerHandle] = None
        self._tasks: set[asyncio.Task[None]] = set()
        self._event_serial = 0
        # Read by the executor thread, replaced (never mutated) by the loop thread.
        self._watched: frozenset[str] = frozenset()
        self._events = ros.node.create_subscription(
            ParameterEvent, "/parameter_events", self._on_event_ros, qos_profile_parameter_events)
        # Parameter server.
        self._server_node = ros.fully_qualified_name
        self._server_key = NameKey.parameter_server(self._server_node)
        self._server_device = names.register(self._server_key)
        self.declared: dict[str, None] = {}  # names clients declared, in order
        self._server_stream_pending = False
        ros.node.add_post_set_parameters_callback(self._on_server_set_ros)

    # --- parameter clients -----------------------------------------------------------------
    async def create_parameter_client(self, request: CreateParameterClient,
                                      ) -> Created[ParameterClientBridge]:
        node = request.node
        existing = self.clients.get(node)
        if existing is not None:
            return Created(self._describe_client(existing), existed=True)
        key = NameKey.parameter_client(node)
        ros_node = self._ros.node
        device = self._names.register(key)
        self._hub.bridge_device(made_bridge(request), device)
        client = ParameterClient(
            node, key, device,
            list_client=ros_node.create_client(ListParametersSrv, f"{node}/list_parameters"),
            get_client=ros_node.create_client(GetParametersSrv, f"{node}/get_parameters"),
            set_client=ros_node.create_client(SetParametersSrv, f"{node}/set_parameters"),
            types_client=ros_node.create_client(GetParameterTypesSrv,
                                                f"{node}/get_parameter_types"))
        client.made_at = asyncio.get_running_loop().time()
        self.clients[node] = client
        # Give discovery a moment, so an existing node is reported ready at once.
        ready = await self._wait_all_ready(client)
        if self.clients.get(node) is client and client.ready is None:
            self._set_ready(client, ready)
        self._schedule_check()
        log.info("parameter client for %s (device %r, %s)", node, client.device,
                 "ready" if client.ready else "not ready")
        return Created(self._describe_client(client), existed=False)

    def remove_parameter_client(self, request: RemoveParameterClient) -> ParameterClientRemoved:
        client = self._client(request.node)
        del self.clients[client.node]
        self._update_watched()
        for ros_client in client.clients():
            self._ros.destroy(ros_client)
        self._hub.forget(client.device)
        self._names.release(client.key)
        return ParameterClientRemoved(client.node, client.device)

    async def list_parameters(self, request: ListParameters,
                              guard: ContentGuard) -> ListParametersResult:
        """The node's parameters a client may see (``guard``: a listing names none
        beforehand, so the dispatcher could not judge them)."""
        client = self._client(request.node)
        listed = await self._call(client, client.list_client,
                                  ListParametersSrv.Request(prefixes=[], depth=0))
        names = sorted(guard.visible_parameters(client.node, listed.result.names))
        types: dict[str, str] = {}
        if names:
            typed = await self._call(client, client.types_client,
                                     GetParameterTypesSrv.Request(names=names))
            types = {name: _KIND.get(int(number), "not_set")
                     for name, number in zip(names, typed.types)}
        return ListParametersResult(client.node, tuple(names), types)

    async def get_parameters(self, request: GetParameters) -> GetParametersResult:
        client = self._client(request.node)
        return GetParametersResult(client.node, await self._get(client, request.names))

    async def set_parameters(self, request: SetParameters,
                             caller: Optional[Replier] = None) -> SetParametersResult:
        client = self._client(request.node)
        names = list(request.values)
        if caller is not None:
            self._judge_own_write(client.node, names, "values")
        reply = await self._call(client, client.set_client, SetParametersSrv.Request(
            parameters=[RosParameter(name=name, value=to_ros_value(request.values[name]))
                        for name in names]))
        if len(reply.results) != len(names):
            raise CommandFailedError("values", f"{len(names)} results from {client.node}",
                                     str(len(reply.results)), code=ErrorCode.ROS_ERROR)
        return SetParametersResult(client.node, {
            name: ParameterOutcome(bool(result.successful),
                                   _explain_refusal(client.node, name, result.reason))
            for name, result in zip(names, reply.results)})

    async def observe_parameters(self, request: ObserveParameters,
                                 guard: ContentGuard) -> ObserveParametersResult:
        client = self._client(request.node)
        client.observed = tuple(dict.fromkeys(request.names))
        client.all_changes = guard if request.all_changes else None
        if not client.all_changes:
            client.values = {n: v for n, v in client.values.items() if n in client.observed}
        self._update_watched()
        if client.observed and client.ready:
            await self._refresh(client)  # a failure is the reply; a later (re)appearance retries
        else:
            self._stream_values(client)
        return ObserveParametersResult(client.node, client.device, tuple(client.observed),
                                       bool(client.ready), dict(client.values))

    def _client(self, node: str) -> ParameterClient:
        client = self.clients.get(node)
        if client is None:
            raise CommandFailedError("node", "a node with a parameter client "
                                     "(create_parameter_client first)", node,
                                     code=ErrorCode.NOT_FOUND)
        return client

    async def _wait_all_ready(self, client: ParameterClient) -> bool:
        # Each service is discovered on its own: all four, within one `ready_wait_s`.
        deadline = asyncio.get_running_loop().time() + self._ready_wait_s
        for ros_client in client.clients():
            left = deadline - asyncio.get_running_loop().time()
            if not await wait_until_ready(ros_client, max(0.0, left)):
                return False
        return True

    async def _call(self, client: ParameterClient, ros_client: Client, request: Any) -> Any:
        # Discovery of a node that just appeared can take seconds: it may use the whole
        # timeout before the call is UNAVAILABLE. Reads are sent again until answered (a
        # request or answer can be lost while the endpoints match); a set is sent once.
        try:
            return await call_ros_service(
                self._hub, ros_client, request, timeout=self._request_timeout_s,
                ready_wait=self._request_timeout_s,
                what=f"the parameter services of {client.node}", field="node",
                resend_every=None if ros_client is client.set_client else _RESEND_READS_S)
        except CommandFailedError as error:
            if error.error_code != ErrorCode.UNAVAILABLE or client.ready:
                raise
            # This call's wait is not all a client waited: create_parameter_client looked
            # for the node first. Say the whole time it has been looked for.
            since = asyncio.get_running_loop().time() - client.made_at
            raise CommandFailedError(error.field, error.expected,
                                     f"{error.got}; not seen in the {since:.1f} s since its "
                                     f"parameter client was made",
                                     code=ErrorCode.UNAVAILABLE) from None

    async def _get(self, client: ParameterClient,
                   names: tuple[str, ...]) -> dict[str, ParameterValue]:
        reply = await self._call(client, client.get_client,
                                 GetParametersSrv.Request(names=list(names)))
        if len(reply.values) != len(names):
            # rclpy answers an empty list if any name is unknown: ask one by one then.
            if len(names) > 1 and not reply.values:
                out: dict[str, ParameterValue] = {}
                for name in names:
                    out.update(await self._get(client, (name,)))
                return out
            return {name: ParameterValue("not_set") for name in names}
        return {name: from_ros_value(value, f"values.{name}")
                for name, value in zip(names, reply.values)}

    # --- parameter watches (for other capabilities) ----------------------------------------
    async def watch_parameter(self, node: str, name: str,
                              on_change: Callable[[ParameterValue], None], *,
                              ready_wait_s: Optional[float] = None,
                              ) -> tuple[ParameterWatch, Optional[ParameterValue]]:
        """Fetch parameter ``name`` of ``node`` (a fully qualified node name) and keep
        ``on_change(value)`` (loop thread) told of every later value: parameter events, and
        a fetch whenever the node (re)appears. Returns the watch and the value now, or None
        if the node is not there yet or does not answer (then ``on_change`` gets it when it
        does; ``watch.unanswered`` says why). The node's readiness is judged as for
        parameter clients (`ready_wait_s`, or the one given, at first, then the periodic
        check). Any other
        failed fetch (a value that cannot be read) raises `CommandError`.

        The daemon's own node is read in process, and told of changes by its set callback:
        a service call to itself can lose its reply while its own endpoints match.
        """
        if node == self._server_node:
            own = ParameterWatch(node, name, on_change, None, ready=True)
            own.value = self._own_value(name)
            self.watches.append(own)
            return own, own.value
        get_client = self._ros.node.create_client(GetParametersSrv, f"{node}/get_parameters")
        watch = ParameterWatch(node, name, on_change, get_client)
        self.watches.append(watch)
        self._update_watched()
        try:
            ready = await wait_until_ready(
                get_client, self._ready_wait_s if ready_wait_s is None else ready_wait_s)
            if watch not in self.watches:  # unwatched meanwhile
                return watch, None
            value = None
            if ready:
                try:
                    value = await self._fetch_watched(watch)
                except CommandError as error:
                    if not self._fetch_failed(watch, error):
                        raise
                    ready = False
        except BaseException:
            self.unwatch_parameter(watch)
            raise
        watch.ready = ready
        self._schedule_check()
        return watch, value

    def unwatch_parameter(self, watch: ParameterWatch) -> None:
        if watch not in self.watches:
            return
        self.watches.remove(watch)
        self._update_watched()
        if watch.get_client is not None:
            self._ros.destroy(watch.get_client)

    async def _fetch_watched(self, watch: ParameterWatch) -> ParameterValue:
        if watch.get_client is None:
            return self._own_value(watch.name)
        started = self._event_serial
        reply = await call_ros_service(
            self._hub, watch.get_client, GetParametersSrv.Request(names=[watch.name]),
            timeout=self._request_timeout_s, ready_wait=self._request_timeout_s,
            what=f"the parameter services of {watch.node}", field="source.node",
            resend_every=_RESEND_READS_S)
        value = (from_ros_value(reply.values[0], "source.parameter") if reply.values
                 else ParameterValue("not_set"))
        if watch.touched > started and watch.value is not None:
            return watch.value  # an event during the fetch is newer than the reply
        watch.value = value
        watch.unanswered = ""
        return value

    async def _refetch_watched(self, watch: ParameterWatch) -> None:
        try:
            value = await self._fetch_watched(watch)
        except CommandError as error:
            if self._fetch_failed(watch, error):
                watch.ready = False
            return
        if watch in self.watches:
            watch.on_change(value)

    @staticmethod
    def _fetch_failed(watch: ParameterWatch, error: CommandError) -> bool:
        """Log a failed fetch; True if it is worth another try (the node did not answer:
        the next readiness check that finds it up fetches again)."""
        retry = error.error_code in (ErrorCode.TIMEOUT, ErrorCode.UNAVAILABLE)
        log.warning("could not fetch %s of %s%s: %s", watch.name, watch.node,
                    " (tried again while the node is up)" if retry else "", error)
        if retry:
            watch.unanswered = str(error)
        return retry

    def _on_watched_event(self, event: ParameterEvent) -> None:
        for watch in tuple(self.watches):
            if watch.node != event.node or watch.get_client is None:
                continue
            for p in (*event.new_parameters, *event.changed_parameters):
                if p.name == watch.name:
                    self._event_changed(watch, p.value)
            if any(p.name == watch.name for p in event.deleted_parameters):
                self._event_changed(watch, RosParameterValue())

    def _event_changed(self, watch: ParameterWatch, ros_value: RosParameterValue) -> None:
        try:
            value = from_ros_value(ros_value, "source.parameter")
        except CommandError as error:
            log.warning("parameter %s of %s not usable: %s", watch.name, watch.node, error)
            return
        self._event_serial += 1
        watch.touched = self._event_serial
        watch.value = value
        watch.on_change(value)

    # --- readiness -------------------------------------------------------------------------
    def _schedule_check(self) -> None:
        if self._check_timer is None and (self.clients or self.watches):
            self._check_timer = asyncio.get_running_loop().call_later(
                self._check_interval_s, self._check_readiness)

    def _check_readiness(self) -> None:
        """Every `check_interval_s` while clients exist: one cheap rcl call per client."""
        self._check_timer = None
        for client in list(self.clients.values()):
            if client.ready is None:
                continue  # its creation is still waiting for discovery
            ready = all(ros_client.service_is_ready() for ros_client in client.clients())
            if ready != client.ready:
                self._set_ready(client, ready)
        for watch in tuple(self.watches):
            if watch.ready is None or watch.get_client is None:
                continue  # its first wait is still running, or it is the daemon's own
            ready = watch.get_client.service_is_ready()
            if ready != watch.ready:
                watch.ready = ready
                log.info("parameter %s of %s: node %s", watch.name, watch.node,
                         "available" if ready else "gone")
                if ready:  # (re)appeared: maybe with another value
                    self._spawn(self._refetch_watched(watch))
        self._schedule_check()

    def _set_ready(self, client: ParameterClient, ready: bool) -> None:
        client.ready = ready
        if not ready:
            log.info("parameter client for %s: node not available", client.node)
            self._status(client, StatusCode.NOT_READY,
                         f"not ready: {client.node} has no parameter services (yet)")
            return
        self._status(client, StatusCode.OK, f"ready: {client.node}")
        if client.observed:
            self._spawn(self._refresh_quietly(client))

    def _status(self, client: ParameterClient, code: int, text: str) -> None:
        self._hub.stream(Message(device_name=client.device,
                                 body=Status(code=code, error_name=_STATUS_NAME, text=text),
                                 metadata=metadata_for(client.key)))

    def _spawn(self, coroutine: Any) -> None:
        task = asyncio.ensure_future(coroutine)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    # --- observed values -------------------------------------------------------------------
    async def _refresh(self, client: ParameterClient) -> None:
        started = self._event_serial
        names = client.observed
        values = await self._get(client, names)
        if self.clients.get(client.node) is not client:
            return
        for name, value in values.items():
            if name in client.observed and client.touched.get(name, 0) <= started:
                client.values[name] = value
        self._stream_values(client)

    async def _refresh_quietly(self, client: ParameterClient) -> None:
        try:
            await self._refresh(client)
        except CommandError as error:
            log.warning("could not fetch the observed parameters of %s: %s", client.node, error)

    def _stream_values(self, client: ParameterClient) -> None:
        values = {n: v.to_dict() for n, v in client.values.items()
                  if client.all_changes or n in client.observed}
        # "ready": whether the node's services answered, which changes after observe's reply.
        text = dumps({"node": client.node, "ready": bool(client.ready), "values": values})
        self._stream_text(client.device, client.key, text)

    def _stream_text(self, device: str, key: NameKey, text: str) -> None:
        size = len(text.encode("utf-8"))
        if size > _MAX_STRING_BYTES:
            log.warning("%s: %d bytes of parameter values do not fit a STRING; use "
                        "get_parameters", device, size)
            self._hub.stream(Message(device_name=device, body=Status(
                code=StatusCode.OVERFLOW, error_name=_STATUS_NAME,
                text=f"values are {size} bytes, over a STRING's {_MAX_STRING_BYTES}; "
                     f"use get_parameters"), metadata=metadata_for(key)))
            return
        self._hub.stream(Message(device_name=device, body=String(text=text),
                                 metadata=metadata_for(key)))

    def _update_watched(self) -> None:
        self._watched = frozenset([node for node, client in self.clients.items()
                                   if client.observed or client.all_changes]
                                  + [w.node for w in self.watches if w.get_client is not None])

    def _on_event_ros(self, event: ParameterEvent) -> None:
        # Executor thread: only pick the watched nodes' events and hand them off.
        if event.node in self._watched:
            self._hub.call_soon(self._on_event, event)

    def _on_event(self, event: ParameterEvent) -> None:
        if self.watches:
            self._on_watched_event(event)
        client = self.clients.get(event.node)
        if client is None or not (client.observed or client.all_changes):
            return
        changed = False
        updates = [(p.name, p.value) for p in (*event.new_parameters, *event.changed_parameters)]
        updates += [(p.name, RosParameterValue()) for p in event.deleted_parameters]
        for name, ros_value in updates:
            if name not in client.observed and not (
                    client.all_changes and client.all_changes.visible_parameters(client.node,
                                                                                 [name])):
                continue
            try:
                value = from_ros_value(ros_value, name)
            except CommandError as error:
                log.warning("parameter %s of %s not streamed: %s", name, client.node, error)
                continue
            self._event_serial += 1
            client.touched[name] = self._event_serial
            if client.values.get(name) != value:
                client.values[name] = value
                changed = True
        if changed:
            self._stream_values(client)

    # --- parameter server (the daemon's own node) -----------------------------------------
    def server_declare_parameter(self, request: ServerDeclareParameter) -> OwnParameter:
        name, value, node = request.name, request.value, self._ros.node
        if value.type == "not_set":
            raise OutOfRangeError("value.type", "a parameter type other than not_set",
                                  "not_set")
        if node.has_parameter(name):
            current = self._server_value(name)
            if name in self.declared and current.type == value.type:
                return OwnParameter(name, current, existed=True)
            raise CommandFailedError("name", "a parameter not declared yet (or declared again "
                                     "with the same type)", f"{name} ({current.type})",
                                     code=ErrorCode.ALREADY_EXISTS)
        parameter = _rclpy_parameter(name, value)
        try:
            # Declared by type, then set: rclpy infers an empty list's type as byte_array.
            node.declare_parameter(name, parameter.type_, ParameterDescriptor(
                name=name, description=request.description))
            result = node.set_parameters([parameter])[0]
            if not result.successful:
                node.undeclare_parameter(name)
                raise CommandFailedError("value", f"a value ROS accepts for {name}",
                                         result.reason, code=ErrorCode.ROS_ERROR)
            if request.read_only:  # only now: a read-only parameter cannot be set
                node.set_descriptor(name, ParameterDescriptor(
                    name=name, type=_ROS_TYPE[value.type], description=request.description,
                    read_only=True))
        except (ParameterException, ValueError, TypeError) as error:
            raise CommandFailedError("name", "a parameter ROS accepts", f"{name} ({error})",
                                     code=ErrorCode.ROS_ERROR) from None
        self.declared[name] = None
        self._request_server_stream()
        return OwnParameter(name, self._server_value(name), existed=False)

    def server_set_parameter(self, request: ServerSetParameter,
                             caller: Optional[Replier] = None) -> OwnParameter:
        name, node = request.name, self._ros.node
        if not node.has_parameter(name):
            raise CommandFailedError("name", "a declared parameter (server_declare_parameter "
                                     "first)", name, code=ErrorCode.NOT_FOUND)
        if caller is not None:
            self._judge_own_write(self._server_node, (name,), "name")
        try:
            result = node.set_parameters([_rclpy_parameter(name, request.value)])[0]
        except (ParameterException, ValueError, TypeError) as error:
            raise CommandFailedError("value", f"a value ROS accepts for {name}", str(error),
                                     code=ErrorCode.ROS_ERROR) from None
        if not result.successful:
            raise CommandFailedError("value", f"a value ROS accepts for {name}", result.reason,
                                     code=ErrorCode.ROS_ERROR)
        return OwnParameter(name, self._server_value(name))

    def server_get_parameters(self, request: ServerGetParameters) -> GetParametersResult:
        node = self._ros.node
        names = request.names or tuple(sorted(node.list_parameters([], 0).names))
        return GetParametersResult(self._server_node,
                                   {name: self._own_value(name) for name in names})

    def server_undeclare_parameter(self, request: ServerUndeclareParameter,
                                   ) -> OwnParameterUndeclared:
        name = request.name
        if name not in self.declared:
            raise CommandFailedError("name", "a parameter a client declared", name,
                                     code=ErrorCode.NOT_FOUND)
        try:
            self._ros.node.undeclare_parameter(name)
        except ParameterException as error:
            raise CommandFailedError("name", "a parameter ROS lets go (read-only ones stay)",
                                     f"{name} ({type(error).__name__})",
                                     code=ErrorCode.ROS_ERROR) from None
        del self.declared[name]
        self._own_watches_changed([name])
        self._request_server_stream()
        return OwnParameterUndeclared(name)

    def _judge_own_write(self, node: str, names: Iterable[str], field: str) -> None:
        """Of the daemon's own node, a client sets only the parameters clients declared
        (`server_declare_parameter`). Its own, ``use_sim_time`` above all (it changes the
        stamp of everything the daemon publishes and broadcasts), are the operator's, set
        with ``--ros-args -p``. The one rule, whatever the route: `server_set_parameter`,
        `set_parameters` through a parameter client of the daemon's node, or a
        `call_service` of its parameter services (`judge_service_call`)."""
        if node != self._server_node:
            return
        for name in names:
            if name not in self.declared:
                raise ForbiddenError(field, "a parameter of the daemon's own node that a "
                                     "client declared (server_declare_parameter); the "
                                     "node's own are set by the operator (--ros-args -p)",
                                     f"{node}.{name}")

    def judge_service_call(self, service: str, ros_type: str, request: Any,
                           client: Optional[Replier]) -> None:
        """A `ServiceBridges` call guard: a call of the daemon node's own set_parameters
        services is judged as `set_parameters` (`_judge_own_write`)."""
        found = parameter_service(service, ros_type)
        if client is None or found is None or found[1] not in _SETTING_SERVICES:
            return
        names = [p.name for p in getattr(request, "parameters", ())]
        self._judge_own_write(found[0], names, "request.parameters")

    def _server_value(self, name: str) -> ParameterValue:
        try:
            parameter = self._ros.node.get_parameter(name)
            ros_value = parameter.get_parameter_value()
        except ParameterException:  # declared, no value yet
            return ParameterValue("not_set")
        return from_ros_value(ros_value, "value")

    def _own_value(self, name: str) -> ParameterValue:
        """A parameter of the daemon's own node, not_set if it is not declared."""
        if not self._ros.node.has_parameter(name):
            return ParameterValue("not_set")
        return self._server_value(name)

    def _on_server_set_ros(self, parameters: list[Parameter]) -> None:
        # Executor thread (a ROS node set it) or loop thread (a client did): hand off.
        names = [p.name for p in parameters]
        self._hub.call_soon(self._server_changed, names)

    def _server_changed(self, names: list[str]) -> None:
        self._own_watches_changed(names)
        if any(name in self.declared for name in names):
            self._request_server_stream()

    def _own_watches_changed(self, names: list[str]) -> None:
        for watch in tuple(self.watches):
            if watch.get_client is None and watch.name in names:
                try:
                    value = self._own_value(watch.name)
                except CommandError as error:
                    log.warning("parameter %s of %s not usable: %s", watch.name, watch.node,
                                error)
                    continue
                self._event_serial += 1
                watch.touched = self._event_serial
                watch.value = value
                watch.on_change(value)

    def _request_server_stream(self) -> None:
        if not self._server_stream_pending:
            self._server_stream_pending = True
            self._hub.call_soon(self._stream_server)

    def _stream_server(self) -> None:
        self._server_stream_pending = False
        values: dict[str, Any] = {}
        for name in self.declared:
            try:
                values[name] = self._server_value(name).to_dict()
            except CommandError as error:
                log.warning("server parameter %s not streamed: %s", name, error)
        self._stream_text(self._server_device, self._server_key,
                          dumps({"node": self._server_node, "values": values}))

    # --- capability ------------------------------------------------------------------------
    def handlers(self) -> dict[type[Op], Handler]:
        return {
            CreateParameterClient: lambda r, _: self.create_parameter_client(r),
            RemoveParameterClient: lambda r, _: self.remove_parameter_client(r),
            ListParameters: lambda r, _, guard: self.list_parameters(r, guard),
            GetParameters: lambda r, _: self.get_parameters(r),
            SetParameters: self.set_parameters,
            ObserveParameters: lambda r, _, guard: self.observe_parameters(r, guard),
            ServerDeclareParameter: lambda r, _: self.server_declare_parameter(r),
            ServerSetParameter: self.server_set_parameter,
            ServerGetParameters: lambda r, _: self.server_get_parameters(r),
            ServerUndeclareParameter: lambda r, _: self.server_undeclare_parameter(r),
        }

    def _describe_client(self, client: ParameterClient) -> ParameterClientBridge:
        return ParameterClientBridge("parameter_client", client.node, client.device,
                                     bool(client.ready), tuple(client.observed))

    def describe(self) -> list[dict[str, Any]]:
        return [self._describe_client(client).to_dict() for client in self.clients.values()]

    def state(self, guard: ContentGuard) -> dict[str, Any]:
        """The daemon node's own parameters clients declared (null while there are none)."""
        return {"parameter_server": {"node": self._server_node, "device": self._server_device,
                                     "parameters": list(self.declared)}
                if self.declared else None}

    def close(self) -> None:
        if self._check_timer is not None:
            self._check_timer.cancel()
            self._check_timer = None
        for task in tuple(self._tasks):
            task.cancel()
        self._watched = frozenset()
        # The node, its clients and subscription are destroyed with it right after.
        self.clients.clear()
        self.watches.clear()

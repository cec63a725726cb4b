"""Service bridges: clients call any installed ROS service, and offer services of their own.

`call_service` (Slicer -> ROS): the request is built from JSON with the generic codec, sent
with ``call_async`` and awaited on the asyncio loop; the rclpy future's done-callback (ROS
executor thread) only hands the result to the loop. Nothing blocks the loop or the executor.

`advertise_service` (ROS -> Slicer): an rclpy service whose callback is a coroutine. rclpy
awaits it inside the executor without blocking other callbacks (it sits in a reentrant
callback group); the coroutine hands the request to the loop, which sends the advertising
client a `service_request` COMMAND and waits for its RTS_COMMAND. The client's answer (or a
default response after the timeout) completes an rclpy future and wakes the executor.

`call_ros_service` is shared with the parameter bridges;
`message_from_json` and `client_answer` with the action bridges.
"""

from __future__ import annotations

import asyncio
import logging
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Mapping, Optional, Protocol, TypeVar

from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.client import Client
from rclpy.exceptions import InvalidHandle
from rclpy.task import Future as RosFuture

from bridge.codecs import CodecError, dict_to_message, message_to_dict
from bridge.codecs.registry import SERVICE
from bridge.core.client_replies import ClientReplies
from bridge.core.content_guards import ContentGuard
from bridge.core.dispatch import Created, Handler
from bridge.core.hub import Hub, Replier
from bridge.codecs.registry import installed_class
from bridge.ros.ros_clients import RosClientCache
from bridge.ros.ros_node import RosNode
from protocol.commands import (Op, AdvertiseService, CallService, CommandError, CommandFailedError,
                               ErrorCode, LimitReachedError, Reply, ServiceRequest,
                               UnadvertiseService, WrongTypeError, loads)
from protocol.naming import DeviceNameRegistry, NameKey, metadata_for

log = logging.getLogger(__name__)

# How often an async wait re-checks that a service server has been discovered.
_READY_POLL_S = 0.05


# ---------------------------------------------------------------------------- shared helpers


def connected_client(client: Optional[Replier], field: str, why: str) -> Replier:
    """The client a request came from; NOT_SUPPORTED for a start-up command (no client
    to ``why``: answer the calls, get the feedback...)."""
    if client is None:
        raise CommandFailedError(field, f"a request from a connected client (it {why})",
                                 "a start-up command", code=ErrorCode.NOT_SUPPORTED)
    return client


def already_served(kind: str, name: str, ros_type: str, client: Replier,
                   owner: Optional[Replier], owner_type: str,
                   graph: Iterable[tuple[str, list[str]]]) -> bool:
    """Whether `client` already serves the ``kind`` (service, action) `name` as `ros_type`
    (advertising again is idempotent); ALREADY_EXISTS if another client (`owner`, serving
    it as `owner_type`) or a ROS node in `graph` ((name, types) pairs) serves it."""
    if owner is not None:
        if owner is client and owner_type == ros_type:
            return True
        raise CommandFailedError(kind, f"a {kind} no other client advertises (or the same "
                                 "type again)", f"{name} ({owner_type})",
                                 code=ErrorCode.ALREADY_EXISTS)
    for found, types in graph:
        if found == name:
            raise CommandFailedError(kind, f"a {kind} no ROS node serves yet",
                                     f"{name} ({', '.join(types)})",
                                     code=ErrorCode.ALREADY_EXISTS)
    return False


class Advertised(Protocol):
    """A ROS service or action a client serves: who advertised it."""

    @property
    def owner(self) -> Replier: ...


A = TypeVar("A", bound=Advertised)


def advertised_by(served: Mapping[str, A], kind: str, name: str,
                  client: Optional[Replier]) -> A:
    """The ``kind`` (service, action) `name` of `served` that `client` advertises (the
    operator's config: whoever does); NOT_FOUND naming the field ``kind`` otherwise. The one
    rule of who may unadvertise."""
    entry = served.get(name)
    if entry is None or (client is not None and entry.owner is not client):
        raise CommandFailedError(kind, f"{'an' if kind[0] in 'aeiou' else 'a'} {kind} this "
                                 "client advertises", name,
                                 code=ErrorCode.NOT_FOUND)
    return entry


async def wait_until_ready(client: Client, wait_s: float) -> bool:
    """True once `client` sees a server, False after `wait_s` (polled on the loop: the
    check is one cheap rcl call, and no thread blocks)."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + wait_s
    while not client.service_is_ready():
        if loop.time() >= deadline:
            return False
        await asyncio.sleep(_READY_POLL_S)
    return True


async def call_ros_service(hub: Hub, client: Client, request: Any, *, timeout: float,
                           ready_wait: float, what: str, field: str,
                           resend_every: Optional[float] = None) -> Any:
    """Call a ROS service from the asyncio loop and return its response.

    Waits up to ``min(timeout, ready_wait)`` for the server (else UNAVAILABLE), then for the
    response until ``timeout`` has passed in all (else TIMEOUT). The errors name ``field``.

    ``resend_every`` is for idempotent requests only (reads): the request is sent again at
    that interval until an answer comes, and the first answer wins. A server seen in the
    graph may not have matched this client's request writer or response reader yet (Fast
    DDS waits 100 ms for the latter, then drops the response: ros2/rmw_fastrtps#392), so on
    a busy machine the first request or its answer can be lost outright.
    """
    loop = asyncio.get_running_loop()
    start = loop.time()
    deadline = start + timeout
    outcome: asyncio.Future[Any] = loop.create_future()
    sent: list[RosFuture] = []

    def send() -> None:
        ros_future = client.call_async(request)
        sent.append(ros_future)
        # Runs in the executor thread (or at once if already done): hand off only.
        ros_future.add_done_callback(
            lambda done: hub.call_soon(_transfer, done, outcome))

    try:
        if not await wait_until_ready(client, min(timeout, ready_wait)):
            raise CommandFailedError(field, f"{what} to be available",
                                     f"no server after {min(timeout, ready_wait):g} s",
                                     code=ErrorCode.UNAVAILABLE)
        send()
        while True:
            left = deadline - loop.time()
            wait = left if resend_every is None else min(left, resend_every)
            done, _ = await asyncio.wait((outcome,), timeout=max(0.0, wait))
            if done:
                return outcome.result()
            if loop.time() >= deadline:
                raise CommandFailedError(field, f"a response from {what} within {timeout:g} s",
                                         "no response", code=ErrorCode.TIMEOUT)
            send()
    except InvalidHandle:  # the bridge was removed meanwhile
        raise CommandFailedError(field, f"{what} to be available", "a removed client",
                                 code=ErrorCode.UNAVAILABLE) from None
    finally:
        for ros_future in sent:
            if not ros_future.done():
                client.remove_pending_request(ros_future)


def _transfer(ros_future: RosFuture, outcome: asyncio.Future[Any]) -> None:
    if outcome.done():  # timed out meanwhile
        return
    if ros_future.cancelled():
        outcome.set_exception(CommandFailedError("service", "a response", "a cancelled call",
                                                 code=ErrorCode.ROS_ERROR))
    elif ros_future.exception() is not None:
        outcome.set_exception(CommandFailedError(
            "service", "a response", str(ros_future.exception()),
            code=ErrorCode.ROS_ERROR))
    else:
        outcome.set_result(ros_future.result())


def message_from_json(cls: Any, data: dict[str, Any], path: str) -> Any:
    """A message of `cls` from a client's JSON fields; `WrongTypeError` naming the field
    under `path` (``request.data``)."""
    try:
        return dict_to_message(cls, data)
    except CodecError as error:
        raise WrongTypeError(f"{path}.{error.field}" if error.field else path,
                             error.expected, error.got) from None


def client_answer(text: str) -> dict[str, Any]:
    """The payload of a client's RTS_COMMAND answer to a COMMAND the daemon sent: an
    ordinary `Reply` (its result) or the bare object, judged by its JSON (3D Slicer's Status
    metadata is junk). A refusal (``ok: false``) raises `CommandFailedError`."""
    data = loads(text)
    if "ok" in data:  # a Reply envelope
        reply = Reply.from_json(text)
        if not reply.ok:
            assert reply.error is not None
            raise CommandFailedError("ok", "true", f"false ({reply.error.message})")
        data = reply.result
    return data


# ---------------------------------------------------------------------------- bridges


@dataclass
class CalledService:
    """A cached client for `call_service` (one per service and type)."""

    service: str
    ros_type: str
    client: Client
    device: str
    key: NameKey
    calls: int = 0
    in_use: int = 0  # calls waiting for their answer: the client must not go meanwhile
    last_used: float = 0.0  # loop time


@dataclass
class ServedService:
    """A ROS service answered by one client (the one that advertised it)."""

    service: str
    ros_type: str
    srv_class: Any
    owner: Replier
    key: NameKey
    device: str
    handle: Any = None  # rclpy Service
    calls: int = 0
    # Touched only in the executor thread: calls being served, and a destroy waiting on them.
    inflight: int = 0
    destroy_pending: bool = False
    closed: bool = False


# Judges a call_service request before it is sent: (service, its type, the ROS request,
# the calling client or None for the operator); raises a CommandError to refuse it.
CallGuard = Callable[[str, str, Any, Optional[Replier]], None]

# call_service's cached rclpy clients: how many at most, and how long one may sit unused.
MAX_SERVICE_CLIENTS = 64
# A withdrawn service lives this long after its last answer: rclpy sends a response after
# the handler returns (another executor thread may run first), and a destroyed service's
# writer drops a reliable response its caller has not taken yet.
SERVICE_LINGER_S = 1.0
IDLE_SERVICE_CLIENT_S = 60.0
# Calls one client may have waiting at once: a quarter of the clients above, so that one
# client calling absent services cannot take every slot from the others.
MAX_CALLS_PER_CLIENT = MAX_SERVICE_CLIENTS // 4


class ServiceBridges:
    """The daemon's service clients (`call_service`) and client-served services."""

    def __init__(self, ros: RosNode, hub: Hub, names: DeviceNameRegistry, *,
                 answer_timeout_s: float = 4.0,
                 max_service_clients: int = MAX_SERVICE_CLIENTS,
                 max_calls_per_client: int = MAX_CALLS_PER_CLIENT,
                 idle_client_s: float = IDLE_SERVICE_CLIENT_S,
                 replies: Optional[ClientReplies] = None) -> None:
        self._ros = ros
        self._hub = hub
        self._names = names
        self._answer_timeout_s = answer_timeout_s
        # Served coroutines wait for a client without holding a mutually exclusive group
        # (the node's default group also runs every subscription).
        self._group = ReentrantCallbackGroup()
        # call_service's rclpy clients: at most `max_service_clients`, none kept idle.
        self.called: RosClientCache[CalledService] = RosClientCache(
            capacity=max_service_clients, idle_s=idle_client_s, destroy=self._destroy_client,
            refusal=lambda service: LimitReachedError(
                "service", f"at most {max_service_clients} services called at once",
                f"a call to {service} more"))
        # The calls each client is waiting for (their tasks): a slot a client holds goes
        # with it, and no client holds more than `max_calls_per_client`.
        self._calls: dict[Replier, set[asyncio.Task[Any]]] = {}
        self._max_calls_per_client = max_calls_per_client
        self._call_guards: list[CallGuard] = []
        self.served: dict[str, ServedService] = {}
        # Withdrawn services still lingering (SERVICE_LINGER_S), by name: advertised again,
        # the old one goes at once, so that it answers no call of the new one's.
        self._lingering: dict[str, ServedService] = {}
        # Calls of served services wait for their client's answer here.
        self._replies = replies if replies is not None else ClientReplies(hub)
        hub.add_closed_listener(self._on_client_closed)

    # --- call_service ----------------------------------------------------------------------
    def add_call_guard(self, guard: CallGuard) -> None:
        """``guard(service, ros_type, request, client)`` judges each call before it is sent
        (raises a `CommandError` to refuse it): the rules another capability keeps about a
        service (an action's hidden services) then hold on this route too."""
        self._call_guards.append(guard)

    async def call_service(self, request: CallService, client: Optional[Replier],
                           guard: ContentGuard) -> dict[str, Any]:
        """``guard``: a parameter listing's reply shows what the parameter globs allow."""
        service = request.service
        ros_type = request.ros_type
        srv = installed_class(SERVICE, request.type, ros_type)
        ros_request = message_from_json(srv.Request, request.request, "request")
        for judge in self._call_guards:
            judge(service, ros_type, ros_request, client)
        mine = self._calls.get(client) if client is not None else None
        if mine is not None and len(mine) >= self._max_calls_per_client:
            raise LimitReachedError("service", f"at most {self._max_calls_per_client} calls "
                                    f"waiting for an answer per client", f"a call to "
                                    f"{service} more")
        entry = self.called.client((service, ros_type),
                                   lambda: self._new_client(service, ros_type, srv))
        task = asyncio.current_task()
        if client is not None and task is not None:
            self._calls.setdefault(client, set()).add(task)
        self.called.take(entry)
        try:
            # The whole timeout may go to discovery: a server missed by the first
            # announcements is found at the next round (Fast DDS: every 3 s, later under load).
            response = await call_ros_service(self._hub, entry.client, ros_request,
                                              timeout=request.timeout,
                                              ready_wait=request.timeout,
                                              what=f"service {service}", field="service")
        finally:
            self.called.release(entry)
            if client is not None and task is not None:
                self._forget_call(client, task)
        entry.calls += 1
        return {"service": service, "type": ros_type, "response":
                guard.service_reply(message_to_dict(response))}

    def _new_client(self, service: str, ros_type: str, srv: Any) -> CalledService:
        client = self._ros.node.create_client(srv, service, callback_group=self._group)
        key = NameKey.service_client(service)
        return CalledService(service, ros_type, client, self._names.register(key), key)

    def _destroy_client(self, entry: CalledService) -> None:
        """A client the cache dropped: destroyed, its device name released once no client
        of another type of the same service holds it."""
        self._ros.destroy(entry.client)
        if not any(e.key == entry.key for e in self.called.values()):
            self._names.release(entry.key)

    def _forget_call(self, client: Replier, task: asyncio.Task[Any]) -> None:
        mine = self._calls.get(client)
        if mine is not None:
            mine.discard(task)
            if not mine:
                del self._calls[client]

    # --- advertise_service -----------------------------------------------------------------
    def advertise_service(self, request: AdvertiseService,
                          client: Optional[Replier]) -> Created:
        client = connected_client(client, "service", "answers the calls")
        service = request.service
        ros_type = request.ros_type
        srv = installed_class(SERVICE, request.type, ros_type)
        graph = self._ros.node.get_service_names_and_types()
        lingering = self._lingering.pop(service, None)
        if lingering is not None:  # ours, withdrawn: it goes now, and is no other's server
            self._ros.executor.create_task(self._destroy_if_idle, lingering)
            graph = [(name, types) for name, types in graph if name != service]
        existing = self.served.get(service)
        if already_served("service", service, ros_type, client,
                          existing.owner if existing else None,
                          existing.ros_type if existing else "", graph):
            assert existing is not None
            return Created(_describe_served(existing), existed=True)
        key = NameKey.service_server(service)
        served = ServedService(service, ros_type, srv, client, key, self._names.register(key))
        served.handle = self._ros.node.create_service(srv, service, self._callback_for(served),
                                                      callback_group=self._group)
        self.served[service] = served
        log.info("serving %s (%s) for client %s", service, ros_type,
                 getattr(client, "peer", "?"))
        return Created(_describe_served(served), existed=False)

    def unadvertise_service(self, request: UnadvertiseService,
                            client: Optional[Replier]) -> dict[str, Any]:
        service = request.service
        served = advertised_by(self.served, "service", service, client)
        self._unadvertise(served)
        return {"service": service, "device": served.device}

    def _callback_for(self, served: ServedService) -> Any:
        async def serve(request: Any, response: Any) -> Any:
            # Executor thread. An exception here would stop the executor: never raise.
            served.inflight += 1
            try:
                if served.closed:
                    return response
                answer = RosFuture(executor=self._ros.executor)
                self._hub.call_soon(self._forward, served, request, answer)
                outcome = await answer
                return outcome if outcome is not None else response
            except Exception:
                log.exception("serving a call of %s failed; the caller gets a default response",
                              served.service)
                return response
            finally:
                served.inflight -= 1
                if served.destroy_pending and not served.inflight:
                    # rclpy sends the response after this step: destroy well after it.
                    self._hub.call_soon(self._destroy_later, served)
        return serve

    def _forward(self, served: ServedService, request: Any, answer: RosFuture) -> None:
        """A ROS call to a served service (loop thread): ask the client that serves it."""
        if served.closed:
            self._settle(answer, None)
            return
        served.calls += 1

        def silence(timed_out: bool) -> None:
            if timed_out:
                log.warning("client %s did not answer a call of %s within %g s; the caller "
                            "gets a default response", getattr(served.owner, "peer", "?"),
                            served.service, self._answer_timeout_s)
            self._settle(answer, None)

        try:
            self._replies.ask(
                served.owner, served.device,
                ServiceRequest(service=served.service, type=served.ros_type,
                               request=message_to_dict(request),
                               timeout=self._answer_timeout_s),
                metadata_for(served.key, ros_type=served.ros_type),
                timeout=self._answer_timeout_s, about=served,
                on_answer=lambda text: self._settle(answer, self._response_from(served, text)),
                on_silence=silence)
        except (CodecError, CommandError) as error:
            log.warning("cannot forward a call of %s to its client (%s); the caller gets a "
                        "default response", served.service, error)
            self._settle(answer, None)

    def _response_from(self, served: ServedService, text: str) -> Any:
        """The client's answer -> a Response, judged by its JSON (3D Slicer's Status
        metadata is junk); None (a default response) with a warning if unusable."""
        try:
            raw = client_answer(text).get("response")
            if not isinstance(raw, dict):
                raise WrongTypeError("response", "an object with the response fields",
                                     type(raw).__name__ if raw is not None else "nothing")
            return dict_to_message(served.srv_class.Response, raw)
        except (CommandError, CodecError) as error:
            log.warning("the answer to a call of %s is unusable (%s); the caller gets a default "
                        "response", served.service, error)
            return None

    def _settle(self, answer: RosFuture, response: Any) -> None:
        if not answer.done():
            answer.set_result(response)
        # The executor resumes a waiting coroutine only when something wakes it.
        self._ros.executor.wake()

    def _unadvertise(self, served: ServedService) -> None:
        served.closed = True
        self.served.pop(served.service, None)
        self._replies.withdraw(served)  # its callers waiting for an answer get a default one
        self._lingering[served.service] = served
        self._names.release(served.key)
        self._hub.forget(served.device)
        # Destroyed in the executor thread once no call is being answered, and a while after
        # the last answer (SERVICE_LINGER_S); a destroyed handle would stop the executor.
        self._destroy_later(served)
        log.info("no longer serving %s", served.service)

    def _destroy_later(self, served: ServedService) -> None:
        """(loop thread) `_destroy_if_idle` in the executor, SERVICE_LINGER_S from now."""
        asyncio.get_running_loop().call_later(
            SERVICE_LINGER_S, lambda: self._ros.executor.create_task(self._destroy_if_idle,
                                                                     served))

    def _destroy_if_idle(self, served: ServedService) -> None:
        if served.inflight:
            served.destroy_pending = True
            return
        served.destroy_pending = False
        if self._lingering.get(served.service) is served:  # (the loop may replace it)
            self._lingering.pop(served.service, None)
        if served.handle is not None:
            try:
                self._ros.node.destroy_service(served.handle)
            except Exception:  # never let cleanup stop the executor
                log.exception("destroying the service %s failed", served.service)
            served.handle = None

    def _on_client_closed(self, client: Replier) -> None:
        for served in [s for s in self.served.values() if s.owner is client]:
            self._unadvertise(served)
        # Nobody waits for its calls' answers any more: their slots are free now.
        for task in self._calls.pop(client, set()):
            task.cancel()

    # --- capability ------------------------------------------------------------------------
    def handlers(self) -> dict[type[Op], Handler]:
        return {
            CallService: self.call_service,
            AdvertiseService: self.advertise_service,
            UnadvertiseService: self.unadvertise_service,
        }

    def describe(self) -> list[dict[str, Any]]:
        return [_describe_served(served) for served in self.served.values()]

    def state(self, guard: ContentGuard) -> dict[str, Any]:
        """call_service's cached clients (not bridges: the daemon makes and drops them)."""
        return {"service_clients": [
            {"service": entry.service, "type": entry.ros_type, "device": entry.device,
             "calls": entry.calls, "waiting": entry.in_use,
             "ready": entry.client.service_is_ready()} for entry in self.called.values()]}

    def close(self) -> None:
        # The node (and its services and clients) is destroyed right after; only make sure
        # no ROS caller waits for a client that is gone.
        for served in list(self.served.values()):
            served.closed = True
            self._replies.withdraw(served)
        self.served.clear()
        self.called.close()


def _describe_served(served: ServedService) -> dict[str, Any]:
    out: dict[str, Any] = {"kind": "served_service", "service": served.service,
                           "type": served.ros_type, "device": served.device,
                           "calls": served.calls}
    return out

"""Service bridges: clients call any installed ROS service, and offer services of their own.

`call_service` (Slicer -> ROS): the request is built from JSON with the generic codec, sent
with ``call_async`` and awaited on the asyncio loop; the rclpy future's done-callback (ROS
executor thread) only hands the result to the loop. Nothing blocks the loop or the executor.

`advertise_service` (ROS -> Slicer): an rclpy service whose callback is a coroutine. rclpy
awaits it inside the executor without blocking other callbacks (it sits in a reentrant
callback group); the coroutine hands the request to the loop, which sends the advertising
client a `service_request` COMMAND and waits for its RTS_COMMAND. The client's answer (or a
default response after the timeout) completes an rclpy future and wakes the executor.

What it shares with other capabilities lives outside it: `bridge.ros.service_calls` (calls,
with the parameter bridges), `bridge.core.served` (advertised entities, with the action
bridges), `bridge.codecs.message_from_json` (a message from a client's JSON).
"""

from __future__ import annotations

import asyncio
import logging
from dataclasses import dataclass
from typing import Any, Callable, Optional

from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.client import Client
from rclpy.task import Future as RosFuture

from bridge.codecs import CodecError, dict_to_message, message_from_json, message_to_dict
from bridge.codecs.registry import SERVICE
from bridge.core.client_replies import ClientReplies
from bridge.core.content_guards import ContentGuard
from bridge.core.dispatch import Created, Handler
from bridge.core.served import advertised_by, already_served, client_answer, connected_client
from bridge.core.hub import Hub, Replier
from bridge.codecs.registry import installed_class
from bridge.ros.ros_clients import RosClientCache
from bridge.ros.ros_node import RosNode
from bridge.ros.service_calls import call_ros_service
from protocol.commands import (AdvertiseService, CallService, CallServiceResult, CommandError,
                               LimitReachedError, Op, ServedServiceBridge, ServiceRequest,
                               UnadvertiseService, UnadvertisedService, WrongTypeError)
from protocol.naming import DeviceNameRegistry, NameKey, metadata_for

log = logging.getLogger(__name__)

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
                           guard: ContentGuard) -> CallServiceResult:
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
        return CallServiceResult(service, ros_type,
                                 guard.service_reply(message_to_dict(response)))

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
                          client: Optional[Replier]) -> Created[ServedServiceBridge]:
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
                            client: Optional[Replier]) -> UnadvertisedService:
        service = request.service
        served = advertised_by(self.served, "service", service, client)
        self._unadvertise(served)
        return UnadvertisedService(service, served.device)

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
        return [_describe_served(served).to_dict() for served in self.served.values()]

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


def _describe_served(served: ServedService) -> ServedServiceBridge:
    return ServedServiceBridge("served_service", served.service, served.ros_type,
                               served.device, served.calls)

"""Command dispatch: a client's COMMAND -> one handler per op -> an RTS_COMMAND reply.

Every request gets a reply carrying its command id: a result, or an error naming the field,
what was expected and what came. Nothing a request does can take the daemon down: an
unexpected exception is logged as a bug and answered as INTERNAL.
"""

from __future__ import annotations

import asyncio
import inspect
import logging
from typing import Any, Awaitable, Callable, Mapping, Protocol, Sequence, Union

from bridge.hub import Hub, Replier
from bridge.ros_node import RosNode
from bridge.security import BridgeQuota, FileResolver, FrameResolver, SecurityPolicy, strip_frame
from protocol import commands as c
from protocol.commands import (CommandError, CommandFailedError, ErrorCode, OutOfRangeError,
                               Reply)
from protocol.messages import Command, Message, RtsCommand

log = logging.getLogger(__name__)

Result = Mapping[str, Any]
# A handler gets the parsed request and the client that sent it (None for start-up config).
Handler = Callable[[Any, Union[Replier, None]], Union[Result, Awaitable[Result]]]

DAEMON_VERSION = "0.1.0"


class Capability(Protocol):
    """One area of the daemon (topics, tf, parameters, services, robots)."""

    def handlers(self) -> Mapping[str, Handler]:
        """The ops it serves: op name -> handler."""
        ...

    def describe(self) -> list[dict[str, Any]]:
        """Its live bridges, for `list_bridges`."""
        ...

    def close(self) -> None: ...


class Dispatcher:
    def __init__(self, ros: RosNode, hub: Hub, capabilities: Sequence[Capability], *,
                 policy: SecurityPolicy | None = None,
                 resolve_frame: FrameResolver = strip_frame,
                 resolve_file: FileResolver | None = None) -> None:
        self._ros = ros
        self._hub = hub
        self._capabilities = tuple(capabilities)
        # Security is checked here, by request fields, so no capability needs to know it.
        self._policy = policy or SecurityPolicy()
        # The tf capability's own frame resolution (--frame-prefix), so frame globs judge
        # the frame that is really looked up or broadcast.
        self._resolve_frame = resolve_frame
        self._resolve_file = resolve_file
        self._quota = BridgeQuota(self._policy.max_bridges_per_client)
        hub.add_closed_listener(self._quota.forget)
        self._tasks: set[asyncio.Task[None]] = set()
        # The one table of what this daemon serves, built from each capability's own list.
        # Ops of the schema missing here are answered NOT_SUPPORTED, naming the op.
        self._handlers: dict[str, Handler] = {
            c.Hello.op: self._hello,
            c.ListBridges.op: self._list_bridges,
            c.ListTopics.op: self._list_topics,
            c.ListServices.op: self._list_services,
        }
        for capability in self._capabilities:
            for op, handler in capability.handlers().items():
                if op not in c.REQUEST_TYPES:
                    raise ValueError(f"{op!r} is not an op of the command schema")
                if op in self._handlers:
                    raise ValueError(f"two handlers for {op!r}")
                self._handlers[op] = handler

    # --- entry points -------------------------------------------------------------------
    def handle(self, message: Message, client: Replier) -> None:
        """A COMMAND from a client (loop thread): reply now, or when an async op is done."""
        body = message.body
        assert isinstance(body, Command)
        try:
            request = c.parse_request(body.name, body.text)
            outcome = self._run(request, client)
        except Exception as error:  # noqa: BLE001 - every failure becomes a reply
            self._reply(client, message, self._failure(body.name, error))
            return
        if inspect.isawaitable(outcome):
            task = asyncio.ensure_future(self._finish(outcome, client, message))
            self._tasks.add(task)
            task.add_done_callback(self._tasks.discard)
        else:
            self._reply(client, message, Reply.success(body.name, outcome))

    async def execute(self, op: str, arguments: Mapping[str, Any]) -> Result:
        """Run one command without a client (start-up config); raises `CommandError`."""
        request = c.parse_request(op, c.dumps(dict(arguments)))
        outcome = self._run(request, None)
        if inspect.isawaitable(outcome):
            return await outcome
        return outcome

    def close(self) -> None:
        for task in tuple(self._tasks):
            task.cancel()
        for capability in reversed(self._capabilities):
            capability.close()

    # --- plumbing -----------------------------------------------------------------------
    def _run(self, request: c.Request, client: Replier | None) -> Result | Awaitable[Result]:
        handler = self._handlers.get(request.op)
        if handler is None:
            raise CommandFailedError("op", "an op this daemon serves: " +
                                     ", ".join(sorted(self._handlers)), request.op,
                                     code=ErrorCode.NOT_SUPPORTED)
        self._policy.check_request(request, self._resolve, self._ros.fully_qualified_name,
                                   self._resolve_frame, from_client=client is not None,
                                   resolve_file=self._resolve_file)
        if client is None:  # start-up config: judged by the policy, not counted
            return handler(request, client)
        reserved = self._quota.reserve(client, request.op)
        try:
            outcome = handler(request, client)
        except BaseException:
            self._quota.settle(client, request.op, reserved, None)
            raise
        if inspect.isawaitable(outcome):
            return self._counted(outcome, client, request.op, reserved)
        self._quota.settle(client, request.op, reserved, outcome)
        return outcome

    async def _counted(self, outcome: Awaitable[Result], client: Replier, op: str,
                       reserved: bool) -> Result:
        result: Result | None = None
        try:
            result = await outcome
            return result
        finally:
            self._quota.settle(client, op, reserved, result)

    def _resolve(self, name: str, field: str) -> str:
        try:
            return self._ros.resolve_topic(name)
        except Exception as error:  # rclpy raises several name-validation exceptions
            raise OutOfRangeError(field, "a valid ROS name", f"{name!r} ({error})") from None

    async def _finish(self, outcome: Awaitable[Result], client: Replier,
                      message: Message) -> None:
        body = message.body
        assert isinstance(body, Command)
        try:
            reply = Reply.success(body.name, await outcome)
        except Exception as error:  # noqa: BLE001
            reply = self._failure(body.name, error)
        self._reply(client, message, reply)

    @staticmethod
    def _failure(op: str, error: BaseException) -> Reply:
        if not isinstance(error, CommandError):
            log.exception("command %s failed unexpectedly", op, exc_info=error)
        else:
            log.info("command %s refused: %s", op, error)
        return c.reply_for_exception(op, error)

    @staticmethod
    def _reply(client: Replier, request: Message, reply: Reply) -> None:
        body = request.body
        assert isinstance(body, Command)
        client.send_message(Message(
            device_name=request.device_name,
            body=RtsCommand(command_id=body.command_id, name=body.name, text=reply.to_json()),
            metadata=reply.metadata(), message_id=request.message_id))

    # --- small handlers -----------------------------------------------------------------
    def _hello(self, request: c.Hello, client: Replier | None) -> Result:
        return {"schema": c.SCHEMA_VERSION, "version": DAEMON_VERSION,
                "node": self._ros.fully_qualified_name, "ops": sorted(self._handlers)}

    def _list_bridges(self, request: c.ListBridges, client: Replier | None) -> Result:
        bridges = [bridge for capability in self._capabilities
                   for bridge in capability.describe()]
        return {"bridges": bridges, "devices": self._hub.devices(),
                "clients": [client.describe() for client in self._hub.clients],
                "hub_dropped": self._hub.dropped}

    def _list_topics(self, request: c.ListTopics, client: Replier | None) -> Result:
        return {"topics": [{"topic": name, "types": list(types)}
                           for name, types in self._ros.node.get_topic_names_and_types()]}

    def _list_services(self, request: c.ListServices, client: Replier | None) -> Result:
        return {"services": [{"service": name, "types": list(types)}
                             for name, types in self._ros.node.get_service_names_and_types()]}

"""Command dispatch: a client's COMMAND -> one handler per op -> an RTS_COMMAND reply.

Every request gets a reply carrying its command id: a result, or an error naming the field,
what was expected and what came. Nothing a request does can take the daemon down: an
unexpected exception is logged as a bug and answered as INTERNAL.

Capabilities register one handler per request class. What the dispatcher does around a
handler comes from the op's declarations (`protocol.commands.op`): its ROS names and a
client's frame ids are resolved once (`Op.with_names`, `Op.with_frames`), the security
policy judges its resources, the content it declares gets its guard (the handler's third
argument, `ContentGuard`: capabilities apply the policy inside messages and results without
knowing it), a creation (its handler returns `Created`) is counted against
its client's quota and recorded with who holds it (the operator's start-up config or the
clients that asked for it), and a removal is allowed by the ownership rules
(`bridge.core.security.BridgeOwners`). A client's bridge ends when the last client holding
it leaves, unless one kept it (`keep_bridge`): the dispatcher runs its kind's remove op, as
the operator. Who receives a bridge's streams follows from who holds it
(`BridgeOwners.audience`): the dispatcher tells the hub whenever that changes, and each
capability reports its bridges' devices to the hub (`Hub.bridge_device`, keyed by
`bridge_key`).

Creations and removals of one bridge (its kind and identity) run one at a time, in the
order they came (`BridgeLocks`): a removal that arrives while an asynchronous creation of
the same bridge still waits (a parameter client waiting for its node) runs once that
creation is done, never against a half-made bridge. Requests for other bridges do not wait.
"""

from __future__ import annotations

import asyncio
import inspect
import logging
import time
from collections import deque
from dataclasses import dataclass, replace
from typing import (Any, Awaitable, Callable, Generic, Mapping, Optional, Protocol, Sequence,
                    TypeVar, Union, cast)

from bridge.core.content_guards import ContentGuard
from bridge.core.heavy import HeavyWork, LargeResult, OffLoop
from bridge.core.hub import Hub, Replier, Subscriber
from bridge.core.logging_limits import RateLimitedLog
from bridge.core.security import (OPERATOR, WRITES, BridgeKey, BridgeOwners, BridgeQuota,
                                  FileResolver, SecurityPolicy, strip_frame)
from protocol.auth import new_challenge, verify
from protocol.freshness import daemon_clock_ms
from protocol import commands as c
from protocol.commands import (CommandError, CommandFailedError, ErrorCode, ForbiddenError,
                               NameResolver, Op, Reply)
from protocol.messages import Command, Message, RtsCommand

log = logging.getLogger(__name__)

Result = Mapping[str, Any]


# A handler's reply: its op's typed result (`protocol.commands.Result`), made the JSON
# object here, in `_created`.
Answer = Union[Result, c.Result]
R = TypeVar("R", bound=Answer)


@dataclass(frozen=True)
class Created(Generic[R]):
    """What a create op's handler returns: its reply, and whether the bridge was there
    already (then the client's quota slot goes back). The reply gets ``existed`` here."""

    reply: R
    existed: bool


Outcome = Union[Answer, Created[Any], Awaitable[Answer], Awaitable[Created[Any]],
                "OffLoop[Answer]"]
# A handler gets the parsed request, the client that sent it (None for start-up config) and,
# when its op declares content (`Op.content`), the `ContentGuard` for it: (request, client,
# guard). The arity is checked when the dispatcher is built.
Handler = Callable[..., Outcome]

DAEMON_VERSION = "0.1.0"
# A command text longer than this is parsed off the loop (in its client's lane).
LARGE_COMMAND_CHARS = 64 * 1024


class RosGraph(Protocol):
    """What the dispatcher asks of ROS: the daemon's `bridge.ros.ros_node.RosNode`, or the
    player's bag (bridge/playback), which serves the same ops without ROS."""

    # get_topic_names_and_types(), count_publishers(topic), get_service_names_and_types()
    node: Any

    @property
    def fully_qualified_name(self) -> str: ...

    def resolve_name(self, name: str, field: str) -> str: ...


class Capability(Protocol):
    """One area of the daemon (topics, tf, parameters, services, robots)."""

    def handlers(self) -> Mapping[type[Op], Handler]:
        """The ops it serves: request class -> handler."""
        ...

    def describe(self) -> list[dict[str, Any]]:
        """Its live bridges, for `list_bridges`: each names its ``kind``, a bridge kind an
        op declares (`protocol.commands.bridge_kinds`)."""
        ...

    def state(self, guard: ContentGuard) -> Mapping[str, Any]:
        """What it holds that is not a bridge (the tf buffer, goals in flight, cached ROS
        clients), each under its own key of the `list_bridges` reply; `guard` judges the
        frames it names."""
        ...

    def close(self) -> None: ...


_KINDS = c.bridge_kinds()


def _as_given(frame: str, field: str) -> str:
    return strip_frame(frame)


def _created(request: c.Request, outcome: Any) -> tuple[Result, bool]:
    """A handler's outcome -> (the reply, whether its bridge was there already). A create
    op's handler says so by returning `Created`; nothing else may."""
    creates = type(request).creates is not None
    if isinstance(outcome, Created) != creates:
        raise TypeError(f"the {request.op} handler returned {type(outcome).__name__}: "
                        f"{'a create op' if creates else 'an op that creates nothing'} "
                        f"returns {'Created' if creates else 'its reply'}")
    reply = outcome.reply if isinstance(outcome, Created) else outcome
    declared = type(request).result
    if declared is not None and not isinstance(reply, declared):
        raise TypeError(f"the {request.op} handler returned {type(reply).__name__}: "
                        f"expected {declared.__name__}, the result its op declares")
    if isinstance(outcome, Created):
        return {**_json_object(outcome.reply), "existed": outcome.existed}, outcome.existed
    return _json_object(cast(Answer, outcome)), False


def _json_object(result: Answer) -> Result:
    """A handler's typed result as its reply's JSON object (a listing's encoded off the
    loop: `LargeResult`)."""
    if isinstance(result, c.Result):
        return LargeResult(result.to_dict()) if result.large else result.to_dict()
    return result


def _check_arity(cls: type[Op], handler: Handler) -> None:
    """A handler takes (request, client), and the guard too when its op declares content."""
    wanted = 3 if cls.content else 2
    try:
        taken = len(inspect.signature(handler).parameters)
    except (TypeError, ValueError):  # a builtin: trust it
        return
    if taken != wanted:
        raise TypeError(f"the {cls.op} handler takes {taken} arguments: expected (request, "
                        f"client{', guard' if cls.content else ''}), as the op declares "
                        f"content={cls.content!r}")


def bridge_key(request: c.Request) -> Optional[BridgeKey]:
    """(kind, identity) of the bridge a create or remove request names, as the
    capabilities keep them (names resolved, so ``cmd`` and ``/cmd`` are one bridge); a
    capability names its bridge's devices to the hub by it (`Hub.bridge_device`)."""
    cls = type(request)
    kind = cls.creates.kind if cls.creates is not None else cls.removes
    if kind is None:
        return None
    return kind, tuple(str(getattr(request, name)) for name in _identity_fields(request))


def made_bridge(request: c.Request) -> BridgeKey:
    """`bridge_key` of a create request: the bridge whose devices its handler reports."""
    key = bridge_key(request)
    if key is None or type(request).creates is None:
        raise TypeError(f"{request.op} creates no bridge")
    return key


def _identity_fields(request: c.Request) -> tuple[str, ...]:
    cls = type(request)
    if cls.creates is not None:
        return cls.creates.identity
    return _KINDS[cast(str, cls.removes)].bridge.identity


class BridgeLocks:
    """One first-come-first-served lock per bridge key (loop thread only). A key is held
    from the start of a create or remove until its outcome is settled."""

    def __init__(self) -> None:
        self._queues: dict[BridgeKey, deque[asyncio.Future[None]]] = {}

    def try_take(self, key: BridgeKey) -> bool:
        """Take ``key`` now if nobody holds it."""
        if key in self._queues:
            return False
        self._queues[key] = deque()
        return True

    async def take(self, key: BridgeKey) -> None:
        """Take ``key``, after those who asked before."""
        if self.try_take(key):
            return
        turn: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self._queues[key].append(turn)
        try:
            await turn
        except asyncio.CancelledError:
            if turn.done() and not turn.cancelled():
                self.release(key)  # handed over as we were cancelled: pass it on
            elif turn in self._queues.get(key, ()):
                self._queues[key].remove(turn)
            raise

    def release(self, key: BridgeKey) -> None:
        queue = self._queues.get(key)
        if queue is None:
            return
        while queue:
            turn = queue.popleft()
            if not turn.done():
                turn.set_result(None)
                return
        del self._queues[key]


class Dispatcher:
    def __init__(self, ros: RosGraph, hub: Hub, capabilities: Sequence[Capability], *,
                 policy: SecurityPolicy | None = None,
                 resolve_frame: NameResolver = _as_given,
                 resolve_file: FileResolver | None = None,
                 heavy: HeavyWork | None = None) -> None:
        self._ros = ros
        self._hub = hub
        self._heavy = heavy  # clients' lanes for OffLoop work and LargeResult replies
        # Clients whose large command is being parsed, and their commands that came after.
        self._parsing: dict[Replier, deque[Message]] = {}
        self._capabilities = tuple(capabilities)
        # Security is checked here, by request fields, so no capability needs to know it.
        self._policy = policy or SecurityPolicy()
        # The tf capability's mapping of a client's frame ids (--frame-prefix), so frame
        # globs judge the frame that is really looked up or broadcast.
        self._resolve_frame = resolve_frame
        self._resolve_file = resolve_file
        self._quota = BridgeQuota(self._policy.max_bridges_per_client,
                                  self._policy.max_bridges)
        self._owners = BridgeOwners()
        self._locks = BridgeLocks()
        self._closing = False
        self._auth_failures = RateLimitedLog(log)
        hub.add_closed_listener(self._client_left)
        self._tasks: set[asyncio.Task[None]] = set()
        # The one table of what this daemon serves, built from each capability's own list.
        # Ops of the schema missing here are answered NOT_SUPPORTED, naming the op.
        own: dict[type[Op], Handler] = {
            c.Hello: self._hello,
            c.Authenticate: self._authenticate,
            c.ListBridges: self._list_bridges,
            c.KeepBridge: self._keep,
            c.ListTopics: self._list_topics,
            c.ListServices: self._list_services,
        }
        self._handlers: dict[str, Handler] = {}
        for table in (own, *(capability.handlers() for capability in self._capabilities)):
            for cls, handler in table.items():
                if c.REQUEST_TYPES.get(cls.op) is not cls or cls.to_client:
                    raise ValueError(f"{cls.__name__} is not a client op of the schema")
                if cls.op in self._handlers:
                    raise ValueError(f"two handlers for {cls.op!r}")
                _check_arity(cls, handler)
                self._handlers[cls.op] = handler

    # --- entry points -------------------------------------------------------------------
    def handle(self, message: Message, client: Replier) -> None:
        """A COMMAND from a client (loop thread): reply now, or when an async op is done.
        Nothing escapes to the session (its connection stays open): a failure anywhere
        becomes the request's error reply.

        A large text (a publish of a megabyte of JSON) is parsed in the client's lane, and
        the client's later commands wait for it, so that they still run in order."""
        try:
            self._handle(message, client)
        except Exception as error:  # noqa: BLE001 - every failure becomes a reply
            body = message.body
            assert isinstance(body, Command)
            self._reply(client, message, self._failure(body.name, error))

    def _handle(self, message: Message, client: Replier) -> None:
        waiting = self._parsing.get(client)
        if waiting is not None:
            waiting.append(message)
            return
        body = message.body
        assert isinstance(body, Command)
        if self._heavy is not None and len(body.text) > LARGE_COMMAND_CHARS:
            try:
                parsing = self._heavy.run(client, lambda: c.parse_request(body.name,
                                                                          body.text))
            except CommandError as error:  # the client's lane is full
                self._reply(client, message, self._failure(body.name, error))
                return
            self._parsing[client] = deque()
            parsing.add_done_callback(lambda done: self._parsed(message, client, done))
            return
        try:
            request = c.parse_request(body.name, body.text)
        except Exception as error:  # noqa: BLE001 - every failure becomes a reply
            self._reply(client, message, self._failure(body.name, error))
            return
        self._dispatch(message, client, request)

    def _parsed(self, message: Message, client: Replier,
                done: asyncio.Future[c.Request]) -> None:
        """A large command's text is parsed (loop thread): run it, then what waited."""
        waiting = self._parsing.pop(client, deque())
        body = message.body
        assert isinstance(body, Command)
        if not done.cancelled():  # cancelled: the client left
            error = done.exception()
            if error is not None:
                self._reply(client, message, self._failure(body.name, error))
            else:
                self._dispatch(message, client, done.result())
        while waiting:
            self.handle(waiting.popleft(), client)
            if client in self._parsing:  # another large one: the rest waits for it
                self._parsing[client].extend(waiting)
                return

    def _dispatch(self, message: Message, client: Replier, request: c.Request) -> None:
        body = message.body
        assert isinstance(body, Command)
        try:
            outcome = self._run(request, client)
        except Exception as error:  # noqa: BLE001 - every failure becomes a reply
            self._reply(client, message, self._failure(body.name, error))
            return
        if inspect.isawaitable(outcome):
            self._spawn(self._finish(outcome, client, message))
        elif isinstance(outcome, LargeResult) and self._heavy is not None:
            self._spawn(self._finish(self._resolved(outcome), client, message))
        else:
            self._reply(client, message, Reply.success(body.name, outcome))

    def _spawn(self, coroutine: Awaitable[None]) -> None:
        task = asyncio.ensure_future(coroutine)
        self._tasks.add(task)
        task.add_done_callback(self._done)

    def _done(self, task: asyncio.Future[None]) -> None:
        self._tasks.discard(task)
        # `_finish` replies to every outcome; anything left is a bug, said here and not as
        # "Task exception was never retrieved" at collection.
        if not task.cancelled() and task.exception() is not None:
            log.error("a command's task failed", exc_info=task.exception())

    @staticmethod
    async def _resolved(result: Result) -> Result:
        return result

    async def execute(self, op: str, arguments: Mapping[str, Any]) -> Result:
        """Run one command without a client (start-up config); raises `CommandError`."""
        request = c.parse_request(op, c.dumps(dict(arguments)))
        outcome = self._run(request, None)
        if inspect.isawaitable(outcome):
            return await outcome
        return outcome

    def close(self) -> None:
        self._closing = True
        for task in tuple(self._tasks):
            task.cancel()
        for capability in reversed(self._capabilities):
            capability.close()

    def _client_left(self, client: Replier) -> None:
        # Those that live only as long as their client (a served service) their capability
        # ends; of the others, those it was the last to hold and nothing keeps end here.
        gone = self._owners.forget(client, {kind for kind, k in _KINDS.items()
                                            if k.bridge.per_connection})
        for key in gone:
            self._hub.drop_bridge(key)
        self._quota.release(client, len(gone))
        self._quota.forget(client)
        if not self._closing:  # closed: the capabilities have closed every bridge
            for key in self._owners.left(client):
                self._spawn(self._end(key))
        self._parsing.pop(client, None)
        if self._heavy is not None:
            self._heavy.forget(client)

    async def _end(self, key: BridgeKey) -> None:
        """Remove a bridge whose last holder left, by its kind's remove op as the operator
        would, unless a client asked for it (a reconnecting one) or kept it meanwhile."""
        await self._locks.take(key)
        try:
            if not self._owners.orphaned(key):
                return
            kind = _KINDS[key[0]]
            request = c.parse_request(kind.remove.op,
                                      c.dumps(dict(zip(kind.bridge.identity, key[1]))))
            try:
                outcome = self._call(self._handlers[kind.remove.op], request, None, key)
                if inspect.isawaitable(outcome):
                    await outcome
            except CommandError as error:  # gone already (its node went): forget it
                log.info("the %s %s its last client left was gone already: %s", key[0],
                         "/".join(key[1]), error)
                self._forget_bridge(key)
            else:
                log.info("removed the %s %s: its last client left", key[0], "/".join(key[1]))
        finally:
            self._locks.release(key)

    def _keep(self, request: c.KeepBridge, client: Replier | None) -> c.KeptBridge:
        key = bridge_key(request.bridge)
        assert key is not None  # a removal names its bridge
        if not self._owners.keep(key):
            identity = _identity_fields(request.bridge)
            raise CommandFailedError(identity[0], f"a live {key[0]}", "/".join(key[1]),
                                     code=ErrorCode.NOT_FOUND)
        self._tell_audience(key)  # every client gets it now
        return c.KeptBridge(key[0], dict(zip(_identity_fields(request.bridge), key[1])))

    def _forget_bridge(self, key: BridgeKey) -> None:
        """`key` is gone: its maker's quota slot goes back."""
        maker = self._owners.removed(key)
        self._hub.drop_bridge(key)
        if maker is not None and maker != OPERATOR:
            self._quota.release(maker)

    def _tell_audience(self, key: BridgeKey) -> None:
        """The hub streams `key`'s devices to whom its holders make its audience."""
        audience = self._owners.audience(key)
        self._hub.set_bridge_audience(key, None if audience is None
                                      else tuple(cast(Subscriber, a) for a in audience))

    # --- plumbing -----------------------------------------------------------------------
    def _run(self, request: c.Request, client: Replier | None) -> Result | Awaitable[Result]:
        handler = self._handlers.get(request.op)
        if handler is None:
            raise CommandFailedError("op", "an op this daemon serves: " +
                                     ", ".join(sorted(self._handlers)), request.op,
                                     code=ErrorCode.NOT_SUPPORTED)
        # Names and frame ids are resolved here, once: the policy, the bridge's identity and
        # the handler all see the fully qualified ones.
        request = request.with_names(self._ros.resolve_name).with_frames(self._resolve_frame)
        self._policy.check_request(request, self._ros.fully_qualified_name,
                                   from_client=client is not None,
                                   resolve_file=self._resolve_file,
                                   grant=client.grant if client is not None else WRITES)
        key = bridge_key(request)
        if key is None:
            return self._call(handler, request, client, None)
        if not self._locks.try_take(key):
            return self._after_turn(handler, request, client, key)
        try:
            outcome = self._call(handler, request, client, key)
        except BaseException:
            self._locks.release(key)
            raise
        if inspect.isawaitable(outcome):
            return self._releasing(outcome, key)
        self._locks.release(key)
        return outcome

    async def _after_turn(self, handler: Handler, request: c.Request, client: Replier | None,
                          key: BridgeKey) -> Result:
        """A create or remove whose bridge another one is creating or removing: its turn
        comes once that one is settled."""
        await self._locks.take(key)
        try:
            outcome = self._call(handler, request, client, key)
            return await outcome if inspect.isawaitable(outcome) else outcome
        finally:
            self._locks.release(key)

    async def _releasing(self, outcome: Awaitable[Result], key: BridgeKey) -> Result:
        try:
            return await outcome
        finally:
            self._locks.release(key)

    def _call(self, handler: Handler, request: c.Request, client: Replier | None,
              key: Optional[BridgeKey]) -> Result | Awaitable[Result]:
        """The handler with the ownership check before it and the bookkeeping after."""
        if key is not None and type(request).removes is not None:
            self._owners.check_removal(key, _identity_fields(request)[0], client)
        if key is not None and type(request).creates is not None \
                and self._owners.owner(key) is None:
            # A new bridge's devices, reported while it is made, go to its maker only.
            self._hub.set_bridge_audience(key, None if client is None
                                          else (cast(Subscriber, client),))
        reserved = client is not None and self._quota.reserve(client, request.op)
        try:
            if type(request).content:
                guard = self._policy.content_guard(request, from_client=client is not None)
                outcome = handler(request, client, guard)
            else:
                outcome = handler(request, client)
            if isinstance(outcome, OffLoop):
                outcome = self._off_loop(outcome, client)
            if not inspect.isawaitable(outcome):
                result, existed = _created(request, outcome)
        except BaseException:
            self._settle(request, client, key, reserved, None, False)
            raise
        if inspect.isawaitable(outcome):
            return self._counted(outcome, request, client, key, reserved)
        self._settle(request, client, key, reserved, result, existed)
        return result

    def _off_loop(self, outcome: OffLoop[Answer],
                  client: Replier | None) -> Answer | Awaitable[Answer]:
        """A handler's `OffLoop` work, in its client's lane (the operator's start-up
        commands run it here and now: nothing else is served yet)."""
        if client is None or self._heavy is None:
            return outcome.work()
        return self._heavy.run(client, outcome.work)  # LaneFullError: LIMIT_REACHED

    async def _counted(self, outcome: Awaitable[Answer | Created[Any]], request: c.Request,
                       client: Replier | None, key: Optional[BridgeKey],
                       reserved: bool) -> Result:
        result: Result | None = None
        existed = False
        try:
            result, existed = _created(request, await outcome)
            return result
        finally:
            self._settle(request, client, key, reserved, result, existed)

    def _settle(self, request: c.Request, client: Replier | None, key: Optional[BridgeKey],
                reserved: bool, result: Optional[Result], existed: bool) -> None:
        """After a handler: count the client's bridges, record who made or removed one."""
        if client is not None:
            self._quota.settle(client, reserved, succeeded=result is not None,
                               existed=existed)
        if key is None:
            return
        if result is None:
            if type(request).creates is not None and self._owners.owner(key) is None:
                self._hub.drop_bridge(key)  # not made after all
            return
        if type(request).creates is not None:
            self._owners.created(key, OPERATOR if client is None else client)
            self._tell_audience(key)
        elif type(request).removes is not None:
            self._forget_bridge(key)

    async def _finish(self, outcome: Awaitable[Result], client: Replier,
                      message: Message) -> None:
        body = message.body
        assert isinstance(body, Command)
        try:
            result = await outcome
            reply = Reply.success(body.name, result)
            if isinstance(result, LargeResult) and self._heavy is not None:
                # A listing's JSON is encoded in the client's lane, not on the loop.
                text = await self._heavy.run(client, reply.to_json)
                self._reply(client, message, reply, text)
                return
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

    @classmethod
    def _reply(cls, client: Replier, request: Message, reply: Reply,
               text: Optional[str] = None) -> None:
        """Send ``reply`` (its JSON ``text`` when already encoded). A result the text cannot
        hold (a NaN or an infinity from ROS: `protocol.commands.dumps` refuses it, naming
        where) is answered with that error instead, under the same command id."""
        body = request.body
        assert isinstance(body, Command)
        if text is None:
            try:
                text = reply.to_json()
            except Exception as error:  # noqa: BLE001 - every failure becomes a reply
                reply = cls._failure(body.name, error)
                text = reply.to_json()
        try:
            client.send_message(Message(
                device_name=request.device_name,
                body=RtsCommand(command_id=body.command_id, name=body.name, text=text),
                metadata=reply.metadata(), message_id=request.message_id))
        except Exception:  # noqa: BLE001 - a bug: said, and the connection stays
            log.exception("the reply to command %s (id %d) could not be sent", body.name,
                          body.command_id)

    # --- small handlers -----------------------------------------------------------------
    def _hello(self, request: c.Hello, client: Replier | None) -> c.HelloResult:
        """The handshake; for a client, also what it may do (``auth``: whether it writes,
        why not, and the challenge its key must answer) and its heartbeat, if asked."""
        greeting = c.HelloResult(c.SCHEMA_VERSION, DAEMON_VERSION,
                                 self._ros.fully_qualified_name, tuple(sorted(self._handlers)))
        if client is None:
            return greeting
        writes, challenge = client.grant.writes, None
        if self._policy.key is not None and not writes and not self._policy.read_only:
            client.challenge = challenge = new_challenge()
        client.reads_stamps = request.stamps
        if request.heartbeat is not None:
            client.start_heartbeat(request.heartbeat)
        if request.display_hz is not None:
            client.pace_display(request.display_hz)
        return replace(greeting, auth=c.HelloAuth(writes, None if writes else client.grant.why,
                                                  challenge),
                       heartbeat=request.heartbeat, display_hz=request.display_hz,
                       clock_ms=daemon_clock_ms())  # streams' message ids are on this clock

    def _authenticate(self, request: c.Authenticate,
                      client: Replier | None) -> c.AuthenticateResult:
        """A key presented against this connection's challenge (one try per challenge: a
        wrong proof needs a new hello)."""
        if client is None:
            raise CommandFailedError("op", "a client's op", "authenticate in the config")
        if self._policy.key is None:
            raise CommandFailedError("op", "a daemon started with --key-file", "a daemon "
                                     "without a key (it judges writers by address: "
                                     f"{self._policy.grant_summary()})",
                                     code=ErrorCode.NOT_SUPPORTED)
        challenge, client.challenge = client.challenge, None
        if challenge is None:
            raise ForbiddenError("op", "authenticate after a hello that gave a challenge",
                                 "no challenge outstanding (send hello again)")
        if not verify(self._policy.key, challenge, request.nonce, request.proof):
            self._auth_failures.warning("auth", time.monotonic(), "a key proof failed "
                                        "(wrong key?); the connection stays read-only")
            raise ForbiddenError("proof", "the proof of the daemon's key for this challenge",
                                 "a proof that does not match (is the key file the "
                                 "daemon's?)")
        client.granted(self._policy.grant_after_proof())
        log.info("a client presented the key: it may write")
        return c.AuthenticateResult(client.grant.writes)

    def _list_bridges(self, request: c.ListBridges, client: Replier | None,
                      guard: ContentGuard) -> c.ListBridgesResult:
        """The bridges (declared kinds only), each capability's other state under its own
        key, and the hub's devices and clients."""
        bridges: list[dict[str, Any]] = []
        state: dict[str, Any] = {}
        for capability in self._capabilities:
            for bridge in capability.describe():
                if bridge.get("kind") not in _KINDS:
                    raise TypeError(f"{type(capability).__name__}.describe(): expected bridges "
                                    f"of a declared kind ({', '.join(sorted(_KINDS))}), got "
                                    f"kind {bridge.get('kind')!r}")
                bridges.append({**bridge, **self._lifetime(bridge)})
            for key, value in capability.state(guard).items():
                if key in state or key in c.ListBridgesResult.__dataclass_fields__:
                    raise TypeError(f"{type(capability).__name__}.state(): expected a key of "
                                    f"its own in the list_bridges reply, got {key!r} (taken)")
                state[key] = value
        return c.ListBridgesResult(tuple(bridges), tuple(self._hub.devices()),
                                   tuple(client.describe() for client in self._hub.clients),
                                   self._hub.dropped, state)

    def _lifetime(self, bridge: Mapping[str, Any]) -> dict[str, Any]:
        """How long a listed bridge lives: ``stays`` (the operator's or kept) and how many
        live ``clients`` hold it (it ends with the last unless it stays)."""
        identity = _KINDS[bridge["kind"]].bridge.identity
        if not all(name in bridge for name in identity):
            return {}
        key = (bridge["kind"], tuple(str(bridge[name]) for name in identity))
        return {"stays": self._owners.stays(key), "clients": len(self._owners.holders(key))}

    def _list_topics(self, request: c.ListTopics,
                     client: Replier | None) -> c.ListTopicsResult:
        # The publisher count: a client's wait for a topic that has none says so.
        node = self._ros.node
        return c.ListTopicsResult(tuple({"topic": name, "types": list(types),
                                         "publishers": node.count_publishers(name)}
                                        for name, types in node.get_topic_names_and_types()))

    def _list_services(self, request: c.ListServices,
                       client: Replier | None) -> c.ListServicesResult:
        return c.ListServicesResult(tuple({"service": name, "types": list(types)}
                                          for name, types
                                          in self._ros.node.get_service_names_and_types()))

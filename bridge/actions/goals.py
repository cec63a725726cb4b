"""Goals clients send to ROS action servers (`send_goal`, `cancel_goal`).

The goal is built from JSON with the generic codec (as service requests are) and sent by a
cached rclpy `ActionClient`. Every call on an ActionClient runs in the executor thread (it
keeps its pending requests in plain dicts that the executor reads); the loop hands work there
with ``executor.create_task`` and gets the outcome back with ``hub.call_soon``. The reply
comes once the server accepted (or refused) the goal; then feedback and the result go to
the sending client as STRING messages (`GoalEvent` JSON) on the goal's device. Nothing
waits on a goal: the loop never blocks.

A server that disappears mid-goal never sends a result: a watchdog on the loop looks at
each action client with goals in flight, and once its server has been gone for
`lost_server_s` the goals end with status ``lost``. A client that leaves has its goals
cancelled (nobody watches them).

A goal's answer can be lost: Fast DDS drops a service response to a reader the server has
not matched yet (it waits 100 ms), which a busy machine's discovery easily exceeds. The goal
then runs all the same, and the action's status topic (transient local, so it arrives
whenever the match completes) lists it: a goal listed there before its answer came is
accepted, and followed by its id like any other.
"""

from __future__ import annotations

import asyncio
import logging
import uuid
from dataclasses import dataclass
from typing import Any, Callable, Optional

from rclpy.action.client import ActionClient, ClientGoalHandle
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.qos import QoSProfile
from rclpy.task import Future as RosFuture
from unique_identifier_msgs.msg import UUID

from bridge.actions.common import destroy_quietly
from bridge.codecs import CodecError, message_to_dict
from bridge.codecs.registry import ACTION
from bridge.core.hub import Hub, Replier
from bridge.core.security import hidden_action
from bridge.codecs.registry import installed_class
from bridge.ros.ros_clients import RosClientCache
from bridge.ros.ros_node import RosNode
from bridge.codecs import message_from_json
from bridge.core.served import connected_client
from protocol import commands as c
from protocol.commands import (CancelGoal, CancelGoalResult, CommandError, CommandFailedError,
                               ErrorCode, ForbiddenError, LimitReachedError, SendGoal,
                               SendGoalResult)
from protocol.messages import Message, String
from protocol.naming import (KEY_FORMAT, KEY_GOAL_STATUS, DeviceNameRegistry, NameKey,
                             metadata_for)

__all__ = ["CalledAction", "GoalSender", "SentGoal"]

log = logging.getLogger("bridge.actions")

_READY_POLL_S = 0.05
# A STRING body holds at most 65535 bytes; an event larger than this says so instead.
_MAX_EVENT_BYTES = 60_000
# Cancel requests in flight at once: a server takes service requests from a queue of 10
# (rmw's default service QoS), so a burst (a client leaving with 32 goals) must not overflow it.
_MAX_CANCELS_IN_FLIGHT = 8
_CANCEL_TIMEOUT_S = 10.0
# Feedback waiting to be taken by the executor: rclpy's default (10) loses feedback when the
# executor thread stalls for 10 feedback periods (measured: 2 of 2,000 at 200 Hz under load).
_FEEDBACK_DEPTH = 100
_CANCEL_TYPE = "action_msgs/srv/CancelGoal"
# action_msgs/srv/CancelGoal return codes.
_CANCEL_CODES = {0: "none", 1: "rejected", 2: "unknown_goal", 3: "goal_terminated"}


def _uuid_msg(goal_hex: str) -> UUID:
    return UUID(uuid=list(bytes.fromhex(goal_hex)))


def _accepted(cls: Any) -> Any:
    """A SendGoal response saying accepted: what a goal handle made from an id needs."""
    return cls.Impl.SendGoalService.Response(accepted=True)


class _StatusWatchingClient(ActionClient):
    """An rclpy ActionClient that also hands each status message to `on_status`
    (executor thread; it must only hand off)."""

    def __init__(self, *args: Any, on_status: Callable[[Any], None], **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[no-untyped-call]  # rclpy: unannotated
        self._on_status = on_status

    async def execute(self, taken_data: Any) -> None:
        await super().execute(taken_data)  # type: ignore[no-untyped-call]  # rclpy: unannotated
        if "status" in taken_data:
            self._on_status(taken_data["status"])


@dataclass
class CalledAction:
    """A cached rclpy ActionClient for `send_goal` (one per action and type)."""

    action: str
    ros_type: str
    cls: Any  # the action class
    client: ActionClient
    in_use: int = 0  # goals sent through it that have not ended
    last_used: float = 0.0  # loop time
    gone_since: Optional[float] = None  # loop time its server was first seen missing


@dataclass
class SentGoal:
    """A goal a client sent, from `send_goal` until its result (or its loss)."""

    goal_id: str  # 32 hex digits
    action: str
    ros_type: str
    owner: Replier
    key: NameKey
    device: str
    called: CalledAction
    handle: Any = None  # rclpy ClientGoalHandle, once accepted
    listed: Optional[asyncio.Future[None]] = None  # set once the status topic lists it
    feedbacks: int = 0
    done: bool = False
    timer: Optional[asyncio.TimerHandle] = None


class GoalSender:
    """`send_goal` and `cancel_goal`: the goals clients send, until they end."""

    def __init__(self, ros: RosNode, hub: Hub, names: DeviceNameRegistry, *,
                 max_action_clients: int, max_goals_per_client: int, idle_client_s: float,
                 lost_server_s: float) -> None:
        self._ros = ros
        self._hub = hub
        self._names = names
        self._group = ReentrantCallbackGroup()
        # send_goal's action clients: each is five ROS entities (three service clients, two
        # subscriptions), so at most `max_action_clients`, none kept idle.
        self.called: RosClientCache[CalledAction] = RosClientCache(
            capacity=max_action_clients, idle_s=idle_client_s, destroy=self._destroy_client,
            refusal=lambda action: LimitReachedError(
                "action", f"at most {max_action_clients} actions with goals in flight at "
                f"once", f"a goal to {action} more"))
        # A quarter of the action clients per client: one client waiting on absent
        # servers cannot take every slot from the others.
        self._max_actions_per_client = max(1, max_action_clients // 4)
        self._max_goals = max_goals_per_client
        self._lost_s = lost_server_s
        self.goals: dict[str, SentGoal] = {}
        self._watch: Optional[asyncio.TimerHandle] = None
        self._cancels: Optional[asyncio.Semaphore] = None  # made on the loop, at first use
        self._tasks: set[asyncio.Task[Any]] = set()
        hub.add_closed_listener(self._on_client_closed)

    # --- helpers ---------------------------------------------------------------------------
    def _in_executor(self, start: Callable[[], RosFuture]) -> asyncio.Future[Any]:
        """Run `start()` (an rclpy call returning a future) in the executor thread; the
        returned loop future gets its outcome."""
        loop = asyncio.get_running_loop()
        outcome: asyncio.Future[Any] = loop.create_future()

        def begin() -> None:  # executor thread
            try:
                ros_future = start()
            except Exception as error:  # noqa: BLE001 - handed to the loop
                self._hub.call_soon(_settle_loop, outcome, None, error)
                return
            ros_future.add_done_callback(
                lambda done: self._hub.call_soon(_settle_loop, outcome, done, None))

        self._ros.executor.create_task(begin)
        return outcome

    async def _cancel(self, handle: Any, timeout: float = _CANCEL_TIMEOUT_S) -> Any:
        """Ask a goal's server to cancel it; the response (TimeoutError after `timeout`)."""
        if self._cancels is None:
            self._cancels = asyncio.Semaphore(_MAX_CANCELS_IN_FLIGHT)
        async with self._cancels:
            return await asyncio.wait_for(self._in_executor(handle.cancel_goal_async), timeout)

    def _cancel_soon(self, handle: Any, why: str) -> None:
        """Cancel without waiting for the answer (it is logged if it fails)."""
        async def run() -> None:
            try:
                await self._cancel(handle)
            except (asyncio.TimeoutError, CommandError) as error:
                log.warning("cancelling goal %s (%s) failed: %s",
                            bytes(handle.goal_id.uuid).hex(), why, str(error) or "no answer")
        task = asyncio.ensure_future(run())
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    def _new_client(self, action: str, ros_type: str, cls: Any) -> CalledAction:
        feedback_qos = QoSProfile(depth=_FEEDBACK_DEPTH)
        client = _StatusWatchingClient(
            self._ros.node, cls, action, callback_group=self._group,
            feedback_sub_qos_profile=feedback_qos,
            on_status=lambda message: self._hub.call_soon(self._on_status, entry, message))
        entry = CalledAction(action, ros_type, cls, client)
        return entry

    def _destroy_client(self, entry: CalledAction) -> None:
        # Destroyed in the executor thread, between two waits (see RosNode.destroy).
        self._ros.executor.create_task(destroy_quietly, entry.client, entry.action)

    # --- send_goal -------------------------------------------------------------------------
    async def send_goal(self, request: SendGoal, client: Optional[Replier]) -> SendGoalResult:
        client = connected_client(client, "action", "gets the feedback and the result")
        action = request.action
        ros_type = request.ros_type
        cls = installed_class(ACTION, request.type, ros_type)
        goal = message_from_json(cls.Goal, request.goal, "goal")
        mine = sum(1 for g in self.goals.values() if g.owner is client)
        if mine >= self._max_goals:
            raise LimitReachedError("goal", f"at most {self._max_goals} goals in flight per "
                                    f"client", f"a goal more to {action}")
        held = {(g.action, g.ros_type) for g in self.goals.values() if g.owner is client}
        if (action, ros_type) not in held and len(held) >= self._max_actions_per_client:
            raise LimitReachedError("action", f"goals to at most "
                                    f"{self._max_actions_per_client} actions in flight per "
                                    f"client", f"a goal to {action} more")
        goal_id = request.goal_id or uuid.uuid4().hex
        if goal_id in self.goals:
            raise CommandFailedError("goal_id", "a goal id not in use", goal_id,
                                     code=ErrorCode.ALREADY_EXISTS)
        entry = self.called.client((action, ros_type),
                                   lambda: self._new_client(action, ros_type, cls))
        key = NameKey.action_goal(action, goal_id)
        sent = SentGoal(goal_id, action, ros_type, client, key, self._names.register(key),
                        entry)
        # Recorded before the goal leaves: feedback may come before the acceptance does.
        self.goals[goal_id] = sent
        self.called.take(entry)
        try:
            handle = await self._send(sent, goal, request.timeout)
        except BaseException:
            self._forget(sent)
            raise
        sent.handle = handle
        if sent.done:  # its client left while the server was accepting: nobody watches it
            self._cancel_soon(handle, "its client left before the goal was accepted")
            raise CommandFailedError("action", "a connected client", "a client that left",
                                     code=ErrorCode.UNAVAILABLE)
        result = self._in_executor(handle.get_result_async)
        result.add_done_callback(lambda done: self._on_result(sent, done))
        if request.result_timeout is not None:
            sent.timer = asyncio.get_running_loop().call_later(
                request.result_timeout, self._result_overdue, sent, request.result_timeout)
        self._schedule_watch()
        log.info("goal %s sent to %s (%s) for client %s", goal_id, action, ros_type,
                 getattr(client, "peer", "?"))
        return SendGoalResult(action, ros_type, goal_id, sent.device, "accepted",
                              message_to_dict(handle.stamp))

    async def _send(self, sent: SentGoal, goal: Any, timeout: float) -> Any:
        loop = asyncio.get_running_loop()
        start = loop.time()
        what = f"the action server of {sent.action}"
        client = sent.called.client
        while not client.server_is_ready():
            if sent.done:  # its client left: the slot is already free, stop waiting
                raise CommandFailedError("action", "a connected client", "a client that left",
                                         code=ErrorCode.UNAVAILABLE)
            if loop.time() - start >= timeout:
                raise CommandFailedError("action", f"{what} to be available",
                                         f"no server after {timeout:g} s",
                                         code=ErrorCode.UNAVAILABLE)
            await asyncio.sleep(_READY_POLL_S)

        def on_feedback(message: Any) -> None:  # executor thread: hand off only
            self._hub.call_soon(self._on_feedback, sent, message)

        response = self._in_executor(
            lambda: client.send_goal_async(
                goal, feedback_callback=on_feedback, goal_uuid=_uuid_msg(sent.goal_id)))
        sent.listed = loop.create_future()
        done, _ = await asyncio.wait((response, sent.listed),
                                     timeout=max(0.0, start + timeout - loop.time()),
                                     return_when=asyncio.FIRST_COMPLETED)
        if response in done:
            handle = response.result()
        elif done:
            # Its answer was lost. The pending request stays in the rclpy client until an
            # answer comes or the client is dropped (idle), whichever is first.
            log.warning("goal %s of %s: the server's answer was lost; the action's status "
                        "topic lists the goal, so it was accepted", sent.goal_id, sent.action)
            response.add_done_callback(lambda late: self._late_answer(sent, late))
            return ClientGoalHandle(
                client, _uuid_msg(sent.goal_id), _accepted(sent.called.cls))
        else:
            # The server may have accepted it and only its answer be lost (Fast DDS drops a
            # response to a reader it has not matched yet), or accept it later: either way
            # the goal would run unwatched, so it is cancelled by its id, and again if an
            # acceptance comes late.
            self._cancel_soon(ClientGoalHandle(
                client, _uuid_msg(sent.goal_id), _accepted(sent.called.cls)),
                "its send_goal timed out")
            response.add_done_callback(self._cancel_late)
            raise CommandFailedError("action", f"{what} to accept or reject the goal within "
                                     f"{timeout:g} s", "no answer; the daemon asked the "
                                     f"server to cancel goal {sent.goal_id} in case it runs",
                                     code=ErrorCode.TIMEOUT)
        if not handle.accepted:
            raise CommandFailedError("goal", f"a goal {what} accepts", "a rejected goal",
                                     code=ErrorCode.REJECTED)
        return handle

    def _on_status(self, entry: CalledAction, message: Any) -> None:
        """A status message of an action the daemon sends goals to (loop thread): goals
        of that action still waiting for their answer that it lists were accepted."""
        for status in message.status_list:
            sent = self.goals.get(bytes(status.goal_info.goal_id.uuid).hex())
            if (sent is not None and sent.called is entry and sent.listed is not None
                    and not sent.listed.done()):
                sent.listed.set_result(None)

    @staticmethod
    def _late_answer(sent: SentGoal, response: asyncio.Future[Any]) -> None:
        """The answer of a goal already taken as accepted from the status topic."""
        if response.cancelled() or response.exception() is not None:
            return
        if not response.result().accepted:  # then the status came from another publisher
            log.warning("goal %s of %s: the server's late answer rejects the goal the "
                        "status topic listed; its result will say how it ended",
                        sent.goal_id, sent.action)

    def _cancel_late(self, response: asyncio.Future[Any]) -> None:
        if response.cancelled() or response.exception() is not None:
            return
        handle = response.result()
        if handle.accepted:
            self._cancel_soon(handle, "accepted after its send_goal timed out")

    def _event(self, sent: SentGoal, status: str, payload: dict[str, Any]) -> None:
        """One STRING `GoalEvent` to the goal's client (loop thread)."""
        body = {"goal_id": sent.goal_id, "action": sent.action, "status": status, **payload}
        try:
            text = c.dumps(body)
        except CommandError as error:
            text = c.dumps({"goal_id": sent.goal_id, "action": sent.action, "status": status,
                            "event": payload.get("event", ""), "error": str(error)})
        if len(text) > _MAX_EVENT_BYTES:
            text = c.dumps({"goal_id": sent.goal_id, "action": sent.action, "status": status,
                            "event": payload.get("event", ""),
                            "error": f"the event is {len(text)} bytes, more than a STRING "
                                     f"message holds ({_MAX_EVENT_BYTES})"})
        meta = metadata_for(sent.key, ros_type=sent.ros_type)
        meta[KEY_GOAL_STATUS] = status
        meta[KEY_FORMAT] = "json"
        sent.owner.send_message(Message(device_name=sent.device, body=String(text),
                                        metadata=meta))

    def _on_feedback(self, sent: SentGoal, message: Any) -> None:
        if sent.done:
            return
        sent.feedbacks += 1
        try:
            feedback = message_to_dict(message.feedback)
        except CodecError as error:
            log.warning("feedback of goal %s is unreadable (%s)", sent.goal_id, error)
            return
        self._event(sent, "executing", {"event": "feedback", "seq": sent.feedbacks,
                                        "feedback": feedback})

    def _on_result(self, sent: SentGoal, done: asyncio.Future[Any]) -> None:
        if sent.done:
            return
        if done.cancelled() or done.exception() is not None:
            why = "cancelled" if done.cancelled() else str(done.exception())
            self._finish(sent, "lost", {"error": f"no result from {sent.action} ({why})"})
            return
        response = done.result()
        status = c.GOAL_STATUSES.get(int(response.status), "unknown")
        try:
            result = message_to_dict(response.result)
        except CodecError as error:
            self._finish(sent, status, {"error": f"the result is unreadable ({error})"})
            return
        self._finish(sent, status, {"result": result})

    def _finish(self, sent: SentGoal, status: str, payload: dict[str, Any]) -> None:
        self._event(sent, status, {"event": "result", "feedbacks": sent.feedbacks, **payload})
        log.info("goal %s of %s ended: %s", sent.goal_id, sent.action, status)
        self._forget(sent)

    def _forget(self, sent: SentGoal) -> None:
        if sent.done:
            return
        sent.done = True
        if sent.timer is not None:
            sent.timer.cancel()
        self.goals.pop(sent.goal_id, None)
        self.called.release(sent.called)
        self._names.release(sent.key)

    def _result_overdue(self, sent: SentGoal, seconds: float) -> None:
        if sent.done:
            return
        if sent.handle is not None:
            self._cancel_soon(sent.handle, "result_timeout")
        self._finish(sent, "timeout", {"error": f"no result within {seconds:g} s "
                                                f"(result_timeout); the daemon asked "
                                                f"{sent.action} to cancel the goal"})

    # --- the watchdog: lost servers (the cache drops idle clients) ---------------------------
    def _schedule_watch(self) -> None:
        if self._watch is None and any(e.in_use for e in self.called.values()):
            self._watch = asyncio.get_running_loop().call_later(self._lost_s / 2, self._look)

    def _look(self) -> None:
        self._watch = None
        now = asyncio.get_running_loop().time()
        for key, entry in list(self.called.items()):
            if entry.in_use == 0:
                entry.gone_since = None
                continue
            if entry.client.server_is_ready():
                entry.gone_since = None
                continue
            if entry.gone_since is None:
                entry.gone_since = now
            elif now - entry.gone_since >= self._lost_s:
                for sent in [g for g in self.goals.values()
                             if g.called is entry and g.handle is not None]:
                    self._finish(sent, "lost", {"error": f"the action server of {entry.action} "
                                                f"went away before the result (no result)"})
                if entry.in_use == 0:
                    self.called.drop(key)  # its pending requests go with it
        self._schedule_watch()

    # --- cancel_goal -----------------------------------------------------------------------
    def _owned(self, action: str, goal_id: str, client: Optional[Replier],
               field: str) -> SentGoal:
        """The goal a client (None: the operator) may cancel: one of ``action`` it sent that
        has not ended; NOT_FOUND naming ``field`` otherwise. The one rule, whatever the
        route (`cancel_goal`, or a call of the action's hidden cancel service)."""
        sent = self.goals.get(goal_id)
        if sent is None or sent.action != action or (client is not None
                                                     and sent.owner is not client):
            raise CommandFailedError(field, f"a goal of {action} this client sent that has "
                                     f"not ended", goal_id, code=ErrorCode.NOT_FOUND)
        return sent

    def judge_service_call(self, service: str, ros_type: str, request: Any,
                           client: Optional[Replier]) -> None:
        """A `ServiceBridges` call guard: `call_service` of ``<action>/_action/cancel_goal``
        is judged as `cancel_goal`: its request (action_msgs/srv/CancelGoal) may name one
        goal, by its id, that this client sent. A zero id or a stamp asks the server to
        cancel every goal (or every goal before the stamp), other clients' and ROS nodes'
        too: refused."""
        action = hidden_action(service, ("cancel_goal",))
        if action is None or client is None:  # not that service, or the operator's config
            return
        if ros_type != _CANCEL_TYPE:
            raise ForbiddenError("type", f"{_CANCEL_TYPE} (the hidden cancel service of "
                                 f"{action})", ros_type)
        info = request.goal_info
        goal = bytes(info.goal_id.uuid)
        if not any(goal) or info.stamp.sec or info.stamp.nanosec:
            raise ForbiddenError("request.goal_info", f"the id of one goal of {action} this "
                                 "client sent, with a zero stamp (a zero id or a stamp "
                                 "cancels other clients' goals too)",
                                 f"goal id {goal.hex()}, stamp {info.stamp.sec}."
                                 f"{info.stamp.nanosec:09d}")
        self._owned(action, goal.hex(), client, "request.goal_info.goal_id")

    async def cancel_goal(self, request: CancelGoal, client: Optional[Replier]
                          ) -> CancelGoalResult:
        action = request.action
        sent = self._owned(action, request.goal_id, client, "goal_id")
        if sent.handle is None:
            raise CommandFailedError("goal_id", "a goal the server has accepted",
                                     "a goal still waiting for its acceptance",
                                     code=ErrorCode.NOT_FOUND)
        try:
            response = await self._cancel(sent.handle, request.timeout)
        except asyncio.TimeoutError:
            raise CommandFailedError("goal_id", f"an answer to the cancel request within "
                                     f"{request.timeout:g} s", "no answer",
                                     code=ErrorCode.TIMEOUT) from None
        code = int(response.return_code)
        canceling = [bytes(g.goal_id.uuid).hex() for g in response.goals_canceling]
        return CancelGoalResult(action, sent.goal_id, code == 0 and sent.goal_id in canceling,
                                code, _CANCEL_CODES.get(code, str(code)))

    def _on_client_closed(self, client: Replier) -> None:
        # Nobody watches its goals any more: ask their servers to stop them.
        for sent in [g for g in self.goals.values() if g.owner is client]:
            if sent.handle is not None:
                self._cancel_soon(sent.handle, "its client left")
            log.info("goal %s of %s canceled: its client left", sent.goal_id, sent.action)
            self._forget(sent)

    def state(self) -> dict[str, Any]:
        """send_goal's cached clients and the goals in flight (not bridges: a goal ends by
        itself, and the daemon makes and drops its clients)."""
        return {"action_clients": [{"action": e.action, "type": e.ros_type, "goals": e.in_use}
                                   for e in self.called.values()],
                "goals": [{"action": g.action, "goal_id": g.goal_id, "device": g.device,
                           "feedbacks": g.feedbacks} for g in self.goals.values()]}

    def close(self) -> None:
        for task in tuple(self._tasks):
            task.cancel()
        self.goals.clear()
        self.called.close()
        if self._watch is not None:
            self._watch.cancel()
            self._watch = None


def _settle_loop(outcome: asyncio.Future[Any], done: Optional[RosFuture],
                 error: Optional[BaseException]) -> None:
    if outcome.done():
        return
    if error is not None:
        outcome.set_exception(CommandFailedError("action", "an rclpy call that works",
                                                 f"{type(error).__name__}: {error}",
                                                 code=ErrorCode.ROS_ERROR))
    elif done is None or done.cancelled():
        outcome.set_exception(CommandFailedError("action", "an answer", "a cancelled request",
                                                 code=ErrorCode.ROS_ERROR))
    elif done.exception() is not None:
        outcome.set_exception(CommandFailedError(
            "action", "an answer", str(done.exception()),
            code=ErrorCode.ROS_ERROR))
    else:
        outcome.set_result(done.result())

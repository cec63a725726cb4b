"""Actions a client serves to ROS (`advertise_action`).

An rclpy `ActionServer` whose execute callback is a coroutine (the node's
SingleThreadedExecutor runs it without blocking other callbacks). It hands the goal to the
loop, which sends the serving client an `action_goal` COMMAND and waits for its
RTS_COMMAND; `action_feedback` commands publish feedback meanwhile. A ROS cancel request is
accepted and passed on as an `action_cancel` COMMAND. The client's answer (or an abort
after `goal_timeout`, or when the client leaves) ends the goal.

Advertised with ``decides``, the server's goal callback is a coroutine too: it puts the goal
to the client as an `action_decide` COMMAND and answers ROS with the client's verdict
(rejected when the client refuses, does not answer within `DECISION_TIMEOUT_S`, or leaves).
"""

from __future__ import annotations

import asyncio
import logging
from dataclasses import dataclass, field
from typing import Any, Optional

from rclpy.action.server import ActionServer, CancelResponse, GoalResponse
from rclpy.action.graph import get_action_names_and_types
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.task import Future as RosFuture

from bridge.actions.common import destroy_quietly
from bridge.codecs import CodecError, message_to_dict
from bridge.codecs.registry import ACTION
from bridge.core.client_replies import ClientReplies
from bridge.core.dispatch import Created
from bridge.core.hub import Hub, Replier
from bridge.codecs.registry import installed_class
from bridge.ros.ros_node import RosNode
from bridge.codecs import message_from_json
from bridge.core.served import advertised_by, already_served, client_answer, connected_client
from protocol import commands as c
from protocol.commands import (ActionCancel, ActionDecide, ActionFeedback, ActionFeedbackResult,
                               ActionGoal, AdvertiseAction, AdvertiseActionResult, CommandError,
                               CommandFailedError, ErrorCode, UnadvertiseAction, UnadvertisedAction,
                               WrongTypeError)
from protocol.naming import DeviceNameRegistry, NameKey, metadata_for

__all__ = ["DECISION_TIMEOUT_S", "ServedAction", "ServedActions"]

log = logging.getLogger("bridge.actions")

# How long a deciding client may take to accept or reject a goal (ROS clients wait for
# the goal response with their own, usually short, timeouts).
DECISION_TIMEOUT_S = 10.0


@dataclass
class _ServedGoal:
    served: ServedAction
    goal_id: str
    handle: Any  # rclpy ServerGoalHandle
    answer: RosFuture
    feedbacks: int = 0


@dataclass
class ServedAction:
    """A ROS action served by one client (the one that advertised it)."""

    action: str
    ros_type: str
    cls: Any
    owner: Replier
    key: NameKey
    device: str
    goal_timeout: float
    decides: bool = False
    server: Any = None  # rclpy ActionServer
    goals: dict[str, _ServedGoal] = field(default_factory=dict)
    received: int = 0
    closed: bool = False
    # Touched only in the executor thread: goals being executed, and a destroy waiting.
    executing: int = 0
    destroy_pending: bool = False
    linger: Optional[asyncio.TimerHandle] = None  # loop thread: the destroy's countdown


class ServedActions:
    """`advertise_action`, `unadvertise_action`, `action_feedback`: actions clients serve."""

    def __init__(self, ros: RosNode, hub: Hub, names: DeviceNameRegistry, *,
                 linger_s: float, replies: Optional[ClientReplies] = None) -> None:
        self._ros = ros
        self._hub = hub
        self._names = names
        self._group = ReentrantCallbackGroup()
        # Goals and decisions wait for their client's answer here.
        self._replies = replies if replies is not None else ClientReplies(hub)
        # An unadvertised server lives this long after its last goal ended, so the ROS
        # client's get_result request (sent or answered after the end) still gets the result,
        # and the status topic (transient local) reaches a ROS client that matches late.
        self._linger_s = linger_s
        self.served: dict[str, ServedAction] = {}
        # Unadvertised, not destroyed yet: advertised again (a client reconnecting), the
        # same server serves on: a second one of the same name would split the ROS goals.
        self._lingering: dict[str, ServedAction] = {}
        hub.add_closed_listener(self._on_client_closed)

    # --- advertise_action ------------------------------------------------------------------
    def advertise_action(self, request: AdvertiseAction, client: Optional[Replier]
                         ) -> Created[AdvertiseActionResult]:
        client = connected_client(client, "action", "executes the goals")
        action = request.action
        ros_type = request.ros_type
        cls = installed_class(ACTION, request.type, ros_type)
        existing = self.served.get(action)
        lingering = self._lingering.get(action)
        if lingering is not None and lingering.ros_type != ros_type:
            raise CommandFailedError("action", "an action no other client advertises (or "
                                     "the same type again)",
                                     f"{action} ({lingering.ros_type}: its client left, the "
                                     f"server ends {self._linger_s:g} s after its last goal)",
                                     code=ErrorCode.ALREADY_EXISTS)
        graph = [] if lingering is not None else get_action_names_and_types(self._ros.node)
        if already_served("action", action, ros_type, client,
                          existing.owner if existing else None,
                          existing.ros_type if existing else "", graph):
            assert existing is not None
            return Created(_describe_served(existing), existed=True)
        key = NameKey.action_server(action)
        if lingering is not None:
            served = self._revive(lingering, client, request)
        else:
            served = ServedAction(action, ros_type, cls, client, key,
                                  self._names.register(key), request.goal_timeout,
                                  request.decides)
            served.server = ActionServer(
                self._ros.node, cls, action, execute_callback=self._execute_for(served),
                goal_callback=self._goal_callback(served),
                cancel_callback=self._cancel_for(served), callback_group=self._group)
        self.served[action] = served
        log.info("serving action %s (%s) for client %s%s", action, ros_type,
                 getattr(client, "peer", "?"),
                 " (its server, still there from an earlier client)" if lingering else "")
        return Created(_describe_served(served), existed=False)

    def _revive(self, served: ServedAction, client: Replier,
                request: AdvertiseAction) -> ServedAction:
        """A lingering server serves again, for `client` (loop thread)."""
        del self._lingering[served.action]
        if served.linger is not None:
            served.linger.cancel()
            served.linger = None
        served.owner = client
        served.device = self._names.register(served.key)
        served.goal_timeout = request.goal_timeout
        served.received = 0
        if served.decides != request.decides:
            served.decides = request.decides
            served.server.register_goal_callback(self._goal_callback(served))
        served.closed = False  # last: the executor thread reads it
        return served

    def _goal_callback(self, served: ServedAction) -> Any:
        return (self._decide_for(served) if served.decides
                else lambda _goal: GoalResponse.ACCEPT)

    def unadvertise_action(self, request: UnadvertiseAction, client: Optional[Replier]
                           ) -> UnadvertisedAction:
        action = request.action
        served = advertised_by(self.served, "action", action, client)
        self._unadvertise(served)
        return UnadvertisedAction(action, served.device)

    def _execute_for(self, served: ServedAction) -> Any:
        async def execute(goal_handle: Any) -> Any:
            # Executor thread. An exception here is logged by rclpy and aborts the goal;
            # still, never raise: end the goal deliberately.
            served.executing += 1
            try:
                answer = RosFuture(executor=self._ros.executor)
                goal_id = bytes(goal_handle.goal_id.uuid).hex()
                if served.closed:
                    goal_handle.abort()
                    return served.cls.Result()
                self._hub.call_soon(self._forward_goal, served, goal_id, goal_handle, answer)
                outcome = await answer
                status, result = outcome if outcome is not None else ("aborted", None)
                if status == "succeeded":
                    goal_handle.succeed()
                elif status == "canceled" and goal_handle.is_cancel_requested:
                    goal_handle.canceled()
                else:  # aborted, or "canceled" without a cancel request (not a legal end)
                    goal_handle.abort()
                return result if result is not None else served.cls.Result()
            except Exception:
                log.exception("executing a goal of %s failed; the goal is aborted",
                              served.action)
                if goal_handle.is_active:
                    goal_handle.abort()
                return served.cls.Result()
            finally:
                served.executing -= 1
                if served.destroy_pending and not served.executing:
                    self._hub.call_soon(self._destroy_later, served)
        return execute

    def _decide_for(self, served: ServedAction) -> Any:
        async def decide(goal: Any) -> GoalResponse:
            # Executor thread: hand the goal to the loop, wait for the client's verdict.
            served.executing += 1
            try:
                if served.closed:
                    return GoalResponse.REJECT
                answer = RosFuture(executor=self._ros.executor)
                self._hub.call_soon(self._forward_decision, served, goal, answer)
                accepted = await answer
                return GoalResponse.ACCEPT if accepted else GoalResponse.REJECT
            except Exception:
                log.exception("deciding on a goal of %s failed; it is rejected",
                              served.action)
                return GoalResponse.REJECT
            finally:
                served.executing -= 1
                if served.destroy_pending and not served.executing:
                    self._hub.call_soon(self._destroy_later, served)
        return decide

    def _forward_decision(self, served: ServedAction, goal: Any, answer: RosFuture) -> None:
        """Put a goal to its deciding client (loop thread)."""
        if served.closed:
            self._decided(answer, False)
            return

        def silence(timed_out: bool) -> None:
            if timed_out:
                log.warning("client %s did not accept or reject a goal of %s within %g s; "
                            "it is rejected", getattr(served.owner, "peer", "?"),
                            served.action, DECISION_TIMEOUT_S)
            self._decided(answer, False)

        try:
            self._replies.ask(
                served.owner, served.device,
                ActionDecide(action=served.action, type=served.ros_type,
                             goal=message_to_dict(goal), timeout=DECISION_TIMEOUT_S),
                metadata_for(served.key, ros_type=served.ros_type),
                timeout=DECISION_TIMEOUT_S, about=served,
                on_answer=lambda text: self._decided(answer, self._verdict(served, text)),
                on_silence=silence)
        except (CodecError, CommandError) as error:
            log.warning("cannot put a goal of %s to its client (%s); it is rejected",
                        served.action, error)
            self._decided(answer, False)

    def _verdict(self, served: ServedAction, text: str) -> bool:
        """The client's answer to `action_decide` -> accepted; unusable answers reject."""
        try:
            data = client_answer(text)
            accept = data.get("accept")
            if not isinstance(accept, bool):
                raise WrongTypeError("accept", "true or false", repr(accept)[:40])
        except CommandError as error:
            log.warning("the answer to a goal of %s is unusable (%s); the goal is rejected",
                        served.action, error)
            return False
        if not accept:
            log.info("the client serving %s rejected a goal: %s", served.action,
                     str(data.get("reason", ""))[:200] or "no reason given")
        return accept

    def _decided(self, answer: RosFuture, accepted: bool) -> None:
        if not answer.done():
            answer.set_result(accepted)
        self._ros.executor.wake()

    def _cancel_for(self, served: ServedAction) -> Any:
        def cancel(goal_handle: Any) -> CancelResponse:  # executor thread: hand off only
            self._hub.call_soon(self._forward_cancel, served,
                                bytes(goal_handle.goal_id.uuid).hex())
            return CancelResponse.ACCEPT
        return cancel

    def _forward_goal(self, served: ServedAction, goal_id: str, handle: Any,
                      answer: RosFuture) -> None:
        """A ROS goal for a served action (loop thread): ask the client that serves it."""
        goal = _ServedGoal(served, goal_id, handle, answer)
        if served.closed:
            self._settle(goal, None)
            return
        served.received += 1

        def silence(timed_out: bool) -> None:
            if timed_out:
                log.warning("client %s did not end a goal of %s within %g s; it is aborted",
                            getattr(served.owner, "peer", "?"), served.action,
                            served.goal_timeout)
            self._settle(goal, None)

        try:
            self._replies.ask(
                served.owner, served.device,
                ActionGoal(action=served.action, type=served.ros_type, goal_id=goal_id,
                           goal=message_to_dict(handle.request), timeout=served.goal_timeout),
                metadata_for(served.key, ros_type=served.ros_type),
                timeout=served.goal_timeout, about=served,
                on_answer=lambda text: self._settle(goal, self._outcome_from(served, text)),
                on_silence=silence)
        except (CodecError, CommandError) as error:
            log.warning("cannot forward a goal of %s to its client (%s); it is aborted",
                        served.action, error)
            self._settle(goal, None)
            return
        served.goals[goal_id] = goal

    def _forward_cancel(self, served: ServedAction, goal_id: str) -> None:
        if served.closed or goal_id not in served.goals:
            return
        self._replies.tell(served.owner, served.device,
                           ActionCancel(action=served.action, goal_id=goal_id),
                           metadata_for(served.key, ros_type=served.ros_type))

    def action_feedback(self, request: ActionFeedback, client: Optional[Replier]
                        ) -> ActionFeedbackResult:
        action = request.action
        served = self.served.get(action)
        goal = served.goals.get(request.goal_id) if served is not None else None
        if served is None or goal is None or (client is not None and served.owner is not client):
            raise CommandFailedError("goal_id", f"a goal of {action} this client is executing",
                                     request.goal_id, code=ErrorCode.NOT_FOUND)
        feedback = message_from_json(served.cls.Feedback, request.feedback, "feedback")
        goal.feedbacks += 1
        # Published now, in order with the client's answer that ends the goal (rcl's publish
        # is thread-safe; the goal handle's own lock guards against its destruction).
        goal.handle.publish_feedback(feedback)
        return ActionFeedbackResult(action, goal.goal_id, goal.feedbacks)

    def _outcome_from(self, served: ServedAction, text: str) -> Optional[tuple[str, Any]]:
        """The client's answer -> (status, Result), judged by its JSON; None (abort) with a
        warning if unusable."""
        try:
            data = client_answer(text)
            status = data.get("status", "succeeded")
            if status not in c.SERVED_OUTCOMES:
                raise CommandFailedError("status", "one of " + "|".join(c.SERVED_OUTCOMES),
                                         repr(status), code=ErrorCode.OUT_OF_RANGE)
            raw = data.get("result", {})
            if not isinstance(raw, dict):
                raise WrongTypeError("result", "an object with the result fields",
                                     type(raw).__name__)
            return status, message_from_json(served.cls.Result, raw, "result")
        except (CommandError, CodecError) as error:
            log.warning("the answer to a goal of %s is unusable (%s); the goal is aborted",
                        served.action, error)
            return None

    def _settle(self, goal: _ServedGoal, outcome: Optional[tuple[str, Any]]) -> None:
        goal.served.goals.pop(goal.goal_id, None)
        if not goal.answer.done():
            goal.answer.set_result(outcome)
        # The executor resumes a waiting coroutine only when something wakes it.
        self._ros.executor.wake()

    def _unadvertise(self, served: ServedAction) -> None:
        served.closed = True
        self.served.pop(served.action, None)
        self._replies.withdraw(served)  # its goals abort, its undecided goals are rejected
        self._names.release(served.key)
        self._destroy_later(served)
        log.info("no longer serving action %s", served.action)

    def _destroy_later(self, served: ServedAction) -> None:
        """Destroy the server in the executor thread once no goal is executing, and not
        before the ROS clients had time to fetch the results (loop thread). Advertised
        again meanwhile, it is not destroyed."""
        if not served.closed:
            return
        self._lingering[served.action] = served
        if served.linger is not None:
            served.linger.cancel()
        served.linger = asyncio.get_running_loop().call_later(
            self._linger_s, self._linger_over, served)

    def _linger_over(self, served: ServedAction) -> None:
        served.linger = None
        if not served.closed or self._lingering.get(served.action) is not served:
            return
        del self._lingering[served.action]
        self._ros.executor.create_task(self._destroy_if_idle, served)

    def _destroy_if_idle(self, served: ServedAction) -> None:
        if served.executing:
            served.destroy_pending = True
            return
        served.destroy_pending = False
        if served.server is not None:
            destroy_quietly(served.server, served.action)
            served.server = None

    def _on_client_closed(self, client: Replier) -> None:
        for served in [s for s in self.served.values() if s.owner is client]:
            self._unadvertise(served)

    def describe(self) -> list[dict[str, Any]]:
        return [_describe_served(served).to_dict() for served in self.served.values()]

    def close(self) -> None:
        # The node (with its action servers) is destroyed right after; only make sure no
        # executing goal waits for a client that is gone.
        for served in list(self.served.values()):
            served.closed = True
            self._replies.withdraw(served)
        for served in self._lingering.values():
            if served.linger is not None:
                served.linger.cancel()
        self._ros.executor.wake()
        self.served.clear()
        self._lingering.clear()


def _describe_served(served: ServedAction) -> AdvertiseActionResult:
    return AdvertiseActionResult("served_action", served.action, served.ros_type,
                                 served.device, served.received, served.decides)

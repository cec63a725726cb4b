"""ROS 2 actions in the Pythonic client: goals sent to ROS action servers, and actions this
client serves to ROS.

    gripper = ros.action("/gripper", "control_msgs/action/GripperCommand")
    goal = gripper.send_goal({"command": {"position": 0.04, "max_effort": 5.0}},
                             feedback=lambda fb: print(fb["position"]))
    result = goal.result(timeout=10)     # the result fields; goal.status says how it ended
    goal.cancel()                        # (before it ends)

    def execute(goal, feedback, cancelled):   # runs in a worker thread
        for step in range(5):
            if cancelled(): return "canceled", {}
            feedback({"position": step / 4})
        return "succeeded", {"position": 1.0, "reached_goal": True}
    ros.serve_action("/my_gripper", "control_msgs/action/GripperCommand", execute,
                     accept=lambda goal: goal["command"]["position"] <= 0.08)
    # accept (optional): called first for each goal; False (or (False, "why")) rejects it,
    # and the ROS client gets REJECTED, as from an rclpy server's goal callback.

The daemon sends a goal's feedback and result as STRING messages (JSON) on the goal's own
device; the client routes them by their ``ros2.goal_id`` metadata, so feedback that comes
before the send_goal reply is not lost (the client chooses the goal id).
"""

from __future__ import annotations

import json
import logging
import threading
import uuid
from typing import Any, Callable, Dict, List, Mapping, Optional, Tuple, Union

from protocol import commands as c
from protocol.messages import Command, Message, RtsCommand, String
from protocol.naming import KEY_GOAL_ID
from slicer_client.owner import ResourceOwner
from slicer_client.transport import CommandFn, request_with

__all__ = ["Accept", "Action", "ActionGoalError", "GoalHandle", "ServedAction", "TERMINAL_STATUSES"]

log = logging.getLogger("slicer_client")

# How a goal can end (the daemon's "result" event status).
TERMINAL_STATUSES = ("succeeded", "canceled", "aborted", "lost", "timeout", "unknown")
FeedbackCallback = Callable[[Dict[str, Any]], None]
# execute(goal, feedback, cancelled) -> (status, result) with status one of SERVED_OUTCOMES
Execute = Callable[[Dict[str, Any], Callable[[Mapping[str, Any]], None], Callable[[], bool]],
                   Tuple[str, Mapping[str, Any]]]
# accept(goal) -> True to execute it, or False / (False, reason) to reject it
Accept = Callable[[Dict[str, Any]], Union[bool, Tuple[bool, str]]]


class ActionGoalError(Exception):
    """A goal ended without a result: its server went away (``lost``), its
    ``result_timeout`` passed (``timeout``), or its result could not be read."""

    def __init__(self, goal_id: str, status: str, message: str) -> None:
        super().__init__(f"goal {goal_id} ended {status}: {message}")
        self.goal_id = goal_id
        self.status = status


class GoalHandle:
    """One goal sent by `Action.send_goal`: its feedback as it comes, then its end."""

    def __init__(self, action: Action, goal_id: str,
                 feedback: Optional[FeedbackCallback]) -> None:
        self.action = action
        self.goal_id = goal_id
        self.device = ""
        self.status = "sending"
        self.feedback: List[Dict[str, Any]] = []  # every feedback, in order
        self.error = ""
        self._result: Optional[Dict[str, Any]] = None
        self._callback = feedback
        self._done = threading.Event()

    @property
    def done(self) -> bool:
        return self._done.is_set()

    def _on_event(self, event: Dict[str, Any]) -> None:  # receive thread
        kind = event.get("event")
        if kind == "feedback" and not self.done:
            value = dict(event.get("feedback") or {})
            self.feedback.append(value)
            self.status = str(event.get("status", "executing"))
            if self._callback is not None:
                self.action._client.emit(self._callback, value)
        elif kind == "result":
            self.status = str(event.get("status", "unknown"))
            self.error = str(event.get("error", ""))
            self._result = dict(event["result"]) if isinstance(event.get("result"), dict) \
                else None
            self._done.set()
            self.action._ended(self)

    def result(self, timeout: Optional[float] = None) -> Dict[str, Any]:
        """Wait for the goal's end; return its result fields (whatever the status: a
        canceled or aborted goal has a result too). Raises `TimeoutError` if it has not
        ended within `timeout` s (the goal goes on), `ActionGoalError` if it ended
        without a result."""
        if not self._done.wait(timeout):
            raise TimeoutError(f"goal {self.goal_id} of {self.action.name}: no result within "
                               f"{timeout} s (status {self.status})")
        if self._result is None:
            raise ActionGoalError(self.goal_id, self.status, self.error or "no result")
        return dict(self._result)

    def cancel(self, timeout: float = 4.0) -> bool:
        """Ask the server to cancel; True if it accepted (the end still comes as the
        result, status ``canceled``)."""
        reply = self.action._client.request(c.CancelGoal(
            action=self.action.name, goal_id=self.goal_id, timeout=timeout),
            timeout=timeout + 2.0)
        return reply.accepted

    def __repr__(self) -> str:
        return f"<GoalHandle {self.action.name} {self.goal_id} {self.status}>"


class Action:
    """A ROS action to send goals to (nothing is kept daemon-side but a cached client)."""

    def __init__(self, client: ResourceOwner, name: str, type: str,
                 router: Dict[str, GoalHandle]) -> None:
        c.resolve_action_type(type)  # fail early on a bad type name
        self._client = client
        self.name = name
        self.type = type
        self._router = router
        self._lock = threading.Lock()

    def send_goal(self, goal: Optional[Mapping[str, Any]] = None, *,
                  feedback: Optional[FeedbackCallback] = None, timeout: float = 4.0,
                  result_timeout: Optional[float] = None) -> GoalHandle:
        """Send a goal (its fields as a dict); returns once the server accepted it.
        `feedback(fields)` runs for each feedback. Raises `CommandRefusedError`: code
        REJECTED (the server refused the goal), UNAVAILABLE (no server), TIMEOUT."""
        return self.send_goal_by(
            lambda goal_id: c.SendGoal(action=self.name, type=self.type, goal=dict(goal or {}),
                                       timeout=timeout, result_timeout=result_timeout,
                                       goal_id=goal_id),
            feedback=feedback, timeout=timeout)

    def send_goal_by(self, make_request: Callable[[str], c.Answered[c.SendGoalResult]], *,
                     feedback: Optional[FeedbackCallback] = None,
                     timeout: float = 4.0) -> GoalHandle:
        """Send a goal through an op that sends it on the daemon's side (``send_goal``, or
        ``execute_motion``, which plans the goal first), made by ``make_request(goal_id)``;
        its events come to the returned handle as a `send_goal`'s do."""
        handle = GoalHandle(self, uuid.uuid4().hex, feedback)
        with self._lock:
            self._router[handle.goal_id] = handle
        request = make_request(handle.goal_id)
        try:
            reply = self._client.request(request, timeout=timeout + 2.0)
        except BaseException:
            with self._lock:
                self._router.pop(handle.goal_id, None)
            raise
        handle.device = reply.device
        if not handle.done:
            handle.status = "accepted"
        return handle

    def _ended(self, handle: GoalHandle) -> None:
        with self._lock:
            self._router.pop(handle.goal_id, None)

    def __repr__(self) -> str:
        return f"<Action {self.name} ({self.type})>"


def route_goal_event(router: Dict[str, GoalHandle], message: Message) -> bool:
    """A STRING goal event (receive thread) -> its handle; True if it was one."""
    goal_id = message.metadata.get(KEY_GOAL_ID)
    if not goal_id or not isinstance(message.body, String):
        return False
    handle = router.get(goal_id)
    if handle is None:
        return True  # a goal this client no longer waits for
    try:
        event = json.loads(message.body.text)
    except ValueError:
        log.warning("goal %s: an unreadable event %r", goal_id, message.body.text[:80])
        return True
    handle._on_event(event)
    return True


class ServedAction:
    """An action this client serves to ROS: each goal runs `execute` in a worker thread
    (see the module); advertised again after a reconnect."""

    def __init__(self, client: ResourceOwner, name: str, type: str, execute: Execute, *,
                 goal_timeout: float = 300.0, accept: Optional[Accept] = None) -> None:
        c.resolve_action_type(type)
        self._client = client
        self.name = name
        self.type = type
        self.goal_timeout = goal_timeout
        self._execute = execute
        self._accept = accept
        self._cancelled: Dict[str, threading.Event] = {}
        self.goals = 0
        self.device = ""

    def advertise(self, command: CommandFn) -> None:
        reply = request_with(command, c.AdvertiseAction(
            action=self.name, type=self.type, goal_timeout=self.goal_timeout,
            decides=self._accept is not None))
        self.device = reply.device

    def unadvertise(self) -> None:
        self._client.request(c.UnadvertiseAction(action=self.name))

    def _on_command(self, message: Message) -> None:  # receive thread: hand off
        body = message.body
        assert isinstance(body, Command)
        if body.name == c.ActionCancel.op:
            cancel = c.ActionCancel.from_json(body.text)
            flag = self._cancelled.get(cancel.goal_id)
            if flag is not None:
                flag.set()
            return
        if body.name == c.ActionDecide.op:
            threading.Thread(target=self._decide,
                             args=(body.command_id, c.ActionDecide.from_json(body.text)),
                             name=f"action {self.name} accept", daemon=True).start()
            return
        request = c.ActionGoal.from_json(body.text)
        self._cancelled[request.goal_id] = threading.Event()
        self.goals += 1
        threading.Thread(target=self._run, args=(body.command_id, request),
                         name=f"action {self.name}", daemon=True).start()

    def _run(self, command_id: int, request: c.ActionGoal) -> None:
        flag = self._cancelled[request.goal_id]

        def feedback(fields: Mapping[str, Any]) -> None:
            self._client.request(c.ActionFeedback(action=self.name, goal_id=request.goal_id,
                                                  feedback=dict(fields)))
        try:
            status, result = self._execute(dict(request.goal), feedback, flag.is_set)
            reply = c.Reply.success(c.ActionGoal.op, {"status": status, "result": dict(result)})
        except Exception as error:  # noqa: BLE001 - the goal is aborted, the client goes on
            log.exception("executing a goal of %s failed", self.name)
            reply = c.Reply.failure(c.ActionGoal.op, c.ErrorCode.INTERNAL,
                                    f"{type(error).__name__}: {error}")
        finally:
            self._cancelled.pop(request.goal_id, None)
        self._answer(command_id, reply, f"the end of goal {request.goal_id}")

    def _decide(self, command_id: int, request: c.ActionDecide) -> None:
        accept = self._accept
        try:
            verdict = accept(dict(request.goal)) if accept is not None else True
            accepted, reason = verdict if isinstance(verdict, tuple) else (verdict, "")
            answer = {"accept": bool(accepted), "reason": str(reason)}
        except Exception as error:  # noqa: BLE001 - the goal is rejected, the client goes on
            log.exception("deciding on a goal of %s failed", self.name)
            answer = {"accept": False, "reason": f"{type(error).__name__}: {error}"}
        self._answer(command_id, c.Reply.success(c.ActionDecide.op, answer), "a verdict")

    def _answer(self, command_id: int, reply: c.Reply, what: str) -> None:
        try:
            self._client.send(Message(device_name=self.device, body=RtsCommand(
                command_id=command_id, name=reply.op, text=reply.to_json()),
                metadata=reply.metadata()))
        except ConnectionError as error:  # the daemon has ended the goal already
            log.info("%s of %s was not sent: %s", what, self.name, error)

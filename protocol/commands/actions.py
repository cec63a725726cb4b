"""Action ops: sending goals to ROS action servers, and actions a client serves.

Sending (Slicer -> ROS): `send_goal` is answered once the server accepted the goal (or
refused it: REJECTED; no server: UNAVAILABLE; no answer: TIMEOUT). Feedback and then the
result arrive afterwards as STRING messages (JSON, `GoalEvent`) on the goal's own device,
sent to the client that sent the goal; `cancel_goal` asks the server to cancel it.

Serving (ROS -> Slicer): after `advertise_action`, each goal a ROS node sends reaches the
client as an `action_goal` COMMAND; the client streams `action_feedback` and answers the
COMMAND with ``{"status": "succeeded"|"aborted"|"canceled", "result": {...}}``. A ROS
client's cancel request reaches it as an `action_cancel` COMMAND. A client that advertised
with ``decides`` is asked first, by an `action_decide` COMMAND, whether to accept the goal
(answer ``{"accept": true|false, "reason": "..."}``): a refused goal is REJECTED to ROS,
as an rclpy server's goal callback would, and never executed.
"""

from __future__ import annotations

import re
import uuid
from dataclasses import dataclass, field
from typing import Any, Optional, cast

from protocol.commands.errors import OutOfRangeError, WrongTypeError
from protocol.commands.fields import MISSING, Args
from protocol.commands.op import ActionUse, Bridge, Example, Op, Resource
from protocol.commands.results import (AdvertiseActionResult, Answered, CancelGoalResult,
                                       Result, SendGoalResult)
from protocol.commands.types import resolve_action_type
from protocol.commands.wire import json_type

__all__ = ["GOAL_STATUSES", "SERVED_OUTCOMES", "ActionCancel", "ActionDecide",
           "ActionFeedback", "ActionFeedbackResult", "ActionGoal", "AdvertiseAction",
           "CancelGoal", "ListActions", "ListActionsResult", "SendGoal", "UnadvertiseAction",
           "UnadvertisedAction", "goal_id_text"]

# action_msgs/msg/GoalStatus codes -> the names replies and goal events use.
GOAL_STATUSES: dict[int, str] = {0: "unknown", 1: "accepted", 2: "executing", 3: "canceling",
                                 4: "succeeded", 5: "canceled", 6: "aborted"}
# How a serving client may end a goal.
SERVED_OUTCOMES = ("succeeded", "aborted", "canceled")

_GOAL_ID = re.compile(r"[0-9a-f]{32}\Z")


def goal_id_text(text: str, path: str = "goal_id") -> str:
    """A goal id as clients write it (a UUID, with or without dashes, any case) -> 32
    lower-case hex digits, the form replies and metadata use."""
    if not isinstance(text, str):
        raise WrongTypeError(path, "a UUID string", json_type(text))
    try:
        return uuid.UUID(text.strip()).hex
    except ValueError:
        raise OutOfRangeError(path, "a UUID (32 hex digits, dashes allowed)",
                              repr(text[:64])) from None


def _action_type(a: Args) -> str:
    text = a.req_str("type")
    resolve_action_type(text, a.path("type"))
    return text


def _object(a: Args, name: str) -> dict[str, Any]:
    raw = a.raw(name, False)
    if raw is MISSING:
        return {}
    if not isinstance(raw, dict):
        raise WrongTypeError(a.path(name), "an object", json_type(raw))
    return raw


@dataclass(frozen=True)
class ListActionsResult(Result):
    """The actions some node serves, each ``action`` with its ``types``."""

    actions: tuple[dict[str, Any], ...]


@dataclass(frozen=True)
class UnadvertisedAction(Result):
    action: str
    device: str


@dataclass(frozen=True)
class ActionFeedbackResult(Result):
    """The feedbacks published for the goal so far."""

    action: str
    goal_id: str
    feedbacks: int


@dataclass(frozen=True)
class ListActions(Op, op="list_actions", writes=False, result=ListActionsResult):
    """Every action of the ROS graph with its types."""

    examples = (Example({}),)

    def resources(self) -> tuple[Resource, ...]:
        return ()

    @classmethod
    def from_args(cls, a: Args) -> ListActions:
        return cls()


@dataclass(frozen=True)
class SendGoal(Op, Answered[SendGoalResult], op="send_goal", ros_names=("action",), writes=True):
    """Send a goal to a ROS action server. ``timeout``: for the server to be found and to
    accept (keep it below the client's own command timeout); ``result_timeout``: if set,
    the daemon cancels the goal when no result came by then (the goal ends ``timeout``).
    ``goal_id``: the client may choose the goal's UUID (so it knows the goal before the
    reply); the daemon draws one otherwise."""

    examples = (Example(
        {"action": "/a", "type": "control_msgs/action/GripperCommand"},
        {("action", "action", "/a")}),)

    action: str
    type: str
    goal: dict[str, Any] = field(default_factory=dict)
    timeout: float = 4.0
    result_timeout: Optional[float] = None
    goal_id: Optional[str] = None

    def resources(self) -> tuple[Resource, ...]:
        return (ActionUse("action", self.action, self.type, writes=True),)

    @property
    def ros_type(self) -> str:
        return resolve_action_type(self.type)

    @classmethod
    def from_args(cls, a: Args) -> SendGoal:
        action, kind = a.ros_name("action"), _action_type(a)
        goal = _object(a, "goal")
        timeout = cast(float, a.opt_float("timeout", 4.0, low=0.0, high=300.0, low_open=True))
        result_timeout = a.opt_float("result_timeout", None, low=0.0, high=86_400.0,
                                     low_open=True)
        raw_id = a.opt_str("goal_id", None, max_len=64)
        return cls(action=action, type=kind, goal=goal, timeout=timeout,
                   result_timeout=result_timeout,
                   goal_id=goal_id_text(raw_id, a.path("goal_id")) if raw_id else None)


@dataclass(frozen=True)
class CancelGoal(Op, Answered[CancelGoalResult], op="cancel_goal",
                 ros_names=("action",), writes=True):
    """Ask the server to cancel a goal this client sent (its end still arrives as the
    goal's result event, status ``canceled`` if the server honours it)."""

    examples = (Example(
        {"action": "/a", "goal_id": "00000000000000000000000000000000"},
        {("action", "action", "/a")}),)

    action: str
    goal_id: str
    timeout: float = 4.0

    def resources(self) -> tuple[Resource, ...]:
        return (ActionUse("action", self.action, writes=True),)

    @classmethod
    def from_args(cls, a: Args) -> CancelGoal:
        return cls(action=a.ros_name("action"),
                   goal_id=goal_id_text(a.req_str("goal_id", max_len=64), a.path("goal_id")),
                   timeout=cast(float, a.opt_float("timeout", 4.0, low=0.0, high=300.0,
                                                   low_open=True)))


@dataclass(frozen=True)
class AdvertiseAction(Op, Answered[AdvertiseActionResult], op="advertise_action",
                      ros_names=("action",), writes=True,
                      creates=Bridge("served_action", ("action",), per_connection=True)):
    """Offer a ROS action served by this client: each goal reaches it as an `ActionGoal`
    COMMAND. ``goal_timeout``: how long a goal may run before the daemon aborts it.
    ``decides``: each goal is first put to the client (`ActionDecide`), which accepts or
    rejects it; otherwise every goal is accepted."""

    examples = (Example(
        {"action": "/a", "type": "control_msgs/GripperCommand"},
        {("action", "action", "/a")}),)

    action: str
    type: str
    goal_timeout: float = 300.0
    decides: bool = False

    def resources(self) -> tuple[Resource, ...]:
        return (ActionUse("action", self.action, self.type, writes=True, serves=True),)

    @property
    def ros_type(self) -> str:
        return resolve_action_type(self.type)

    @classmethod
    def from_args(cls, a: Args) -> AdvertiseAction:
        return cls(action=a.ros_name("action"), type=_action_type(a),
                   goal_timeout=cast(float, a.opt_float("goal_timeout", 300.0, low=0.0,
                                                        high=86_400.0, low_open=True)),
                   decides=a.opt_bool("decides", False))


@dataclass(frozen=True)
class UnadvertiseAction(Op, op="unadvertise_action", ros_names=("action",), writes=False,
                        result=UnadvertisedAction,
                        removes="served_action"):
    examples = (Example({"action": "/a"}),)

    action: str

    def resources(self) -> tuple[Resource, ...]:
        return ()  # only the client that serves it may

    @classmethod
    def from_args(cls, a: Args) -> UnadvertiseAction:
        return cls(action=a.ros_name("action"))


@dataclass(frozen=True)
class ActionFeedback(Op, op="action_feedback", ros_names=("action",), writes=True,
                     result=ActionFeedbackResult):
    """Feedback of a goal this client serves, published to the ROS client that sent it."""

    examples = (Example(
        {"action": "/a", "goal_id": "00000000000000000000000000000000", "feedback": {}},
        {("action", "action", "/a")}),)

    action: str
    goal_id: str
    feedback: dict[str, Any] = field(default_factory=dict)

    def resources(self) -> tuple[Resource, ...]:
        return (ActionUse("action", self.action, writes=True, serves=True),)

    @classmethod
    def from_args(cls, a: Args) -> ActionFeedback:
        return cls(action=a.ros_name("action"),
                   goal_id=goal_id_text(a.req_str("goal_id", max_len=64), a.path("goal_id")),
                   feedback=_object(a, "feedback"))


@dataclass(frozen=True)
class ActionGoal(Op, op="action_goal", ros_names=("action",), writes=False, to_client=True):
    """Sent by the daemon to the client that advertised ``action``: one goal to execute
    within ``timeout`` seconds. Answer: ``{"status": ..., "result": {...}}``."""

    examples = (Example(
        {"action": "/a", "type": "control_msgs/GripperCommand",
         "goal_id": "00000000000000000000000000000000", "goal": {}}),)

    action: str
    type: str
    goal_id: str
    goal: dict[str, Any] = field(default_factory=dict)
    timeout: float = 300.0

    def resources(self) -> tuple[Resource, ...]:
        return ()  # the daemon sends it; no client may

    @classmethod
    def from_args(cls, a: Args) -> ActionGoal:
        return cls(action=a.ros_name("action"), type=_action_type(a),
                   goal_id=goal_id_text(a.req_str("goal_id", max_len=64), a.path("goal_id")),
                   goal=a.req_obj_raw("goal"),
                   timeout=cast(float, a.opt_float("timeout", 300.0, low=0.0, high=86_400.0,
                                                   low_open=True)))


@dataclass(frozen=True)
class ActionDecide(Op, op="action_decide", ros_names=("action",), writes=False, to_client=True):
    """Sent by the daemon to a client that advertised ``action`` with ``decides``: a ROS
    client sent this goal; answer ``{"accept": bool, "reason": str}`` within ``timeout``
    seconds (no answer in time: the goal is rejected). An accepted goal then comes as an
    `ActionGoal`."""

    examples = (Example({"action": "/a", "type": "control_msgs/GripperCommand", "goal": {}}),)

    action: str
    type: str
    goal: dict[str, Any] = field(default_factory=dict)
    timeout: float = 10.0

    def resources(self) -> tuple[Resource, ...]:
        return ()  # the daemon sends it; no client may

    @classmethod
    def from_args(cls, a: Args) -> ActionDecide:
        return cls(action=a.ros_name("action"), type=_action_type(a),
                   goal=a.req_obj_raw("goal"),
                   timeout=cast(float, a.opt_float("timeout", 10.0, low=0.0, high=3_600.0,
                                                   low_open=True)))


@dataclass(frozen=True)
class ActionCancel(Op, op="action_cancel", ros_names=("action",), writes=False, to_client=True):
    """Sent by the daemon to the serving client: a ROS client asks to cancel a goal. The
    client ends the goal (its `ActionGoal` answer, status ``canceled``) when it can."""

    examples = (Example({"action": "/a", "goal_id": "00000000000000000000000000000000"}),)

    action: str
    goal_id: str

    def resources(self) -> tuple[Resource, ...]:
        return ()  # the daemon sends it; no client may

    @classmethod
    def from_args(cls, a: Args) -> ActionCancel:
        return cls(action=a.ros_name("action"),
                   goal_id=goal_id_text(a.req_str("goal_id", max_len=64), a.path("goal_id")))

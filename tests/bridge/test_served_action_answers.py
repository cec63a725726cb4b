"""An action a TCP client serves (`advertise_action`), answered by hand: a raw connection
receives the daemon's `action_goal` / `action_decide` COMMANDs and sends back whatever a
client without slicer_client might (a bad status, a result that is not an object, fields of
the wrong type, a refusal envelope, a verdict that is not a boolean). A real rclpy
ActionClient in another process (`gripper_action_client.py`) sends the goals and prints how
they ended: every unusable answer aborts the goal (or rejects it), and the daemon goes on.
Also: the same action advertised twice, unadvertised by its owner, and a goal that reaches
the server while it lingers after its client left.
"""

from __future__ import annotations

import json
import queue
from typing import Any, Iterator, Optional

import pytest

from protocol.commands import ErrorCode, Reply
from protocol.messages import Command, Message, RtsCommand
from slicer_client.connection import CommandRefusedError, Connection
from support import Child, Processes, RunningDaemon, scaled

pytestmark = pytest.mark.ros

GRIPPER = "control_msgs/action/GripperCommand"
SUCCEEDED, CANCELED, ABORTED = 4, 5, 6


class HandServer:
    """A raw connection that serves an action: COMMANDs from the daemon are queued, each
    answered by `answer` with any text."""

    def __init__(self, daemon: RunningDaemon) -> None:
        self.commands: queue.Queue[Message] = queue.Queue()
        self.connection = Connection("127.0.0.1", daemon.port, on_message=self._on_message)
        self.device = ""

    def _on_message(self, message: Message) -> None:  # receive thread
        if isinstance(message.body, Command):
            self.commands.put(message)

    def advertise(self, action: str, **extra: Any) -> dict[str, Any]:
        reply = self.connection.command("advertise_action",
                                        {"action": action, "type": GRIPPER, **extra})
        self.device = reply["device"]
        return reply

    def next_command(self, name: str) -> tuple[Message, dict[str, Any]]:
        message = self.commands.get(timeout=scaled(30))
        assert isinstance(message.body, Command)
        assert message.body.name == name, (message.body.name, message.body.text)
        return message, json.loads(message.body.text)

    def answer(self, message: Message, text: str) -> None:
        assert isinstance(message.body, Command)
        self.connection.send(Message(device_name=self.device, body=RtsCommand(
            command_id=message.body.command_id, name=message.body.name, text=text)))

    def close(self) -> None:
        self.connection.close()


@pytest.fixture
def hand(daemon: RunningDaemon) -> Iterator[HandServer]:
    server = HandServer(daemon)
    yield server
    server.close()


def ros_goal(processes: Processes, action: str, position: str, *extra: str) -> Child:
    return processes.python("caller", "gripper_action_client.py", action, position, *extra)


def ros_result(caller: Child) -> dict[str, Any]:
    line = caller.wait_for_output("RESULT ", timeout=60)
    result: dict[str, Any] = json.loads(line[line.index("RESULT ") + 7:])
    return result


@pytest.mark.parametrize("answer, logged", [
    ({"status": "exploded", "result": {}}, "status: expected one of succeeded|aborted|canceled"),
    ({"status": "succeeded", "result": [1, 2]}, "result: expected an object with the result "
                                                "fields, got list"),
    ({"status": "succeeded", "result": {"position": "far"}}, "result.position"),
    (Reply.failure("action_goal", ErrorCode.INTERNAL, "the robot is on fire").to_json(),
     "ok: expected true, got false (the robot is on fire)"),
    ({"status": "canceled", "result": {"position": 0.2}}, None),
], ids=["bad-status", "result-not-object", "result-wrong-type", "refused", "canceled-unasked"])
def test_an_unusable_answer_aborts_the_goal(hand: HandServer, processes: Processes,
                                            daemon: RunningDaemon, answer: Any,
                                            logged: Optional[str]) -> None:
    hand.advertise("/hand_gripper")
    caller = ros_goal(processes, "/hand_gripper", "0.4")
    message, goal = hand.next_command("action_goal")
    assert goal["action"] == "/hand_gripper" and goal["type"] == GRIPPER
    assert goal["goal"] == {"command": {"position": 0.4, "max_effort": 1.0}}
    hand.answer(message, answer if isinstance(answer, str) else json.dumps(answer))
    result = ros_result(caller)
    # "canceled" without a cancel request is no legal end either: aborted too, its result
    # kept; an unusable answer has no result.
    position = 0.2 if logged is None else 0.0
    assert result == {"status": ABORTED, "position": position, "reached_goal": False}
    if logged is not None:
        line = daemon.child.wait_for_output("the goal is aborted")
        assert "is unusable" in line and "/hand_gripper" in line and logged in line, line
    # The action still serves: a good answer now succeeds.
    again = ros_goal(processes, "/hand_gripper", "0.6")
    message, goal = hand.next_command("action_goal")
    hand.answer(message, json.dumps({"status": "succeeded",
                                     "result": {"position": 0.6, "reached_goal": True}}))
    assert ros_result(again) == {"status": SUCCEEDED, "position": 0.6, "reached_goal": True}


def test_a_goal_json_cannot_carry_is_aborted_without_asking_the_client(
        hand: HandServer, processes: Processes, daemon: RunningDaemon) -> None:
    """A NaN position has no JSON form: the goal never reaches the client."""
    hand.advertise("/nan_gripper")
    caller = ros_goal(processes, "/nan_gripper", "nan")
    assert ros_result(caller)["status"] == ABORTED
    line = daemon.child.wait_for_output("cannot forward a goal of /nan_gripper")
    assert "expected finite doubles (JSON has no NaN or infinity), got nan" in line
    assert hand.commands.empty()


def test_a_verdict_that_is_not_a_boolean_rejects_and_nan_is_never_asked(
        hand: HandServer, processes: Processes, daemon: RunningDaemon) -> None:
    reply = hand.advertise("/hand_picky", decides=True)
    assert reply["decides"] is True
    caller = ros_goal(processes, "/hand_picky", "0.5")
    message, asked = hand.next_command("action_decide")
    assert asked["goal"] == {"command": {"position": 0.5, "max_effort": 1.0}}
    hand.answer(message, json.dumps({"accept": "yes please"}))
    caller.wait_for_output("REJECTED", timeout=60)
    line = daemon.child.wait_for_output("the goal is rejected")
    assert "accept: expected true or false" in line and "'yes please'" in line
    # A goal JSON cannot carry is rejected without asking.
    nan = ros_goal(processes, "/hand_picky", "nan")
    nan.wait_for_output("REJECTED", timeout=60)
    daemon.child.wait_for_output("cannot put a goal of /hand_picky to its client")
    # A refusal with a reason is a plain rejection; an acceptance executes the goal.
    refused = ros_goal(processes, "/hand_picky", "0.7")
    message, _ = hand.next_command("action_decide")
    hand.answer(message, json.dumps({"accept": False, "reason": "too wide today"}))
    refused.wait_for_output("REJECTED", timeout=60)
    daemon.child.wait_for_output("rejected a goal: too wide today")
    accepted = ros_goal(processes, "/hand_picky", "0.1")
    message, _ = hand.next_command("action_decide")
    hand.answer(message, json.dumps({"accept": True}))
    message, _ = hand.next_command("action_goal")
    hand.answer(message, json.dumps({"result": {"position": 0.1}}))  # status defaults
    assert ros_result(accepted)["status"] == SUCCEEDED
    assert hand.commands.empty()


def test_advertised_twice_unadvertised_then_revived_deciding(
        daemon: RunningDaemon, processes: Processes) -> None:
    """The same client advertising again gets the existing one; its owner unadvertises it;
    a goal reaching the lingering server is aborted (not served by anybody); advertised
    again with ``decides``, the lingering server asks for verdicts from then on."""
    first = HandServer(daemon)
    try:
        made = first.advertise("/hand_again")
        assert made["existed"] is False and made["decides"] is False
        again = first.connection.command("advertise_action",
                                         {"action": "/hand_again", "type": GRIPPER})
        assert again["existed"] is True and again["device"] == made["device"]
        with pytest.raises(CommandRefusedError) as other_type:
            first.connection.command("advertise_action", {
                "action": "/hand_again", "type": "control_msgs/action/PointHead"})
        assert other_type.value.code == ErrorCode.ALREADY_EXISTS
        gone = first.connection.command("unadvertise_action", {"action": "/hand_again"})
        assert (gone["action"], gone["device"]) == ("/hand_again", made["device"])
        daemon.child.wait_for_output("no longer serving action /hand_again")
        listed = first.connection.command("list_bridges")["bridges"]
        assert not [b for b in listed if b.get("action") == "/hand_again"]
        # The server lingers (10 s): a ROS goal now is aborted at once.
        orphan = ros_goal(processes, "/hand_again", "0.3")
        assert ros_result(orphan)["status"] == ABORTED
        assert first.commands.empty()
        revived = first.advertise("/hand_again", decides=True)
        assert revived["existed"] is False and revived["decides"] is True
        daemon.child.wait_for_output("its server, still there from an earlier client")
        caller = ros_goal(processes, "/hand_again", "0.3")
        message, _ = first.next_command("action_decide")
        first.answer(message, json.dumps({"accept": False}))
        caller.wait_for_output("REJECTED", timeout=60)
        # Unadvertised again: a goal for the deciding, lingering server is rejected unasked.
        first.connection.command("unadvertise_action", {"action": "/hand_again"})
        late = ros_goal(processes, "/hand_again", "0.3")
        late.wait_for_output("REJECTED", timeout=60)
        assert first.commands.empty()
    finally:
        first.close()


def test_feedback_for_a_goal_it_does_not_execute_is_refused(
        hand: HandServer, processes: Processes) -> None:
    hand.advertise("/hand_feedback")
    caller = ros_goal(processes, "/hand_feedback", "0.5")
    message, goal = hand.next_command("action_goal")
    with pytest.raises(CommandRefusedError) as bad:
        hand.connection.command("action_feedback", {"action": "/hand_feedback",
                                                    "goal_id": goal["goal_id"],
                                                    "feedback": {"position": "half"}})
    assert bad.value.code == ErrorCode.WRONG_TYPE and bad.value.field.startswith("feedback")
    done = hand.connection.command("action_feedback", {"action": "/hand_feedback",
                                                       "goal_id": goal["goal_id"],
                                                       "feedback": {"position": 0.25}})
    assert done["feedbacks"] == 1 and done["goal_id"] == goal["goal_id"]
    hand.answer(message, json.dumps({"status": "aborted", "result": {"position": 0.25}}))
    assert ros_result(caller) == {"status": ABORTED, "position": 0.25, "reached_goal": False}
    with pytest.raises(CommandRefusedError) as ended:
        hand.connection.command("action_feedback", {"action": "/hand_feedback",
                                                    "goal_id": goal["goal_id"],
                                                    "feedback": {"position": 0.3}})
    assert ended.value.code == ErrorCode.NOT_FOUND and ended.value.field == "goal_id"

"""Goals the daemon sends to real rclpy action servers in other processes, on the paths a
user hits when things go wrong: a goal id already in flight, a cancel while the server has
not accepted yet, a cancel the busy server does not answer, a client that leaves while its
goal is being accepted (or while the cancel goes unanswered), feedback JSON cannot carry,
and the action's hidden cancel service called with another type.
"""

from __future__ import annotations

import json
import threading
import uuid
from typing import Any

import pytest

from protocol.commands import ErrorCode
from protocol.messages import String
from protocol.naming import KEY_GOAL_ID
from slicer_client.connection import Connection
from support import Child, Processes, RunningDaemon, refused, scaled, wait_until

pytestmark = pytest.mark.ros

GRIPPER = "control_msgs/action/GripperCommand"


def goal(position: float, effort: float = 2.0) -> dict[str, Any]:
    return {"command": {"position": position, "max_effort": effort}}


def gripper(processes: Processes, action: str, *args: str) -> Child:
    child = processes.python(action.strip("/"), "gripper_action_server.py", "--action",
                             action, *args)
    child.wait_for_output("READY")
    return child


def test_a_goal_id_in_flight_cannot_be_used_again(client: Connection,
                                                  processes: Processes) -> None:
    gripper(processes, "/busy_id", "--steps", "100", "--period", "0.05")
    goal_id = uuid.uuid4().hex
    first = client.command("send_goal", {"action": "/busy_id", "type": GRIPPER,
                                         "goal": goal(1.0), "goal_id": goal_id,
                                         "timeout": scaled(20)}, timeout=scaled(25))
    assert first["goal_id"] == goal_id and first["status"] == "accepted"
    error = refused(lambda: client.command("send_goal", {
        "action": "/busy_id", "type": GRIPPER, "goal": goal(0.5), "goal_id": goal_id}))
    assert error.code == ErrorCode.ALREADY_EXISTS and error.field == "goal_id"
    assert goal_id in str(error)
    assert client.command("cancel_goal", {"action": "/busy_id", "goal_id": goal_id},
                          timeout=scaled(10))["accepted"] is True


def test_the_hidden_cancel_service_with_another_type_is_forbidden(client: Connection) -> None:
    error = refused(lambda: client.command("call_service", {
        "service": "/some_action/_action/cancel_goal", "type": "std_srvs/srv/Trigger"}))
    assert error.code == ErrorCode.FORBIDDEN and error.field == "type"
    assert "action_msgs/srv/CancelGoal" in str(error) and "/some_action" in str(error)


def test_cancel_before_the_acceptance_and_a_client_leaving_meanwhile(
        daemon: RunningDaemon, processes: Processes) -> None:
    """The server takes 3 s to accept: meanwhile the goal cannot be cancelled (NOT_FOUND,
    saying why); its client leaving then has the daemon cancel the goal once accepted."""
    server = gripper(processes, "/slow_accept", "--steps", "100", "--period", "0.05",
                     "--accept-delay", "3")
    leaving = daemon.connect()
    # A goal it rejects at once first: the daemon knows the server, so the next goal leaves
    # at once (and its client leaves while the server takes its 3 s, not before it).
    assert refused(lambda: leaving.command("send_goal", {
        "action": "/slow_accept", "type": GRIPPER, "goal": goal(1.0, effort=-1.0),
        "timeout": scaled(20)}, timeout=scaled(25))).code == ErrorCode.REJECTED
    goal_id = uuid.uuid4().hex
    replies: list[Any] = []

    def send() -> None:
        try:
            replies.append(leaving.command("send_goal", {
                "action": "/slow_accept", "type": GRIPPER, "goal": goal(1.0),
                "goal_id": goal_id, "timeout": scaled(20)}, timeout=scaled(25)))
        except Exception as error:  # noqa: BLE001 - the connection closes under it
            replies.append(error)

    sender = threading.Thread(target=send)
    sender.start()
    try:
        wait_until(lambda: any(g["goal_id"] == goal_id
                               for g in leaving.command("list_bridges")["goals"]),
                   scaled(20), "the goal in flight")
        error = refused(lambda: leaving.command("cancel_goal", {"action": "/slow_accept",
                                                                "goal_id": goal_id}))
        assert error.code == ErrorCode.NOT_FOUND and error.field == "goal_id"
        assert "still waiting for its acceptance" in str(error)
        leaving.close()
    finally:
        sender.join(scaled(30))
    assert len(replies) == 1 and isinstance(replies[0], Exception)
    # Accepted after its client left: nobody watches it, the daemon cancels it.
    server.wait_for_output("GOAL 1.0", timeout=30)
    server.wait_for_output("CANCELED", timeout=30)
    assert "DONE" not in server.output()


def test_a_cancel_the_busy_server_does_not_answer(daemon: RunningDaemon,
                                                  processes: Processes) -> None:
    """One executor thread, busy moving the gripper: the cancel request waits. A cancel
    with a short timeout is a TIMEOUT; when the client leaves, the daemon's own cancel
    waits its 10 s and says so in the log; the server, busy all along, ends the goal."""
    server = gripper(processes, "/one_thread", "--steps", "160", "--period", "0.1",
                     "--threads", "1")
    leaving = daemon.connect()
    try:
        sent = leaving.command("send_goal", {"action": "/one_thread", "type": GRIPPER,
                                             "goal": goal(1.0), "timeout": scaled(20)},
                               timeout=scaled(25))
        server.wait_for_output("FEEDBACK")
        error = refused(lambda: leaving.command("cancel_goal", {
            "action": "/one_thread", "goal_id": sent["goal_id"], "timeout": 0.5}))
        assert error.code == ErrorCode.TIMEOUT and error.field == "goal_id"
        assert "within 0.5 s" in str(error)
    finally:
        leaving.close()
    line = daemon.child.wait_for_output(f"cancelling goal {sent['goal_id']} (its client "
                                        f"left) failed", timeout=60)
    assert line.endswith("failed: no answer")
    server.wait_for_output("DONE 1.0", timeout=60)
    assert "CANCELED" not in server.output()


def test_feedback_json_cannot_carry_arrives_as_an_error_event(daemon: RunningDaemon,
                                                              processes: Processes) -> None:
    """A goal of 1e308 over 5 steps: the server's feedback overflows to infinity (no JSON
    form). Each feedback event says so; the result (1e308) still arrives whole."""
    gripper(processes, "/overflow", "--steps", "5", "--period", "0.05")
    events: list[dict[str, Any]] = []
    ended = threading.Event()

    def on_message(message: Any) -> None:
        if isinstance(message.body, String) and message.metadata.get(KEY_GOAL_ID):
            event = json.loads(message.body.text)
            events.append(event)
            if event.get("event") == "result":
                ended.set()

    connection = Connection("127.0.0.1", daemon.port, on_message=on_message)
    try:
        connection.command("send_goal", {"action": "/overflow", "type": GRIPPER,
                                         "goal": goal(1e308), "timeout": scaled(20)},
                           timeout=scaled(25))
        assert ended.wait(scaled(30))
    finally:
        connection.close()
    feedback = [e for e in events if e["event"] == "feedback"]
    assert len(feedback) == 5
    assert feedback[0]["feedback"]["position"] == pytest.approx(2e307)
    for bad in feedback[1:]:
        assert "feedback" not in bad
        assert "feedback.position: expected finite doubles (JSON has no NaN or infinity)" \
            in bad["error"]
        assert bad["status"] == "executing"
    assert events[-1]["status"] == "succeeded" and events[-1]["result"]["position"] == 1e308

"""ROS 2 actions through the real daemon: goals sent to a real rclpy action server in another
process (feedback order, result, cancel mid-goal, two goals at once, a server that dies
mid-goal, an absent server, a rejected goal, a result timeout), and an action a TCP client
serves, driven by a real rclpy ActionClient in another process.
"""

from __future__ import annotations

import json
import threading
from typing import Any

import pytest

import slicer_client
from protocol.commands import ErrorCode
from protocol.messages import String
from protocol.naming import KEY_ACTION, KEY_GOAL_ID, KEY_GOAL_STATUS, KEY_ROLE
from slicer_client.actions import ActionGoalError
from slicer_client.client import Client
from slicer_client.connection import Connection
from support import (Child, Processes, RunningDaemon, refused, scaled, start_daemon,
                     wait_until)

pytestmark = pytest.mark.ros

GRIPPER = "control_msgs/action/GripperCommand"


def goal(position: float, effort: float = 2.0) -> dict[str, Any]:
    return {"command": {"position": position, "max_effort": effort}}


@pytest.fixture(scope="module")
def daemon(module_processes: Processes) -> RunningDaemon:
    return start_daemon(module_processes)


@pytest.fixture(scope="module")
def server(module_processes: Processes) -> Child:
    child = module_processes.python("gripper", "gripper_action_server.py", "--steps", "5",
                                    "--period", "0.1")
    child.wait_for_output("READY")
    return child


# Actions these tests serve through the daemon (unadvertised when their client leaves).
def slow_server(processes: Processes, action: str = "/slow_gripper", *,
                period: float = 0.05, threads: int = 4) -> Child:
    """A gripper server that takes 100 steps of `period` s per goal."""
    child = processes.python("slow-gripper", "gripper_action_server.py", "--action", action,
                             "--steps", "100", "--period", str(period), "--threads",
                             str(threads))
    child.wait_for_output("READY")
    return child


def test_feedback_in_order_then_the_result(ros: Client, server: Child) -> None:
    seen: list[float] = []
    gripper = ros.action("/gripper", GRIPPER)
    handle = gripper.send_goal(goal(0.5), feedback=lambda fb: seen.append(fb["position"]),
                               timeout=scaled(10))
    result = handle.result(timeout=scaled(10))
    assert handle.status == "succeeded"
    assert result == {"position": 0.5, "effort": 2.0, "stalled": False, "reached_goal": True}
    # The handle holds every feedback before its result; the callbacks run on the client's
    # callback thread, which may not have reached the last one yet (seen once in ci61).
    assert [round(f["position"], 6) for f in handle.feedback] == [0.1, 0.2, 0.3, 0.4, 0.5]
    wait_until(lambda: len(seen) == 5, 10, "the fifth feedback callback")
    assert [round(p, 6) for p in seen] == [0.1, 0.2, 0.3, 0.4, 0.5]
    assert handle.done and handle.device.startswith("goal:grippe")


def test_goal_events_on_the_wire(daemon: RunningDaemon, server: Child) -> None:
    """What a client without the Pythonic layer (3D Slicer) sees: STRING messages on the
    goal's device, JSON, with ros2.* metadata naming the action, goal and status."""
    events: list[tuple[str, dict[str, str], dict[str, Any]]] = []
    done = threading.Event()

    def on_message(message: Any) -> None:  # receive thread
        if isinstance(message.body, String) and message.metadata.get(KEY_GOAL_ID):
            event = json.loads(message.body.text)
            events.append((message.device_name, dict(message.metadata), event))
            if event["event"] == "result":
                done.set()

    connection = Connection("127.0.0.1", daemon.port, on_message=on_message)
    try:
        reply = connection.command("send_goal", {"action": "gripper",
                                                 "type": "control_msgs/GripperCommand",
                                                 "goal": goal(1.0), "timeout": scaled(10),
                                                 "goal_id": "0123456789abcdef0123456789ABCDEF"})
        assert reply["goal_id"] == "0123456789abcdef0123456789abcdef"
        assert reply["status"] == "accepted" and reply["action"] == "/gripper"
        assert done.wait(scaled(10))
    finally:
        connection.close()
    devices = {device for device, _, _ in events}
    assert devices == {reply["device"]}
    kinds = [event["event"] for _, _, event in events]
    assert kinds == ["feedback"] * 5 + ["result"]
    assert [event["seq"] for _, _, event in events[:5]] == [1, 2, 3, 4, 5]
    _, meta, last = events[-1]
    assert meta[KEY_ROLE] == "action_goal" and meta[KEY_ACTION] == "/gripper"
    assert meta[KEY_GOAL_ID] == reply["goal_id"] and meta[KEY_GOAL_STATUS] == "succeeded"
    assert last["result"]["position"] == 1.0 and last["feedbacks"] == 5
    assert events[0][1][KEY_GOAL_STATUS] == "executing"


def test_cancel_mid_goal(ros: Client, processes: Processes) -> None:
    slow = slow_server(processes)
    first = threading.Event()
    handle = ros.action("/slow_gripper", GRIPPER).send_goal(
        goal(1.0), feedback=lambda fb: first.set(), timeout=scaled(10))
    assert first.wait(scaled(10))
    assert handle.cancel(timeout=scaled(5)) is True
    result = handle.result(timeout=scaled(10))
    assert handle.status == "canceled"
    assert 0.0 < result["position"] < 1.0 and not result["reached_goal"]
    slow.wait_for_output("CANCELED")
    # The goal is gone: cancelling it again names it.
    error = refused(lambda: handle.cancel())
    assert error.code == ErrorCode.NOT_FOUND and error.field == "goal_id"


def test_two_goals_at_once(ros: Client, server: Child) -> None:
    gripper = ros.action("/gripper", GRIPPER)
    a = gripper.send_goal(goal(1.0), timeout=scaled(10))
    b = gripper.send_goal(goal(-2.0), timeout=scaled(10))
    assert a.goal_id != b.goal_id and a.device != b.device
    assert a.result(scaled(10))["position"] == 1.0
    assert b.result(scaled(10))["position"] == -2.0
    # Each goal got its own feedback, and only its own.
    assert [round(f["position"], 6) for f in a.feedback] == [0.2, 0.4, 0.6, 0.8, 1.0]
    assert [round(f["position"], 6) for f in b.feedback] == [-0.4, -0.8, -1.2, -1.6, -2.0]


def test_a_server_that_dies_mid_goal_ends_the_goal_lost(ros: Client, processes: Processes
                                                        ) -> None:
    dying = processes.python("dying", "gripper_action_server.py", "--action", "/dying",
                             "--steps", "100", "--period", "0.05", "--die-after", "2")
    dying.wait_for_output("READY")
    handle = ros.action("/dying", GRIPPER).send_goal(goal(1.0), timeout=scaled(10))
    dying.wait_for_output("FEEDBACK")
    # DDS notices a crashed participant only when its lease runs out (Fast DDS: 20 s):
    # the wait is bounded by that, not by luck.
    with pytest.raises(ActionGoalError) as ended:
        handle.result(timeout=scaled(40))
    assert ended.value.status == "lost"
    assert "went away" in str(ended.value)


def test_absent_server_is_unavailable(ros: Client) -> None:
    error = refused(lambda: ros.action("/nobody", GRIPPER).send_goal(goal(1.0), timeout=0.5))
    assert error.code == ErrorCode.UNAVAILABLE and error.field == "action"
    assert "no server after 0.5 s" in str(error)


def test_rejected_goal(ros: Client, server: Child) -> None:
    error = refused(lambda: ros.action("/gripper", GRIPPER).send_goal(goal(1.0, effort=-1),
                                                                      timeout=scaled(10)))
    assert error.code == ErrorCode.REJECTED and error.field == "goal"
    assert "rejected" in str(error)
    server.wait_for_output("REJECTED")


def test_result_timeout_cancels_the_goal(ros: Client, processes: Processes) -> None:
    slow = slow_server(processes)
    handle = ros.action("/slow_gripper", GRIPPER).send_goal(
        goal(1.0), timeout=scaled(10), result_timeout=0.5)
    with pytest.raises(ActionGoalError) as ended:
        handle.result(timeout=scaled(10))
    assert ended.value.status == "timeout" and "result_timeout" in str(ended.value)
    slow.wait_for_output("CANCELED")  # the daemon asked the server to stop


def test_a_goal_the_server_answers_too_late_is_cancelled(ros: Client,
                                                         processes: Processes) -> None:
    """No answer within `timeout` is a TIMEOUT, and the goal must not run unwatched: the
    daemon cancels it by its id (for a response that was lost) and again when the late
    acceptance comes."""
    late = processes.python("late-gripper", "gripper_action_server.py", "--action",
                            "/late_gripper", "--steps", "100", "--period", "0.05",
                            "--accept-delay", "2")
    late.wait_for_output("READY")
    gripper = ros.action("/late_gripper", GRIPPER)
    # A goal it rejects (at once) first: the server is known, the next timeout is its answer's.
    assert refused(lambda: gripper.send_goal(goal(1.0, effort=-1.0), timeout=scaled(10))
                   ).code == ErrorCode.REJECTED
    error = refused(lambda: gripper.send_goal(goal(1.0), timeout=0.5))
    assert error.code == ErrorCode.TIMEOUT and "cancel goal" in str(error)
    late.wait_for_output("GOAL 1.0")
    late.wait_for_output("CANCELED")


def test_a_goal_whose_answer_is_lost_is_followed_from_the_status_topic(
        ros: Client, processes: Processes) -> None:
    """The server never answers the goal request (as when Fast DDS drops the response to
    a reader it has not matched yet) but runs the goal and lists it on the status topic:
    send_goal says accepted, and the result comes by the goal's id."""
    server = processes.python("unanswering", "unanswering_action_server.py", "/unanswering")
    server.wait_for_output("READY")
    handle = ros.action("/unanswering", GRIPPER).send_goal(goal(0.3), timeout=scaled(20))
    assert server.wait_for_output("GOAL ").endswith(f"GOAL {handle.goal_id} 0.3")
    result = handle.result(timeout=scaled(20))
    assert handle.status == "succeeded"
    assert result == {"position": 0.3, "effort": 0.0, "stalled": False, "reached_goal": True}
    assert server.wait_for_output("RESULT ").endswith(f"RESULT {handle.goal_id}")


def test_a_client_side_wait_that_ends_first_raises_timeout(ros: Client, server: Child) -> None:
    handle = ros.action("/gripper", GRIPPER).send_goal(goal(1.0), timeout=scaled(10))
    with pytest.raises(TimeoutError):
        handle.result(timeout=0.01)
    assert handle.result(timeout=scaled(10))["reached_goal"] is True


def test_bad_goals_are_named(ros: Client, server: Child) -> None:
    error = refused(lambda: ros.command("send_goal", {
        "action": "/gripper", "type": GRIPPER, "goal": {"command": {"position": "far"}}}))
    assert error.code == ErrorCode.WRONG_TYPE and error.field.startswith("goal.command")
    error = refused(lambda: ros.command("send_goal", {"action": "/gripper",
                                                      "type": "control_msgs/action/Nope"}))
    assert error.code == ErrorCode.UNKNOWN_ROS_TYPE and error.field == "type"
    error = refused(lambda: ros.command("send_goal", {"action": "/gripper", "type": GRIPPER,
                                                      "goal_id": "not-a-uuid"}))
    assert error.code == ErrorCode.OUT_OF_RANGE and error.field == "goal_id"
    error = refused(lambda: ros.command("cancel_goal", {
        "action": "/gripper", "goal_id": "0" * 32}))
    assert error.code == ErrorCode.NOT_FOUND


def test_list_actions(ros: Client, server: Child) -> None:
    def listed() -> bool:
        actions = ros.command("list_actions")["actions"]
        return {"action": "/gripper", "types": [GRIPPER]} in actions
    wait_until(listed, 20, "/gripper in list_actions")


def test_list_actions_lists_served_actions_not_the_daemon_s_own_clients(
        ros: Client, server: Child) -> None:
    """Issue 25, item 11: a goal that found no server leaves the daemon's action client in
    the graph for a while; list_actions lists what some node serves, so not that."""
    refused(lambda: ros.action("/nobody_listed", GRIPPER).send_goal(goal(1.0), timeout=0.5))
    wait_until(lambda: any(t["topic"] == "/nobody_listed/_action/status"
                           for t in ros.command("list_topics")["topics"]), 20,
               "the daemon's client of /nobody_listed in its graph")
    wait_until(lambda: {"action": "/gripper", "types": [GRIPPER]}
               in ros.command("list_actions")["actions"], 20, "/gripper in list_actions")
    actions = ros.command("list_actions")["actions"]
    assert not [a for a in actions if a["action"] == "/nobody_listed"], actions


# ---------------------------------------------------------------------------- served


def test_an_action_served_by_the_client(ros: Client, processes: Processes) -> None:
    seen: list[dict[str, Any]] = []

    def execute(request: dict[str, Any], feedback: Any, cancelled: Any) -> tuple[str, Any]:
        seen.append(request)
        target = request["command"]["position"]
        for step in (1, 2, 3):
            feedback({"position": target * step / 3})
        return "succeeded", {"position": target, "reached_goal": True}

    served = ros.serve_action("/served_gripper", GRIPPER, execute)
    assert served.device == "act:served_gripper"
    caller = processes.python("caller", "gripper_action_client.py", "/served_gripper", "0.3",
                              "--feedbacks", "3")
    line = caller.wait_for_output("RESULT ", timeout=30)
    result = json.loads(line[line.index("RESULT ") + 7:])
    assert result == {"status": 4, "position": 0.3, "reached_goal": True}  # SUCCEEDED

    def feedback(prefix: str) -> list[float]:
        return [round(float(x.split()[1]), 6) for x in caller.lines()
                if x.startswith(prefix + " ")]

    # Every feedback reaches ROS, in order. rclpy's ActionClient may still drop the last
    # ones from its callback when the result overtakes them there (it forgets a goal's
    # feedback callback with its result), as with any action server.
    wait_until(lambda: len(feedback("FEEDBACK_TOPIC")) >= 3, timeout=10,
               what=f"the three feedbacks; the caller said:\n{caller.output()}")
    assert feedback("FEEDBACK_TOPIC") == [0.1, 0.2, 0.3]
    called = feedback("FEEDBACK")
    assert called == [0.1, 0.2, 0.3][:len(called)]
    assert seen == [{"command": {"position": 0.3, "max_effort": 1.0}}]
    bridges = ros.list_bridges()["bridges"]
    assert {"kind": "served_action", "action": "/served_gripper", "type": GRIPPER,
            "device": "act:served_gripper", "goals": 1, "decides": False,
            "clients": 1, "stays": False} in bridges  # it goes with its client


def test_a_served_action_decides_which_goals_it_accepts(ros: Client, processes: Processes
                                                        ) -> None:
    """accept(goal) runs first: a refused goal is REJECTED to the ROS client, as by an
    rclpy goal callback, and never executed; an accept callback that fails rejects too."""
    executed: list[float] = []
    asked: list[float] = []

    def accept(goal: dict[str, Any]) -> Any:
        position = goal["command"]["position"]
        asked.append(position)
        if position < 0:
            raise ValueError("no negative gaps")
        return position <= 1.0, "wider than the gripper opens"

    def execute(request: dict[str, Any], feedback: Any, cancelled: Any) -> tuple[str, Any]:
        executed.append(request["command"]["position"])
        return "succeeded", {"position": request["command"]["position"], "reached_goal": True}

    ros.serve_action("/picky_gripper", GRIPPER, execute, accept=accept)
    wide = processes.python("wide", "gripper_action_client.py", "/picky_gripper", "2.0")
    assert wide.wait_for_output("REJECTED", timeout=30)
    negative = processes.python("negative", "gripper_action_client.py", "/picky_gripper",
                                "-0.5")
    assert negative.wait_for_output("REJECTED", timeout=30)
    fine = processes.python("fine", "gripper_action_client.py", "/picky_gripper", "0.5")
    assert fine.wait_for_output("ACCEPTED", timeout=30)
    line = fine.wait_for_output("RESULT ", timeout=30)
    assert json.loads(line[line.index("RESULT ") + 7:])["status"] == 4  # SUCCEEDED
    assert sorted(asked) == [-0.5, 0.5, 2.0] and executed == [0.5]
    (listed,) = [b for b in ros.list_bridges()["bridges"]
                 if b.get("action") == "/picky_gripper"]
    assert listed["decides"] is True


def test_a_goal_waiting_for_a_verdict_is_rejected_when_its_client_leaves(
        daemon: RunningDaemon, processes: Processes) -> None:
    leaving = slicer_client.connect("127.0.0.1", daemon.port, reconnect=False)
    asked, release = threading.Event(), threading.Event()

    def accept(goal: dict[str, Any]) -> bool:
        asked.set()
        release.wait(scaled(30))
        return True

    leaving.serve_action("/undecided", GRIPPER, lambda *a: ("succeeded", {}), accept=accept)
    caller = processes.python("caller", "gripper_action_client.py", "/undecided", "0.3")
    try:
        assert asked.wait(scaled(20))
        leaving.close()
        caller.wait_for_output("REJECTED", timeout=30)
    finally:
        release.set()


def test_a_served_goal_is_cancelled_by_its_ros_client(ros: Client, processes: Processes
                                                      ) -> None:
    cancelled_seen = threading.Event()

    def execute(request: dict[str, Any], feedback: Any, cancelled: Any) -> tuple[str, Any]:
        feedback({"position": 0.1})
        wait_until(cancelled, 30, "the cancel request")
        cancelled_seen.set()
        return "canceled", {"position": 0.1}

    ros.serve_action("/cancel_me", GRIPPER, execute)
    caller = processes.python("caller", "gripper_action_client.py", "/cancel_me", "0.3",
                              "--cancel-after", "1")
    assert caller.wait_for_output("CANCEL ", timeout=30).endswith("CANCEL 0")
    line = caller.wait_for_output("RESULT ", timeout=30)
    assert json.loads(line[line.index("RESULT ") + 7:])["status"] == 5  # CANCELED
    assert cancelled_seen.is_set()


def test_a_served_goal_aborts_when_its_client_leaves(daemon: RunningDaemon,
                                                     processes: Processes) -> None:
    leaving = slicer_client.connect("127.0.0.1", daemon.port, reconnect=False)
    started, release = threading.Event(), threading.Event()

    def execute(request: dict[str, Any], feedback: Any, cancelled: Any) -> tuple[str, Any]:
        started.set()
        release.wait(scaled(30))  # the client leaves before
        return "succeeded", {}

    leaving.serve_action("/left_behind", GRIPPER, execute)
    caller = processes.python("caller", "gripper_action_client.py", "/left_behind", "0.3")
    assert started.wait(scaled(20))
    leaving.close()
    try:
        line = caller.wait_for_output("RESULT ", timeout=30)
    finally:
        release.set()
    assert json.loads(line[line.index("RESULT ") + 7:])["status"] == 6  # ABORTED


def test_a_served_action_advertised_again_after_its_client_left(daemon: RunningDaemon,
                                                                processes: Processes) -> None:
    """A client that reconnects advertises its action again while the daemon's server of
    it still lingers (results are fetched for 10 s after the last goal): that server serves
    on, for the new client; another type under that name is refused meanwhile."""
    first = slicer_client.connect("127.0.0.1", daemon.port, reconnect=False)
    first.serve_action("/again", GRIPPER, lambda g, fb, cancelled: ("succeeded", {}))
    first.close()
    daemon.child.wait_for_output("no longer serving action /again")
    with slicer_client.connect("127.0.0.1", daemon.port, reconnect=False) as second:
        error = refused(lambda: second.command("advertise_action", {
            "action": "/again", "type": "control_msgs/action/PointHead"}))
        assert (error.error.code, error.error.field) == (ErrorCode.ALREADY_EXISTS, "action")
        assert error.error.message == (
            "action: expected an action no other client advertises (or the same type again), "
            "got /again (control_msgs/action/GripperCommand: its client left, the server "
            "ends 10 s after its last goal)")
        served = second.serve_action("/again", GRIPPER,
                                     lambda g, fb, cancelled: ("succeeded", {"position": 0.4}))
        assert served.device == "act:again"
        (listed,) = [a for a in second.command("list_actions")["actions"]
                     if a["action"] == "/again"]
        assert listed["types"] == [GRIPPER]
        caller = processes.python("caller", "gripper_action_client.py", "/again", "0.4")
        line = caller.wait_for_output("RESULT ", timeout=30)
        assert json.loads(line[line.index("RESULT ") + 7:]) == {
            "status": 4, "position": 0.4, "reached_goal": False}


def test_serving_errors(ros: Client, server: Child) -> None:
    wait_until(lambda: any(a["action"] == "/gripper"
                           for a in ros.command("list_actions")["actions"]), 20, "discovery")
    error = refused(lambda: ros.command("advertise_action", {"action": "/gripper",
                                                             "type": GRIPPER}))
    assert error.code == ErrorCode.ALREADY_EXISTS
    error = refused(lambda: ros.command("action_feedback", {
        "action": "/gripper", "goal_id": "0" * 32, "feedback": {}}))
    assert error.code == ErrorCode.NOT_FOUND
    error = refused(lambda: ros.command("unadvertise_action", {"action": "/gripper"}))
    assert error.code == ErrorCode.NOT_FOUND
    error = refused(lambda: ros.command("action_goal", {
        "action": "/x", "type": GRIPPER, "goal_id": "0" * 32, "goal": {}}))
    assert error.code == ErrorCode.NOT_SUPPORTED  # the daemon sends it, no client may


def test_the_reference_style_facade(ros: Client, server: Child) -> None:
    node = ros.GetDefaultROS2Node()
    client = node.CreateAndAddActionClientNode(GRIPPER, "/gripper")
    assert node.CreateAndAddActionClientNode(GRIPPER, "/gripper") is client
    assert node.GetActionClientNodeByName("/gripper") is client
    events: list[str] = []
    client.AddObserver("ModifiedEvent", lambda caller, event: events.append(event))
    assert client.GetGoalStatus() == "" and client.GetLastResult() is None
    goal_id = client.SendGoal(goal(0.25), timeout=scaled(10))
    assert len(goal_id) == 32
    assert client.WaitForResult(scaled(10))["position"] == 0.25
    wait_until(lambda: len(events) == 6, 10, "5 feedback events and the end")
    assert client.GetGoalStatus() == "succeeded" and client.GetNumberOfFeedbacks() == 5
    assert client.GetLastFeedback()["position"] == pytest.approx(0.25)
    assert client.GetLastResult()["reached_goal"] is True
    assert client.CancelGoal() is False  # it has ended
    assert node.RemoveAndDeleteActionClientNode("/gripper") is True
    assert node.GetActionClientNodeByName("/gripper") is None


def test_goals_in_flight_are_bounded_per_client_and_cancelled_when_it_leaves(
        daemon: RunningDaemon, processes: Processes) -> None:
    slow = slow_server(processes, "/bounded", period=0.5, threads=40)
    greedy = slicer_client.connect("127.0.0.1", daemon.port, reconnect=False)
    other = slicer_client.connect("127.0.0.1", daemon.port, reconnect=False)
    try:
        action = greedy.action("/bounded", GRIPPER)
        handles = [action.send_goal(goal(1.0), timeout=scaled(10)) for _ in range(32)]
        error = refused(lambda: action.send_goal(goal(1.0), timeout=scaled(10)))
        assert error.code == ErrorCode.LIMIT_REACHED and error.field == "goal"
        assert "at most 32 goals in flight per client" in str(error)
        # Another client has its own count, and cannot cancel this client's goals.
        mine = other.action("/bounded", GRIPPER).send_goal(goal(0.5), timeout=scaled(10))
        error = refused(lambda: other.command("cancel_goal", {
            "action": "/bounded", "goal_id": handles[0].goal_id}))
        assert error.code == ErrorCode.NOT_FOUND
        goals = greedy.list_bridges()["goals"]
        assert len(goals) == 33 and {g["device"] for g in goals} >= {h.device for h in handles}
        assert mine.cancel(timeout=scaled(5))
        assert mine.result(scaled(10)) is not None and mine.status == "canceled"
    finally:
        greedy.close()
        other.close()
    # The greedy client left: its goals are cancelled, none of them runs to the end.
    wait_until(lambda: slow.output().count("CANCELED") >= 33, 20, "every goal cancelled")
    assert "DONE" not in slow.output()


def test_a_lost_connection_ends_the_goals_and_a_served_action_comes_back(
        processes: Processes) -> None:
    slow_server(processes, "/far")
    daemon = start_daemon(processes)
    ros = slicer_client.connect("127.0.0.1", daemon.port, retry_interval=0.2)
    back = threading.Event()
    ros.on_connection_change(lambda connected, reason: connected and back.set())
    try:
        handle = ros.action("/far", GRIPPER).send_goal(goal(1.0), timeout=scaled(10))
        ros.serve_action("/back", GRIPPER,
                         lambda g, fb, cancelled: ("succeeded", {"position": 0.7}))
        daemon.child.stop()  # the daemon goes away mid-goal
        with pytest.raises(ActionGoalError) as ended:
            handle.result(timeout=scaled(10))
        assert ended.value.status == "lost" and "connection" in str(ended.value)
        # A new daemon on the same port: the client advertises its action again.
        again = processes.bridge("run", "--port", str(daemon.port))
        again.wait_for_output("listening on", timeout=30)
        assert back.wait(scaled(20))
        caller = processes.python("caller", "gripper_action_client.py", "/back", "0.7")
        line = caller.wait_for_output("RESULT ", timeout=30)
        assert json.loads(line[line.index("RESULT ") + 7:]) == {
            "status": 4, "position": 0.7, "reached_goal": False}
    finally:
        ros.close()


"""Slots a client holds, and rules that must hold on every route (issue 22, items 4, 5
and 12), on a running daemon with raw TCP clients and real rclpy peers."""

from __future__ import annotations

from typing import Any

from hardening_tools import RawClient, ask, reply_to, send_command
from protocol.commands import ErrorCode
from support import Processes, start_daemon, wait_until

TRIGGER = "std_srvs/srv/Trigger"
GRIPPER = "control_msgs/action/GripperCommand"
CANCEL = "action_msgs/srv/CancelGoal"


def _error(reply: dict[str, Any]) -> tuple[int, str]:
    assert not reply["ok"], reply
    return reply["error"]["code"], reply["error"]["field"]


def test_a_client_calling_absent_services_leaves_slots_to_others_and_frees_its_own(
        processes: Processes) -> None:
    """The issue's attack: 64 calls to absent services, each with a 120 s timeout. One
    client gets at most a quarter of the 64 slots, another client's call to a live
    server goes through meanwhile, and the first client's calls end when it leaves."""
    server = processes.python("server", "service_server.py", "--namespace", "/live")
    server.wait_for_output("READY", timeout=30)
    daemon = start_daemon(processes)
    hog, other = RawClient(daemon.port), RawClient(daemon.port)
    try:
        for i in range(64):
            send_command(hog, "call_service", {"service": f"/absent_{i}", "type": TRIGGER,
                                               "request": {}, "timeout": 120}, i + 1)
        # The calls over its share are refused at once, in order; the others wait.
        refused = [reply_to(hog, i) for i in range(17, 65)]
        assert {_error(r) for r in refused} == {(ErrorCode.LIMIT_REACHED, "service")}
        assert "16 calls waiting for an answer per client" in refused[0]["error"]["message"]
        answered = ask(other, "call_service", {"service": "/live/trigger", "type": TRIGGER,
                                               "request": {}, "timeout": 20}, 1, timeout=30)
        assert answered["ok"] and answered["result"]["response"]["success"] is True
    finally:
        hog.close()

    def waiting() -> int:
        clients = ask(other, "list_bridges", {}, 2)["result"]["service_clients"]
        return sum(c["waiting"] for c in clients)

    wait_until(lambda: waiting() == 0, timeout=10, what="the hog's calls ended with it")
    other.close()


def test_a_client_waiting_on_absent_actions_leaves_action_slots_to_others(
        processes: Processes) -> None:
    server = processes.python("server", "gripper_action_server.py", "--action", "/grip")
    server.wait_for_output("READY", timeout=30)
    daemon = start_daemon(processes)
    hog, other = RawClient(daemon.port), RawClient(daemon.port)
    goal = {"command": {"position": 0.1, "max_effort": 1.0}}
    try:
        for i in range(32):
            send_command(hog, "send_goal", {"action": f"/absent_{i}", "type": GRIPPER,
                                            "goal": goal, "timeout": 120}, i + 1)
        refused = [reply_to(hog, i) for i in range(9, 33)]
        assert {_error(r) for r in refused} == {(ErrorCode.LIMIT_REACHED, "action")}
        sent = ask(other, "send_goal", {"action": "/grip", "type": GRIPPER, "goal": goal,
                                        "timeout": 20}, 1, timeout=30)
        assert sent["ok"] and sent["result"]["status"] == "accepted", sent
    finally:
        hog.close()
        other.close()


def test_the_hidden_cancel_service_cancels_only_the_callers_own_goal(
        processes: Processes) -> None:
    """cancel_goal answers NOT_FOUND for another client's goal; a call of the action's
    hidden cancel service (action_msgs/srv/CancelGoal) is judged the same way: a zero id
    or a stamp (every goal) is refused, another client's goal id is NOT_FOUND, and the
    goal's owner may cancel it there."""
    server = processes.python("server", "gripper_action_server.py", "--action", "/grip",
                              "--steps", "30", "--period", "0.1")
    server.wait_for_output("READY", timeout=30)
    daemon = start_daemon(processes)
    owner, intruder = RawClient(daemon.port), RawClient(daemon.port)
    goal = {"command": {"position": 0.2, "max_effort": 1.0}}
    service = "/grip/_action/cancel_goal"
    try:
        first = ask(owner, "send_goal", {"action": "/grip", "type": GRIPPER, "goal": goal,
                                         "timeout": 20}, 1, timeout=30)["result"]
        uuid = list(bytes.fromhex(first["goal_id"]))
        every = ask(intruder, "call_service", {"service": service, "type": CANCEL,
                                               "request": {}, "timeout": 10}, 1)
        assert _error(every) == (ErrorCode.FORBIDDEN, "request.goal_info")
        stamped = ask(intruder, "call_service", {"service": service, "type": CANCEL, "request": {
            "goal_info": {"goal_id": {"uuid": uuid}, "stamp": {"sec": 2 ** 30}}}}, 2)
        assert _error(stamped) == (ErrorCode.FORBIDDEN, "request.goal_info")
        theirs = ask(intruder, "call_service", {"service": service, "type": CANCEL, "request": {
            "goal_info": {"goal_id": {"uuid": uuid}}}}, 3)
        assert _error(theirs) == (ErrorCode.NOT_FOUND, "request.goal_info.goal_id")
        also = ask(intruder, "cancel_goal", {"action": "/grip", "goal_id": first["goal_id"]}, 4)
        assert _error(also) == (ErrorCode.NOT_FOUND, "goal_id")
        # The owner's goal ran to its end: nothing above reached its server.
        server.wait_for_output("DONE 0.2", timeout=30)
        assert "CANCELED" not in server.output()
        second = ask(owner, "send_goal", {"action": "/grip", "type": GRIPPER, "goal": goal,
                                          "timeout": 20}, 2, timeout=30)["result"]
        mine = ask(owner, "call_service", {"service": service, "type": CANCEL, "request": {
            "goal_info": {"goal_id": {"uuid": list(bytes.fromhex(second["goal_id"]))}}},
            "timeout": 10}, 3, timeout=20)
        assert mine["ok"] and mine["result"]["response"]["return_code"] == 0, mine
        server.wait_for_output("CANCELED", timeout=30)
    finally:
        owner.close()
        intruder.close()


def test_clients_set_only_the_daemon_parameters_clients_declared(
        processes: Processes) -> None:
    """use_sim_time changes the stamp of everything the daemon publishes: it is the
    operator's (--ros-args -p), on every route a client could take to it."""
    daemon = start_daemon(processes)
    client = RawClient(daemon.port)
    node = "/slicer_bridge"
    sim = {"type": "bool", "value": True}
    try:
        direct = ask(client, "server_set_parameter", {"name": "use_sim_time", "value": sim}, 1)
        assert _error(direct) == (ErrorCode.FORBIDDEN, "name")
        assert ask(client, "create_parameter_client", {"node": node}, 2, timeout=20)["ok"]
        through = ask(client, "set_parameters", {"node": node,
                                                 "values": {"use_sim_time": sim}}, 3)
        assert _error(through) == (ErrorCode.FORBIDDEN, "values")
        called = ask(client, "call_service", {
            "service": f"{node}/set_parameters", "type": "rcl_interfaces/srv/SetParameters",
            "request": {"parameters": [{"name": "use_sim_time",
                                        "value": {"type": 1, "bool_value": True}}]},
            "timeout": 10}, 4)
        assert _error(called) == (ErrorCode.FORBIDDEN, "request.parameters")
        now = ask(client, "server_get_parameters", {"names": ["use_sim_time"]}, 5)
        assert now["result"]["values"]["use_sim_time"] == {"type": "bool", "value": False}
        # What a client declared, clients set, on each route.
        assert ask(client, "server_declare_parameter", {
            "name": "needle", "value": {"type": "double", "value": 1.0}}, 6)["ok"]
        assert ask(client, "server_set_parameter", {
            "name": "needle", "value": {"type": "double", "value": 2.0}}, 7)["ok"]
        assert ask(client, "set_parameters", {"node": node, "values": {
            "needle": {"type": "double", "value": 3.0}}}, 8, timeout=20)["ok"]
        now = ask(client, "server_get_parameters", {"names": ["needle"]}, 9)
        assert now["result"]["values"]["needle"] == {"type": "double", "value": 3.0}
    finally:
        client.close()

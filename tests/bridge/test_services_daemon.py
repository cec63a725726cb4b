"""Services through the real daemon: calls to rclpy peer servers, and services a TCP client
advertises and answers, called by an rclpy peer. Namespaces: relative service names resolve
under the daemon's namespace, absolute ones do not.
"""

from __future__ import annotations

import json
import threading
import time
from typing import Any, Callable, Iterator

import pytest

from protocol import commands as c
from protocol.commands import ErrorCode, Reply
from protocol.messages import Command, Message, RtsCommand
from slicer_client.connection import CommandRefusedError, Connection
from support import Child, Processes, RunningDaemon, scaled, start_daemon, wait_until


@pytest.fixture(scope="module")
def server(module_processes: Processes) -> Child:
    child = module_processes.python("service_server", "service_server.py",
                                    "--slow-seconds", "5")
    child.wait_for_output("READY")
    return child


def refused(call: Callable[[], Any]) -> c.ErrorInfo:
    with pytest.raises(CommandRefusedError) as info:
        call()
    return info.value.error


def response_of(child: Child, timeout: float = 30.0) -> dict[str, Any]:
    line = child.wait_for_output("RESPONSE ", timeout=timeout)
    return json.loads(line[line.index("RESPONSE ") + len("RESPONSE "):])


class Answerer:
    """A client that serves what it advertises: every `service_request` COMMAND is answered
    by `answer(request_dict) -> response dict` (None: never answered), with junk Status
    metadata as 3D Slicer writes it."""

    def __init__(self, daemon: RunningDaemon,
                 answer: Callable[[dict[str, Any]], dict[str, Any] | None]) -> None:
        self.answer = answer
        self.seen: list[dict[str, Any]] = []
        self.lock = threading.Lock()
        self.connection = Connection("127.0.0.1", daemon.port, on_message=self._on_message)

    def _on_message(self, message: Message) -> None:  # receive thread
        body = message.body
        if not isinstance(body, Command) or body.name != c.ServiceRequest.op:
            return
        request = c.ServiceRequest.from_json(body.text)
        with self.lock:
            self.seen.append({"service": request.service, "type": request.type,
                              "request": request.request, "device": message.device_name})
        response = self.answer(request.request)
        if response is None:
            return
        reply = Reply.success(body.name, {"response": response})
        self.connection.send(Message(
            device_name="", body=RtsCommand(command_id=body.command_id, name=body.name,
                                            text=reply.to_json()),
            metadata={"Status": "\x01garbage"}))


@pytest.fixture
def answerer_factory(daemon: RunningDaemon) -> Iterator[Callable[..., Answerer]]:
    made: list[Answerer] = []

    def make(answer: Callable[[dict[str, Any]], dict[str, Any] | None]) -> Answerer:
        made.append(Answerer(daemon, answer))
        return made[-1]

    yield make
    for answerer in made:
        answerer.connection.close()


# ---------------------------------------------------------------------------- call_service


def test_set_bool_round_trip(client: Connection, server: Child) -> None:
    # The first call of the module may wait for a discovery round: a generous timeout.
    result = client.command("call_service", {"service": "/set_enabled",
                                             "type": "std_srvs/srv/SetBool",
                                             "request": {"data": True}, "timeout": 10.0},
                            timeout=15)
    assert result == {"service": "/set_enabled", "type": "std_srvs/srv/SetBool",
                      "response": {"success": True, "message": "/ enabled=True"}}
    assert server.wait_for_output("CALL set_enabled").endswith('{"data": true}')
    # `pkg/Type` spelling and a relative name (the daemon's namespace is /).
    result = client.command("call_service", {"service": "set_enabled", "type": "std_srvs/SetBool",
                                             "request": {"data": False}})
    assert result["response"] == {"success": False, "message": "/ enabled=False"}


def test_trigger_round_trip(client: Connection, server: Child) -> None:
    first = client.command("call_service", {"service": "/trigger", "type": "std_srvs/srv/Trigger"})
    second = client.command("call_service", {"service": "/trigger",
                                             "type": "std_srvs/srv/Trigger", "request": {}})
    assert first["response"]["success"] is True
    number = int(first["response"]["message"].split()[-1])
    assert second["response"] == {"success": True, "message": f"triggered {number + 1}"}


def test_timeout(client: Connection, server: Child) -> None:
    started = time.monotonic()
    error = refused(lambda: client.command("call_service", {
        "service": "/slow", "type": "std_srvs/srv/Trigger", "timeout": 2.5}))
    elapsed = time.monotonic() - started
    assert error.code == ErrorCode.TIMEOUT and error.field == "service", error
    assert "within 2.5 s" in error.message, error  # its own timeout, not the default 4 s
    assert 2.5 <= elapsed < 2.5 + scaled(1.5), elapsed
    server.wait_for_output("CALL slow")
    # The daemon keeps serving while the peer still sleeps.
    result = client.command("call_service", {"service": "/set_enabled",
                                             "type": "std_srvs/srv/SetBool",
                                             "request": {"data": True}})
    assert result["response"]["success"] is True


def test_missing_service_is_unavailable_within_the_timeout(client: Connection) -> None:
    started = time.monotonic()
    error = refused(lambda: client.command("call_service", {
        "service": "/no_such_service", "type": "std_srvs/srv/Trigger", "timeout": 1.0}))
    elapsed = time.monotonic() - started
    assert error.code == ErrorCode.UNAVAILABLE and error.field == "service", error
    assert "no server after 1 s" in error.message, error
    assert elapsed < 1.0 + scaled(0.9), elapsed


def test_bad_request_fields_are_named(client: Connection, server: Child) -> None:
    error = refused(lambda: client.command("call_service", {
        "service": "/set_enabled", "type": "std_srvs/srv/SetBool", "request": {"data": "yes"}}))
    assert (error.code, error.field) == (ErrorCode.WRONG_TYPE, "request.data"), error
    error = refused(lambda: client.command("call_service", {
        "service": "/set_enabled", "type": "std_srvs/srv/SetBool", "request": {"dta": True}}))
    assert error.field == "request.dta", error
    assert "data" in error.message


@pytest.mark.parametrize("kind", ["std_srvs/srv/NoSuchService", "no_such_pkg/srv/Thing"])
def test_unknown_service_type(client: Connection, kind: str) -> None:
    error = refused(lambda: client.command("call_service", {"service": "/x", "type": kind}))
    assert (error.code, error.field) == (ErrorCode.UNKNOWN_ROS_TYPE, "type"), error


# ---------------------------------------------------------------------------- advertise


def test_advertised_service_answered_by_the_client(processes: Processes, client: Connection,
                                                   answerer_factory: Callable[..., Answerer]
                                                   ) -> None:
    answerer = answerer_factory(lambda request: {"success": not request["data"],
                                                 "message": f"slicer saw {request['data']}"})
    result = answerer.connection.command("advertise_service", {
        "service": "/slicer/toggle", "type": "std_srvs/srv/SetBool"})
    assert result == {"kind": "served_service", "service": "/slicer/toggle",
                      "type": "std_srvs/srv/SetBool", "device": "srv:slicer/toggle",
                      "calls": 0, "existed": False}
    caller = processes.python("caller", "service_caller.py", "/slicer/toggle",
                              "std_srvs/srv/SetBool", '{"data": true}')
    assert response_of(caller) == {"success": False, "message": "slicer saw True"}
    assert answerer.seen == [{"service": "/slicer/toggle", "type": "std_srvs/srv/SetBool",
                              "request": {"data": True}, "device": "srv:slicer/toggle"}]
    # Listed, and visible in the ROS graph.
    services = {s["service"]: s for s in client.command("list_services")["services"]}
    assert services["/slicer/toggle"]["types"] == ["std_srvs/srv/SetBool"]
    bridges = client.command("list_bridges")["bridges"]
    assert {"kind": "served_service", "service": "/slicer/toggle",
            "type": "std_srvs/srv/SetBool", "device": "srv:slicer/toggle",
            "calls": 1, "clients": 1, "stays": False} in bridges
    # Another client cannot take it over; the owner advertising again is idempotent.
    error = refused(lambda: client.command("advertise_service", {
        "service": "/slicer/toggle", "type": "std_srvs/srv/SetBool"}))
    assert error.code == ErrorCode.ALREADY_EXISTS
    assert answerer.connection.command("advertise_service", {
        "service": "/slicer/toggle", "type": "std_srvs/srv/SetBool"})["existed"] is True
    assert answerer.connection.command("unadvertise_service",
                                       {"service": "/slicer/toggle"}) == {
        "service": "/slicer/toggle", "device": "srv:slicer/toggle"}
    wait_until(lambda: "/slicer/toggle" not in {
        s["service"] for s in client.command("list_services")["services"]}, 10,
        "the unadvertised service to leave the graph")


def test_a_service_advertised_again_right_after_its_withdrawal_answers_as_the_new_one(
        processes: Processes, answerer_factory: Callable[..., Answerer]) -> None:
    """A withdrawn service lingers a second (its last answers must reach their callers);
    advertised again meanwhile (a client that reconnects), the old one goes at once, so
    no call gets its default answer instead of the new server's."""
    old = answerer_factory(lambda request: {"success": False, "message": "old"})
    new = answerer_factory(lambda request: {"success": True, "message": "new"})
    args = {"service": "/slicer/again", "type": "std_srvs/srv/Trigger"}
    old.connection.command("advertise_service", args)
    old.connection.command("unadvertise_service", {"service": "/slicer/again"})
    assert new.connection.command("advertise_service", args)["existed"] is False
    for _ in range(3):
        caller = processes.python("caller", "service_caller.py", "/slicer/again",
                                  "std_srvs/srv/Trigger", "{}")
        assert response_of(caller) == {"success": True, "message": "new"}
    assert old.seen == [] and len(new.seen) == 3


def test_concurrent_calls_of_an_advertised_trigger(processes: Processes,
                                                   answerer_factory: Callable[..., Answerer]
                                                   ) -> None:
    counter = iter(range(1, 100))
    answerer = answerer_factory(lambda request: {"success": True,
                                                 "message": f"answer {next(counter)}"})
    answerer.connection.command("advertise_service", {"service": "/slicer/reset",
                                                      "type": "std_srvs/Trigger"})
    callers = [processes.python(f"caller{i}", "service_caller.py", "/slicer/reset",
                                "std_srvs/srv/Trigger", "{}") for i in range(2)]
    messages = sorted(response_of(caller)["message"] for caller in callers)
    assert messages == ["answer 1", "answer 2"]


def test_unanswered_call_gets_a_default_response(processes: Processes, daemon: RunningDaemon,
                                                 answerer_factory: Callable[..., Answerer]
                                                 ) -> None:
    silent = answerer_factory(lambda request: None)
    silent.connection.command("advertise_service", {"service": "/slicer/silent",
                                                    "type": "std_srvs/srv/Trigger"})
    started = time.monotonic()
    caller = processes.python("caller", "service_caller.py", "/slicer/silent",
                              "std_srvs/srv/Trigger", "{}")
    assert response_of(caller) == {"success": False, "message": ""}
    assert time.monotonic() - started >= 4.0  # the daemon's answer timeout
    assert len(silent.seen) == 1
    daemon.child.wait_for_output("did not answer a call of /slicer/silent")


def test_refusing_client_gives_a_default_response(processes: Processes,
                                                  daemon: RunningDaemon) -> None:
    def refuse(message: Message) -> None:
        body = message.body
        if isinstance(body, Command) and body.name == c.ServiceRequest.op:
            reply = Reply.failure(body.name, ErrorCode.ROS_ERROR, "not now")
            refusing.send(Message(device_name="", body=RtsCommand(
                command_id=body.command_id, name=body.name, text=reply.to_json()),
                metadata={"Status": "SUCCESS"}))  # Status says success: the JSON wins

    refusing = Connection("127.0.0.1", daemon.port, on_message=refuse)
    try:
        refusing.command("advertise_service", {"service": "/slicer/refuse",
                                               "type": "std_srvs/srv/SetBool"})
        caller = processes.python("caller", "service_caller.py", "/slicer/refuse",
                                  "std_srvs/srv/SetBool", '{"data": true}')
        assert response_of(caller) == {"success": False, "message": ""}
        daemon.child.wait_for_output("not now")
    finally:
        refusing.close()


def test_disconnect_unadvertises(processes: Processes, daemon: RunningDaemon,
                                 client: Connection) -> None:
    first = Connection("127.0.0.1", daemon.port)
    first.command("advertise_service", {"service": "/slicer/bye", "type": "std_srvs/Trigger"})
    assert "/slicer/bye" in {s["service"] for s in client.command("list_services")["services"]}
    first.close()
    wait_until(lambda: "/slicer/bye" not in {
        s["service"] for s in client.command("list_services")["services"]}, 10,
        "the service of a disconnected client to go")
    # Free again for a new client.
    second = Connection("127.0.0.1", daemon.port)
    try:
        assert second.command("advertise_service", {"service": "/slicer/bye",
                                                    "type": "std_srvs/Trigger"})["existed"] is False
    finally:
        second.close()


def test_advertise_errors(client: Connection, server: Child) -> None:
    error = refused(lambda: client.command("advertise_service", {
        "service": "/slicer/x", "type": "std_srvs/srv/Nope"}))
    assert (error.code, error.field) == (ErrorCode.UNKNOWN_ROS_TYPE, "type")
    error = refused(lambda: client.command("advertise_service", {
        "service": "/set_enabled", "type": "std_srvs/srv/SetBool"}))
    assert (error.code, error.field) == (ErrorCode.ALREADY_EXISTS, "service"), error
    error = refused(lambda: client.command("unadvertise_service", {"service": "/slicer/none"}))
    assert error.code == ErrorCode.NOT_FOUND


# ---------------------------------------------------------------------------- namespaces


def test_namespaces(processes: Processes) -> None:
    """Two robots' servers side by side; the daemon runs in /PSM1."""
    servers = [processes.python(f"server_{ns}", "service_server.py", "--namespace", ns)
               for ns in ("PSM1", "PSM2")]
    for child in servers:
        child.wait_for_output("READY")
    daemon = start_daemon(processes, "--namespace", "/PSM1")
    connection = daemon.connect()
    answering: Connection | None = None
    answering_conn: list[Connection] = []
    try:
        # A fresh daemon may need a discovery round (seconds) to see the servers.
        relative = connection.command("call_service", {
            "service": "set_enabled", "type": "std_srvs/srv/SetBool", "request": {"data": True},
            "timeout": 10.0}, timeout=15)
        assert relative["service"] == "/PSM1/set_enabled"
        assert relative["response"]["message"] == "/PSM1 enabled=True"
        absolute = connection.command("call_service", {
            "service": "/PSM2/set_enabled", "type": "std_srvs/srv/SetBool",
            "request": {"data": True}, "timeout": 10.0}, timeout=15)
        assert absolute["response"]["message"] == "/PSM2 enabled=True"
        for child in servers:
            child.wait_for_output("CALL set_enabled")
            assert child.output().count("CALL set_enabled") == 1

        def answer(message: Message) -> None:
            body = message.body
            if isinstance(body, Command) and body.name == c.ServiceRequest.op:
                request = c.ServiceRequest.from_json(body.text)
                reply = Reply.success(body.name, {"response": {
                    "success": True, "message": f"answered {request.service}"}})
                answering_conn[0].send(Message(device_name="", body=RtsCommand(
                    command_id=body.command_id, name=body.name, text=reply.to_json())))

        answering = Connection("127.0.0.1", daemon.port, on_message=answer)
        answering_conn.append(answering)
        advertised = answering.command("advertise_service", {"service": "reset",
                                                             "type": "std_srvs/srv/Trigger"})
        assert advertised["service"] == "/PSM1/reset"
        caller = processes.python("caller", "service_caller.py", "/PSM1/reset",
                                  "std_srvs/srv/Trigger", "{}")
        assert response_of(caller) == {"success": True, "message": "answered /PSM1/reset"}
    finally:
        if answering is not None:
            answering.close()
        connection.close()

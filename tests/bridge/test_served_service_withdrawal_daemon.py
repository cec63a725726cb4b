"""A service a client serves, withdrawn while a ROS caller waits on it, and a daemon that
stops while a client still serves one: a real daemon, a real rclpy caller in another process
(tests/peers/service_caller.py), a real TCP client that advertises and never answers.

The daemon stops cleanly with services still served. The waiting caller gets the default
response at once (not after the answer timeout: the withdrawn service lingers a second, so
rclpy sends that response before the service is destroyed) and the service leaves the ROS
graph."""

from __future__ import annotations

import json
import threading
from typing import Any


from protocol import commands as c
from protocol.messages import Command, Message
from slicer_client.connection import Connection
from support import Processes, assert_clean_exit, start_daemon, wait_until


class SilentServer:
    """A client that advertises services and never answers the calls it is sent."""

    def __init__(self, port: int) -> None:
        self.seen: list[str] = []
        self.lock = threading.Lock()
        self.connection = Connection("127.0.0.1", port, on_message=self._on_message)

    def _on_message(self, message: Message) -> None:  # receive thread
        body = message.body
        if isinstance(body, Command) and body.name == c.ServiceRequest.op:
            with self.lock:
                self.seen.append(c.ServiceRequest.from_json(body.text).service)


def response_of(line: str) -> dict[str, Any]:
    return dict(json.loads(line[line.index("RESPONSE ") + len("RESPONSE "):]))


def test_the_daemon_stops_while_a_client_still_serves_a_service(processes: Processes) -> None:
    daemon = start_daemon(processes)
    server = SilentServer(daemon.port)
    try:
        server.connection.command("advertise_service", {"service": "/slicer/kept",
                                                        "type": "std_srvs/srv/Trigger"})
        assert "/slicer/kept" in {
            s["service"] for s in server.connection.command("list_services")["services"]}
        assert_clean_exit(daemon)
    finally:
        server.connection.close()


def test_a_service_withdrawn_during_a_call_answers_it_and_goes(processes: Processes) -> None:
    daemon = start_daemon(processes)
    server = SilentServer(daemon.port)
    try:
        server.connection.command("advertise_service", {"service": "/slicer/held",
                                                        "type": "std_srvs/srv/Trigger"})
        caller = processes.python("caller", "service_caller.py", "/slicer/held",
                                  "std_srvs/srv/Trigger", "{}", "--timeout", "15")
        wait_until(lambda: server.seen == ["/slicer/held"], 20, "the call sent to the client")
        withdrawn = server.connection.command("unadvertise_service",
                                              {"service": "/slicer/held"})
        assert withdrawn["service"] == "/slicer/held"
        assert response_of(caller.wait_for_output("RESPONSE ")) == {"success": False,
                                                                   "message": ""}
        # Answered by the withdrawal, not by the daemon's answer timeout.
        assert "did not answer a call" not in daemon.child.output()
        wait_until(lambda: "/slicer/held" not in {
            s["service"] for s in server.connection.command("list_services")["services"]},
            20, "the withdrawn service to leave the ROS graph")
        assert_clean_exit(daemon)
    finally:
        server.connection.close()

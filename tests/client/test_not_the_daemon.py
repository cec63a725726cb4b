"""Connecting to something that is not the daemon says what it is, at once."""

from __future__ import annotations

import socket
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Iterator

import pytest

import slicer_client
from protocol.framing import encode
from protocol.messages import Message, Status
from slicer_client.connection import Connection


class _Quiet(BaseHTTPRequestHandler):
    def log_message(self, *args: object) -> None:
        pass


@pytest.fixture
def http_port() -> Iterator[int]:
    server = ThreadingHTTPServer(("127.0.0.1", 0), _Quiet)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield server.server_address[1]
    server.shutdown()
    server.server_close()
    thread.join(timeout=5)


class _OneShotServer:
    """A TCP server that sends `greeting` to each client, then reads and ignores."""

    def __init__(self, greeting: bytes) -> None:
        self._listener = socket.create_server(("127.0.0.1", 0))
        self.port = self._listener.getsockname()[1]
        self._greeting = greeting
        self._stop = threading.Event()
        self._clients: list[socket.socket] = []
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        self._listener.settimeout(0.1)
        while not self._stop.is_set():
            try:
                client, _ = self._listener.accept()
            except socket.timeout:
                continue
            self._clients.append(client)
            if self._greeting:
                client.sendall(self._greeting)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        for client in self._clients:
            client.close()
        self._listener.close()


def test_an_http_server_is_named_not_taken_for_a_broken_daemon(http_port: int) -> None:
    with pytest.raises(slicer_client.NotTheDaemonError) as caught:
        slicer_client.connect("127.0.0.1", http_port, reconnect=True)
    message = str(caught.value)
    assert f"127.0.0.1:{http_port} is not the slicer-ros2-bridge daemon" in message
    # Python's server answers our binary request line as HTTP/0.9: a bare HTML error page.
    assert "an HTTP server answers there (its first bytes: b'<!DOCTYPE HTML>" in message
    assert "header version" not in message  # the framing detail is not the user's problem
    assert isinstance(caught.value, slicer_client.DaemonUnreachableError)


def test_3d_slicers_own_server_is_recognised_at_once() -> None:
    # What 3D Slicer's OpenIGTLinkIF sends when a client connects (SlicerOpenIGTLink,
    # vtkMRMLIGTLConnectorNode::ProcessIOConnectorEvents): a header-v2 STATUS, device name
    # "", with one metadata element "dummy".
    greeting = encode(Message(device_name="", body=Status(), metadata={"dummy": "dummy"}),
                      header_version=2)
    server = _OneShotServer(greeting)
    try:
        start = time.monotonic()
        with pytest.raises(slicer_client.NotTheDaemonError) as caught:
            slicer_client.connect("127.0.0.1", server.port)
        assert "3D Slicer's own OpenIGTLinkIF server answers there" in str(caught.value)
        # Recognised from its greeting, not after the 10 s hello timeout.
        assert time.monotonic() - start < 10
    finally:
        server.close()


def test_a_silent_peer_gets_a_timeout_that_says_what_may_be_there() -> None:
    server = _OneShotServer(b"")
    try:
        connection = Connection("127.0.0.1", server.port)
        try:
            with pytest.raises(slicer_client.CommandTimeoutError) as caught:
                connection.command("hello", timeout=0.5)
            message = str(caught.value)
            assert "accepted the connection but has answered no command" in message
            assert "3D Slicer's own listens on 18944 too" in message
        finally:
            connection.close()
    finally:
        server.close()

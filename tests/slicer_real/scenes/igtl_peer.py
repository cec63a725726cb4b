"""The daemon's end of an OpenIGTLink link, in the scene's process, for what a real daemon
will not do on cue (go silent, leave a command unanswered, count each message it is sent,
drop the connection): a real TCP server speaking the project's codec (protocol.framing),
which Slicer's own connector connects to. It answers no command."""

from __future__ import annotations

import socket
import threading
from typing import Optional

from protocol import framing
from protocol.messages import Message


class IgtlPeer:
    """Accepts one connection at a time on 127.0.0.1 (`port`); keeps what it receives."""

    def __init__(self) -> None:
        self._server = socket.create_server(("127.0.0.1", 0))
        self.port: int = self._server.getsockname()[1]
        self.received: list[Message] = []
        self.connections = 0  # accepted so far
        self._conn: Optional[socket.socket] = None
        self._lock = threading.Lock()
        self.resume()

    def resume(self) -> None:
        """Listen (again, on the same port, after `drop`)."""
        if self._server.fileno() < 0:
            self._server = socket.create_server(("127.0.0.1", self.port))
        threading.Thread(target=self._serve, args=(self._server,), name="igtl-peer",
                         daemon=True).start()

    def _serve(self, server: socket.socket) -> None:
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return  # closed
            self._conn = conn
            self.connections += 1
            decoder = framing.Decoder()
            try:
                while data := conn.recv(1 << 16):
                    decoder.feed(data)
                    self.received.extend(decoder.messages())
            except OSError:
                pass
            conn.close()

    def send(self, message: Message) -> None:
        conn = self._conn
        assert conn is not None, "nothing connected to the peer"
        with self._lock:
            conn.sendall(framing.encode(message, header_version=2))

    def of_type(self, type_name: str, device: str = "") -> list[Message]:
        return [m for m in list(self.received)
                if m.type_name == type_name and (not device or m.device_name == device)]

    def kick(self) -> None:
        """Close the connection and go on listening (the connector reconnects at once)."""
        conn = self._conn
        if conn is not None:
            conn.shutdown(socket.SHUT_RDWR)

    def drop(self) -> None:
        """Close the connection and stop listening until `resume` (the connector retries)."""
        self._server.close()
        conn = self._conn
        if conn is not None:
            conn.shutdown(socket.SHUT_RDWR)

    def close(self) -> None:
        self._server.close()
        if self._conn is not None:
            self._conn.close()

"""A raw OpenIGTLink client for the benchmarks: one socket, a reader thread that takes
everything the daemon sends (so a client that asked for large data never holds the daemon
back), and COMMANDs with their replies. Only `protocol` is used, never slicer_client, so a
figure does not depend on the client library's own costs."""

from __future__ import annotations

import itertools
import json
import socket
import struct
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Optional

from protocol.framing import Decoder, encode
from protocol.messages import Command, Message, Status

__all__ = ["CommandFailed", "RawSession", "Received"]

_HEADER = struct.Struct(">H12s20sQQQ")


class CommandFailed(Exception):
    """A reply with ``ok: false``; ``error`` is its error object."""

    def __init__(self, op: str, error: dict[str, Any]) -> None:
        super().__init__(f"{op}: {error.get('name')} {error.get('message')}")
        self.error = error


@dataclass
class Received:
    """What the reader thread has taken: counts per message type, bytes, STATUS texts."""

    messages: dict[str, int] = field(default_factory=dict)
    bytes: int = 0
    statuses: list[tuple[str, int, str]] = field(default_factory=list)  # device, code, text
    stamps: dict[str, int] = field(default_factory=dict)  # device -> its last IGTL time stamp


class RawSession:
    """``RawSession(port)``: connected, header v2 announced, the reader running."""

    def __init__(self, port: int, *, name: str = "bench") -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=30)
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.sock.sendall(encode(Message("", Status(text=name)), header_version=2))
        self.received = Received()
        self.closed = threading.Event()
        self._ids = itertools.count(1)
        self._replies: dict[int, dict[str, Any]] = {}
        self._cond = threading.Condition()
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def send(self, data: bytes) -> None:
        self.sock.sendall(data)

    def send_command(self, op: str, arguments: dict[str, Any]) -> int:
        command_id = next(self._ids)
        self.sock.sendall(encode(Message("bench", Command(
            command_id=command_id, name=op, text=json.dumps(arguments))), header_version=2))
        return command_id

    def reply(self, command_id: int, timeout: float = 60.0) -> Optional[dict[str, Any]]:
        """The reply envelope, or None if it did not come within ``timeout``."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while command_id not in self._replies:
                left = deadline - time.monotonic()
                if left <= 0 or self.closed.is_set():
                    return None
                self._cond.wait(left)
            return self._replies.pop(command_id)

    def command(self, op: str, arguments: Optional[dict[str, Any]] = None,
                timeout: float = 60.0) -> dict[str, Any]:
        """The result; `CommandFailed` for a refusal, TimeoutError without a reply."""
        reply = self.reply(self.send_command(op, arguments or {}), timeout)
        if reply is None:
            raise TimeoutError(f"{op}: no reply within {timeout} s")
        if not reply["ok"]:
            raise CommandFailed(op, reply["error"])
        return dict(reply["result"])

    def _read(self) -> None:
        # Headers only, except for replies and STATUS: a client that receives 50 MB models
        # must not be slower than the daemon it measures.
        buffer = bytearray()
        try:
            while True:
                data = self.sock.recv(1 << 20)
                if not data:
                    break
                self.received.bytes += len(data)
                buffer += data
                offset = 0
                while len(buffer) - offset >= _HEADER.size:
                    _, type_raw, device, stamp, body_size, _ = _HEADER.unpack_from(buffer,
                                                                                    offset)
                    end = offset + _HEADER.size + body_size
                    if end > len(buffer):
                        break
                    kind = type_raw.rstrip(b"\0").decode("ascii", "replace")
                    self.received.messages[kind] = self.received.messages.get(kind, 0) + 1
                    self.received.stamps[device.rstrip(b"\0").decode("utf-8", "replace")] = stamp
                    if kind in ("RTS_COMMAND", "STATUS"):
                        decoder = Decoder(max_body_size=body_size)
                        decoder.feed(bytes(buffer[offset:end]))
                        message = decoder.next_message()
                        if message is not None:
                            self._take(message)
                    offset = end
                del buffer[:offset]
        except OSError:
            pass
        finally:
            self.closed.set()
            with self._cond:
                self._cond.notify_all()

    def _take(self, message: Message) -> None:
        kind = message.type_name
        if kind == "RTS_COMMAND":
            with self._cond:
                self._replies[message.body.command_id] = json.loads(message.body.text)
                self._cond.notify_all()
        elif kind == "STATUS":
            body = message.body
            self.received.statuses.append((message.device_name, int(body.code), body.text))

    def close(self) -> None:
        try:
            self.sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self.sock.close()
        self._thread.join(5)

"""Helpers of the hardening tests: raw sockets, malformed wire bytes, /proc figures."""

from __future__ import annotations

import json
import os
import socket
import struct
import subprocess
import time
from pathlib import Path
from typing import Optional

from protocol.crc64 import crc64
from protocol.errors import MessageError
from protocol.framing import Decoder, encode
from protocol.messages import Command, Message, Status, String, Transform
from support import PEERS, Child, Processes, scaled

import numpy as np
import pytest

HEADER = struct.Struct(">H12s20sQQQ")


def header(type_name: str, device: str, body_size: int, crc: int, version: int = 1) -> bytes:
    return HEADER.pack(version, type_name.encode(), device.encode(), 0, body_size, crc)


def raw_message(type_name: str, body: bytes, *, device: str = "fuzz", version: int = 1,
                crc: Optional[int] = None) -> bytes:
    """Header + body with the right CRC unless one is given (the body may be nonsense)."""
    return header(type_name, device, len(body), crc64(body) if crc is None else crc,
                  version) + body


def command_bytes(op: str, text: bytes, command_id: int = 7) -> bytes:
    """A COMMAND (header v2) whose text is arbitrary bytes, ENCODING 106 (UTF-8)."""
    content = struct.pack(">I128sHI", command_id, op.encode(), 106, len(text)) + text
    ext = struct.pack(">HHII", 12, 2, 0, 0)
    return raw_message("COMMAND", ext + content + b"\x00\x00", device="command", version=2)


def transform_bytes(values: list[float], device: str = "fuzz") -> bytes:
    return raw_message("TRANSFORM", struct.pack(">12f", *values), device=device)


def valid_messages() -> list[bytes]:
    """One valid message of several types, as wire bytes (a seed for fuzzing)."""
    matrix = np.eye(4)
    messages = [
        Message(device_name="t", body=Transform(matrix=matrix)),
        Message(device_name="s", body=String(text="hello")),
        Message(device_name="st", body=Status(text="ok")),
        Message(device_name="command", body=Command(command_id=1, name="hello", text="{}"),
                metadata={"client": "fuzz"}),
    ]
    out = [encode(m, header_version=1) for m in messages[:3]]
    out += [encode(m, header_version=2) for m in messages]
    return out


def malformed_inputs() -> dict[str, bytes]:
    """Every kind of bad input the daemon must survive, as wire bytes. Those that break
    framing are last-in-stream by nature (the daemon closes that connection)."""
    nan, inf = float("nan"), float("inf")
    identity = [1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0]
    good = raw_message("STRING", struct.pack(">HH", 3, 2) + b"hi")
    return {
        "wrong CRC": good[:-1] + b"\x00" if good[-1:] != b"\x00" else good[:-1] + b"\x01",
        "bad CRC field": raw_message("STRING", struct.pack(">HH", 3, 2) + b"hi", crc=12345),
        "unknown type": raw_message("NOSUCHTYPE", b"\x01\x02\x03"),
        "empty type": raw_message("", b""),
        "STRING length over body": raw_message("STRING", struct.pack(">HH", 3, 500) + b"hi"),
        "STRING invalid UTF-8": raw_message("STRING", struct.pack(">HH", 106, 4)
                                            + b"\xff\xfe\xc3\x28"),
        "TRANSFORM short": raw_message("TRANSFORM", b"\x00" * 47),
        "TRANSFORM NaN": transform_bytes([nan] * 12),
        "TRANSFORM inf": transform_bytes(identity[:9] + [inf, -inf, 0.0]),
        "IMAGE size over buffer": raw_message("IMAGE", struct.pack(
            ">HBBBBHHH12f3H3H", 1, 1, 3, 2, 1, 4000, 4000, 4000, *([1.0] * 12),
            0, 0, 0, 4000, 4000, 4000) + b"\x00" * 100),
        "IMAGE header only": raw_message("IMAGE", b"\x00" * 10),
        "POLYDATA counts lie": raw_message("POLYDATA", struct.pack(">10I", *([0xFFFFFFFF] * 10))),
        "POINT ragged": raw_message("POINT", b"\x00" * 137),
        "STATUS short": raw_message("STATUS", b"\x00\x01"),
        "v2 ext header sizes inconsistent": raw_message(
            "STRING", struct.pack(">HHII", 12, 60000, 70000, 0) + b"\x00\x03\x00\x02hi",
            version=2),
        "v2 ext header size too small": raw_message(
            "STRING", struct.pack(">HHII", 4, 0, 0, 0) + b"x", version=2),
        "v2 body shorter than ext header": raw_message("STRING", b"\x00\x0c", version=2),
        "v2 metadata count lies": raw_message(
            "STRING", struct.pack(">HHII", 12, 2, 100, 0) + struct.pack(">HH", 3, 2) + b"hi"
            + b"\x00\x09", version=2),
        "COMMAND JSON garbage": command_bytes("create_subscriber", b"{not json"),
        "COMMAND invalid UTF-8": command_bytes("hello", b"{\"client\": \"\xff\xfe\"}"),
        "COMMAND deeply nested": command_bytes("publish", b"{\"topic\":\"/x\",\"value\":"
                                               + b"[" * 100_000 + b"]" * 100_000 + b"}"),
        "COMMAND unknown op": command_bytes("rm_rf", b"{}"),
        "COMMAND NaN": command_bytes("broadcast_transform", b"{\"parent\":\"a\",\"child\":"
                                     b"\"b\",\"matrix\":[[NaN,0,0,0],[0,1,0,0],[0,0,1,0],"
                                     b"[0,0,0,1]]}"),
        "COMMAND huge numbers": command_bytes("create_subscriber", b"{\"topic\":\"/x\","
                                              b"\"type\":\"String\",\"rate_hz\":1e999}"),
        "COMMAND truncated body": raw_message("COMMAND", b"\x00\x00\x00\x01abc", version=1),
        "GET_ unknown": raw_message("GET_NOTHING", b""),
        "RTS_COMMAND garbage": raw_message("RTS_COMMAND", b"\x00" * 20),
    }


def framing_breakers() -> dict[str, bytes]:
    """Inputs after which the stream cannot continue: the daemon closes the connection."""
    return {
        "BODY_SIZE 2^63": header("STRING", "x", 1 << 63, 0),
        "BODY_SIZE 2^64-1": header("STRING", "x", (1 << 64) - 1, 0),
        "header version 7": header("STRING", "x", 4, 0, version=7),
        "header version 0": header("STRING", "x", 4, 0, version=0),
    }


def read_until_closed(sock: socket.socket, timeout: float = 10.0) -> list[Message]:
    """Every message the daemon sends on `sock` until it closes the connection
    (``timeout`` scaled)."""
    timeout = scaled(timeout)
    decoder = Decoder()
    messages: list[Message] = []
    deadline = time.monotonic() + timeout
    while True:
        sock.settimeout(max(0.01, deadline - time.monotonic()))
        try:
            data = sock.recv(65536)
        except (ConnectionResetError, BrokenPipeError):
            return messages
        except socket.timeout:
            raise AssertionError(f"the daemon did not close the connection within {timeout} s;"
                                 f" got {[m.type_name for m in messages]}") from None
        if not data:
            return messages
        decoder.feed(data)
        messages.extend(decoder.messages())


def fd_count(pid: int) -> int:
    return len(os.listdir(f"/proc/{pid}/fd"))


def rss_bytes(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024
    raise AssertionError("no VmRSS")


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class RawClient:
    """A bare socket to the daemon: sends any bytes, reads whole messages when asked."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=5)
        self.decoder = Decoder()
        self.received: list[Message] = []

    def send(self, data: bytes) -> None:
        self.sock.sendall(data)

    def read_until(self, predicate, timeout: float = 10.0) -> Message:
        """Read until a message satisfies `predicate`; return it (``timeout`` scaled)."""
        timeout = scaled(timeout)
        deadline = time.monotonic() + timeout
        while True:
            for index, message in enumerate(self.received):
                if predicate(message):
                    del self.received[:index + 1]
                    return message
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise AssertionError(f"no matching message within {timeout} s; got "
                                     f"{[(m.type_name, m.device_name) for m in self.received]}")
            self.sock.settimeout(remaining)
            data = self.sock.recv(1 << 16)
            if not data:
                raise AssertionError("the daemon closed the connection")
            self.decoder.feed(data)
            while True:
                try:
                    message = self.decoder.next_message()
                except MessageError:  # pragma: no cover - the daemon sends valid messages
                    raise
                if message is None:
                    break
                self.received.append(message)

    def close(self) -> None:
        self.sock.close()


def is_reply(command_id: int):
    def matches(message: Message) -> bool:
        return message.type_name == "RTS_COMMAND" and message.body.command_id == command_id
    return matches


def send_command(client: RawClient, op: str, arguments: dict, command_id: int) -> None:
    """Send one COMMAND (JSON ``arguments``) without waiting for its reply."""
    client.send(command_bytes(op, json.dumps(arguments).encode(), command_id))


def reply_to(client: RawClient, command_id: int, timeout: float = 10.0) -> dict:
    """The reply envelope ({"ok", "result" | "error"}) of command ``command_id`` (what
    came before it is dropped: read replies in the order they come)."""
    return json.loads(client.read_until(is_reply(command_id), timeout).body.text)


def ask(client: RawClient, op: str, arguments: dict, command_id: int,
        timeout: float = 10.0) -> dict:
    """Send one COMMAND and return its reply envelope (``timeout`` scaled)."""
    send_command(client, op, arguments, command_id)
    return reply_to(client, command_id, timeout)


class MarkerPeer:
    """tests/peers/marker_publisher.py and its control file: `send` publishes once what the
    document holds (markers, "statics" on /tf_static, ...) and waits until it has."""

    def __init__(self, processes: Processes, folder: Path) -> None:
        self.control = folder / "control.json"
        self.seq = 0
        self.child: Child = processes.python("markers", str(PEERS / "marker_publisher.py"),
                                             str(self.control))
        self.child.wait_for_output("READY", timeout=30)

    def send(self, **doc: object) -> None:
        self.seq += 1
        tmp = self.control.with_suffix(".tmp")
        tmp.write_text(json.dumps({"seq": self.seq, **doc}))
        os.replace(tmp, self.control)
        self.child.wait_for_output(f"APPLIED {self.seq}", timeout=30)


def make_certificate(folder: Path, *addresses: str) -> tuple[Path, Path]:
    """A self-signed certificate (and its key, mode 0600 as openssl writes it) for
    ``localhost`` and these IP addresses (127.0.0.1 always): the TLS port's test chain."""
    cert, key = folder / "cert.pem", folder / "key.pem"
    names = ",".join(f"IP:{address}" for address in ("127.0.0.1", *addresses))
    made = subprocess.run(["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes",
                           "-keyout", str(key), "-out", str(cert), "-days", "2",
                           "-subj", "/CN=localhost", "-addext",
                           f"subjectAltName={names},DNS:localhost"],
                          capture_output=True, text=True, timeout=60)
    if made.returncode != 0:
        pytest.skip(f"openssl could not make a test certificate: {made.stderr[-300:]}")
    return cert, key

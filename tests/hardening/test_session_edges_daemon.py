"""One connection's edges, against a real daemon over raw TCP: streaming-control messages
a client may send, GET_ queries answered with a device's value, a heartbeat asked for twice,
a frame whose deadline grows once its header tells its body's size, and a large body that
fails its CRC once decoded off the loop."""

from __future__ import annotations

import json
import socket
import struct
import time
from typing import Iterator

import numpy as np
import pytest

from hardening_tools import (RawClient, ask, command_bytes, header, raw_message,
                             read_until_closed, reply_to, send_command)
from protocol.liveness import HEARTBEAT_DEVICE
from protocol.messages import StatusCode, String
from support import Processes, RunningDaemon, assert_clean_exit, start_daemon

FRAME_DEADLINE_S = 3.0


@pytest.fixture(scope="module")
def daemon(module_processes: Processes) -> Iterator[RunningDaemon]:
    running = start_daemon(module_processes, "--frame-deadline", str(FRAME_DEADLINE_S))
    yield running
    assert_clean_exit(running)


@pytest.fixture
def raw(daemon: RunningDaemon) -> Iterator[RawClient]:
    client = RawClient(daemon.port)
    yield client
    client.close()


def test_streaming_control_messages_are_taken_silently(raw: RawClient) -> None:
    """STT_/STP_/RTS_ messages (OpenIGTLink's streaming control, replies to queries the
    daemon never makes) are taken without a STATUS; the connection goes on."""
    raw.send(raw_message("STT_TDATA", struct.pack(">I12s", 50, b"")) +
             raw_message("STP_TDATA", b"") + raw_message("RTS_TDATA", b"\x00"))
    reply = ask(raw, "hello", {}, 1)
    assert reply["ok"] is True
    assert not [m for m in raw.received if m.type_name == "STATUS"], raw.received


def test_get_string_returns_a_device_s_value(raw: RawClient) -> None:
    send_command(raw, "create_marker_subscriber", {"topic": "/session_edges_markers",
                                                   "type": "Marker", "fixed_frame": "world"}, 1)
    # The topic's index comes before the reply (read_until drops what precedes a match).
    index = raw.read_until(lambda m: m.device_name.startswith("mks:"))
    device = index.device_name
    assert reply_to(raw, 1)["result"]["device"] == device
    assert json.loads(index.body.text)["markers"] == 0
    raw.send(raw_message("GET_STRING", b"", device=device))
    answer = raw.read_until(lambda m: m.device_name == device and m.type_name == "STRING")
    assert isinstance(answer.body, String) and answer.body.text == index.body.text
    # Every STRING device: asked with an empty name.
    raw.send(raw_message("GET_STRING", b"", device=""))
    assert raw.read_until(lambda m: m.device_name == device).body.text == index.body.text
    ask(raw, "remove_marker_subscriber", {"topic": "/session_edges_markers"}, 2)


def test_a_heartbeat_asked_for_again_replaces_the_first(raw: RawClient) -> None:
    assert ask(raw, "hello", {"heartbeat": 30.0}, 1)["result"]["heartbeat"] == 30.0
    assert ask(raw, "hello", {"heartbeat": 0.2}, 2)["result"]["heartbeat"] == 0.2
    beats = [raw.read_until(lambda m: m.device_name == HEARTBEAT_DEVICE) for _ in range(3)]
    assert all(b.type_name == "STATUS" and b.body.code == StatusCode.OK for b in beats)
    stamps = [b.message_id for b in beats]
    assert stamps == sorted(stamps)


def test_the_frame_deadline_grows_with_the_body_its_header_announces(
        daemon: RunningDaemon) -> None:
    """The first bytes of a header start a deadline of --frame-deadline; once the header is
    whole the deadline grows by the body's share (1 s per 8 MiB). The client is told the
    grown one when it runs out."""
    body_size = 8 * 1024 * 1024
    with socket.create_connection(("127.0.0.1", daemon.port)) as sock:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        head = header("STRING", "slow", body_size, 0)
        sock.sendall(head[:10])
        # A separate segment (the daemon reads the header's start first); well within the
        # deadline of the first one.
        time.sleep(0.2)
        sock.sendall(head[10:] + b"\x00" * 100)
        started = time.monotonic()
        said = read_until_closed(sock, timeout=FRAME_DEADLINE_S + 10)
        waited = time.monotonic() - started
    (status,) = [m for m in said if m.type_name == "STATUS"]
    assert status.body.code == StatusCode.TIME_OUT
    assert f"within {FRAME_DEADLINE_S + 1.0:.1f} s" in status.body.text, status.body.text
    assert waited > FRAME_DEADLINE_S  # not the header's own deadline alone


def test_a_large_body_failing_its_crc_off_the_loop_is_refused(raw: RawClient) -> None:
    """A body over the heavy threshold is decoded off the loop; a CRC that does not match
    is said in a STATUS naming the device, and the connection goes on."""
    device = ask(raw, "create_publisher", {"topic": "/session_edges_mesh",
                                           "type": "shape_msgs/msg/Mesh"}, 1)["result"]["device"]
    body = struct.pack(">10I", 3, 0, 0, 0, 0, 0, 0, 0, 0, 0) + np.zeros(
        30_000, dtype=">f4").tobytes()
    raw.send(raw_message("POLYDATA", body, device=device, crc=1) + command_bytes("hello", b"{}", 2))
    told = raw.read_until(lambda m: m.type_name == "STATUS")
    assert told.body.code == StatusCode.CHECKSUM_ERROR
    assert told.body.text.startswith("CRC: expected"), told.body.text
    assert ask(raw, "hello", {}, 3)["ok"] is True


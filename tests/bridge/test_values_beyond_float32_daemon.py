"""Values from ROS that are finite in metres but not once in millimetres as float32 (what a
TRANSFORM carries), and doubles JSON cannot carry, on a real daemon with real peers
(tests/peers/huge_values_publisher.py, param_node.py, param_caller.py):

- no TRANSFORM holding an infinity or a NaN reaches a client (every element of every raw
  frame read is checked), on the native lane and on the Python path alike; the good
  messages between the bad ones still arrive, and each refusal is logged, rate-limited;
- a one-shot tf lookup that would hold infinity is an error reply naming the cause, and
  the session stays open (the issue saw 3 of 3 clients cut off);
- call_service whose response holds inf or NaN gets an error reply naming the field (the
  issue saw none within 8 s, and "Task exception was never retrieved")."""

from __future__ import annotations

import itertools
import json
import math
import socket
import struct
import time
from typing import Iterator

import pytest

from bridge.core import native_stream
from protocol.commands import ErrorCode
from protocol.framing import Decoder
from slicer_client.connection import CommandRefusedError, Connection
from support import Processes, RunningDaemon, assert_clean_exit, scaled, start_daemon

_names = itertools.count()
RCLPY_TAKE = ("--ros-take", "rclpy")  # no rcl reader, so no native lane


@pytest.fixture(params=["native lane", "python path"])
def daemon_of(request: pytest.FixtureRequest, processes: Processes) -> Iterator[RunningDaemon]:
    if request.param == "native lane" and not native_stream.available():
        pytest.skip("the native lane is not built here (no Cython or C compiler)")
    running = start_daemon(processes, *(RCLPY_TAKE if request.param == "python path"
                                         else ()))
    yield running
    assert_clean_exit(running)


def read_transforms(raw: socket.socket, wanted: dict[str, int],
                    timeout: float) -> dict[str, list[tuple[float, ...]]]:
    """Read raw frames until each device in `wanted` sent that many TRANSFORMs; the 12
    float32 of every TRANSFORM read (any device) are checked as they come (a v1 reader:
    the body is the 48)."""
    decoder = Decoder()
    devices: dict[str, list[tuple[float, ...]]] = {}
    deadline = time.monotonic() + timeout
    while any(len(devices.get(d, [])) < n for d, n in wanted.items()):
        assert time.monotonic() < deadline, {d: len(v) for d, v in devices.items()}
        raw.settimeout(max(0.1, deadline - time.monotonic()))
        data = raw.recv(1 << 16)
        assert data, "the daemon closed the raw reader's connection"
        decoder.feed(data)
        while (frame := decoder.next_frame()) is not None:
            if frame.type_name != "TRANSFORM":
                continue
            values = struct.unpack(">12f", bytes(frame.body))
            assert all(math.isfinite(v) for v in values), (frame.device_name, values)
            devices.setdefault(frame.device_name, []).append(values)
    return devices


def refused(connection: Connection, op: str, args: dict, timeout: float) -> tuple:
    started = time.monotonic()
    with pytest.raises(CommandRefusedError) as info:
        connection.command(op, args, timeout=timeout)
    return info.value.error, time.monotonic() - started


def test_no_transform_holds_infinity_and_lookups_say_why(
        processes: Processes, daemon_of: RunningDaemon) -> None:
    topic = f"/huge_{next(_names)}"
    client = daemon_of.connect()
    raw = socket.create_connection(("127.0.0.1", daemon_of.port), timeout=10)
    try:
        pose_device = client.command("create_subscriber", {"topic": topic,
                                                           "type": "PoseStamped"})["device"]
        lookups = {child: client.command("create_tf_lookup", {"parent": "world",
                                                              "child": child})["device"]
                   for child in ("huge", "big", "b", "ok")}
        # Kept, they stream to the raw reader too (a client's bridge streams only to the
        # clients that hold it: docs/security.md, "Who owns a bridge").
        kept = [{"kind": "subscriber", "topic": topic},
                *({"kind": "tf_lookup", "parent": "world", "child": child}
                  for child in lookups)]
        for bridge in kept:
            client.command("keep_bridge", bridge)
        peer = processes.python("huge", "huge_values_publisher.py", topic)
        peer.wait_for_output("READY")
        # A lookup sends when its value changes: world <- ok once.
        got = read_transforms(raw, {pose_device: 20, lookups["ok"]: 1}, scaled(30))

        # Only the good poses (0.25 and 0.5 m) came, in mm; the lookups of frames beyond
        # float32 sent nothing.
        assert {values[9] for values in got[pose_device]} == {250.0, 500.0}
        assert {values[9] for values in got[lookups["ok"]]} == {100.0}
        for child in ("huge", "big", "b"):
            assert lookups[child] not in got, child

        # One-shot lookups: an error reply naming the cause, the session open.
        for child, x_m in (("huge", 1e306), ("big", 1e36), ("b", 6e35)):
            error, _ = refused(client, "lookup_transform", {"parent": "world",
                                                            "child": child}, 10)
            assert (error.code, error.field) == (ErrorCode.NOT_SUPPORTED, "child")
            assert f"a transform world <- {child} whose numbers fit float32 in mm" \
                in error.message
            assert f"[{x_m!r}, 0.0, 0.0] m" in error.message
        error, took = refused(client, "lookup_transform", {"parent": "world", "child": "huge",
                                                           "timeout": 3.0}, 10)
        assert error.code == ErrorCode.NOT_SUPPORTED and took < 2.5  # no waiting for data
        ok = client.command("lookup_transform", {"parent": "world", "child": "ok"})
        assert ok["matrix"][0][3] == pytest.approx(100.0)
        assert client.command("hello")["node"]
        read_transforms(raw, {pose_device: 5}, scaled(30))  # still streamed
        for bridge in kept:
            client.command(f"remove_{bridge.pop('kind')}", bridge)
    finally:
        raw.close()
        client.close()
    output = daemon_of.child.wait_for_output(f"from {topic}, not sent: pose.position")
    assert "expected within float32 once in mm" in output
    log = daemon_of.child.output()
    # Rate-limited: at 50 Hz for seconds, a line at most every 5 s per stream.
    assert log.count(f"from {topic}, not sent") <= 3
    assert "lookup world <- huge (device" in log and "not sent: translation" in log


def test_call_service_whose_response_holds_inf_or_nan_is_answered(
        processes: Processes, daemon_of: RunningDaemon) -> None:
    name = f"odd_doubles_{next(_names)}"
    client = daemon_of.connect()
    try:
        peer = processes.python(name, "param_node.py", name)
        peer.wait_for_output("READY")
        request = {"service": f"/{name}/get_parameters", "type": "rcl_interfaces/GetParameters",
                   "request": {"names": ["count", "ratio"]}}
        answer = client.command("call_service", request, timeout=20)
        assert answer["response"]["values"][1]["double_value"] == 3.0
        for value in (math.inf, math.nan, -math.inf):
            caller = processes.python("caller", "param_caller.py", f"/{name}", json.dumps(
                {"set": "ratio", "type": "double", "value": value}))
            line = caller.wait_for_output("RESULT ", timeout=30)
            assert json.loads(line[line.index("{"):]) == {"successful": True, "reason": ""}
            error, took = refused(client, "call_service", request, 20)
            assert (error.code, error.field) == (ErrorCode.NOT_SUPPORTED,
                                                 "result.response.values[1].double_value")
            assert "finite doubles (JSON has no NaN or infinity)" in error.message
            assert f"got {value!r}" in error.message
            assert took < 8.0
        # The daemon's own op says the same, through the same refusal.
        client.command("create_parameter_client", {"node": name})
        error, _ = refused(client, "get_parameters", {"node": name, "names": ["ratio"]}, 20)
        assert (error.code, error.field) == (ErrorCode.NOT_SUPPORTED, "values.ratio")
        assert "finite doubles (JSON has no NaN or infinity)" in error.message
        assert client.command("hello")["node"]
    finally:
        client.close()
    assert "Task exception was never retrieved" not in daemon_of.child.output()

"""Parameter values JSON cannot carry or a STRING cannot hold, set by real ROS nodes
(tests/peers/param_node.py, param_caller.py) on a real daemon: a double set to NaN by ROS is
refused on reading, naming the parameter, and not pushed to observers; values too large for
a STRING are said in a STATUS OVERFLOW instead; the daemon's own parameters set to NaN by ROS
are left out of its stream; a read-only one cannot be undeclared."""

from __future__ import annotations

import itertools
import json
from typing import Any, Callable

import pytest

from protocol import commands as c
from protocol.commands import ErrorCode
from protocol.messages import Status, StatusCode, String
from slicer_client.connection import CommandRefusedError, Connection
from support import Child, Processes, RunningDaemon

_nodes = itertools.count()
NAN = float("nan")


def refused(call: Callable[[], Any]) -> c.ErrorInfo:
    with pytest.raises(CommandRefusedError) as info:
        call()
    return info.value.error


def caller_results(child: Child, count: int) -> list[dict[str, Any]]:
    lines = [child.wait_for_output("RESULT ", timeout=30) for _ in range(count)]
    return [json.loads(line[line.index("RESULT ") + len("RESULT "):]) for line in lines]


def values_of(message: Any) -> dict[str, Any]:
    return dict(json.loads(message.body.text)["values"])


def test_nan_and_oversized_values_of_a_node(processes: Processes, daemon: RunningDaemon,
                                            client: Connection) -> None:
    name = f"odd_values_{next(_nodes)}"
    peer = processes.python(name, "param_node.py", name)
    peer.wait_for_output("READY")
    device = client.command("create_parameter_client", {"node": name})["device"]
    client.wait_for(device, lambda m: not isinstance(m.body, Status)
                    or m.body.code == StatusCode.OK, timeout=20)
    observed = client.command("observe_parameters", {"node": name, "names": ["ratio"],
                                                     "all_changes": True})
    assert observed["values"]["ratio"] == {"type": "double", "value": 3.0}

    # ROS sets a double to NaN: JSON cannot say it; observers are not told a wrong value.
    caller = processes.python("caller", "param_caller.py", f"/{name}",
                              json.dumps({"set": "ratio", "type": "double", "value": NAN}))
    assert caller_results(caller, 1) == [{"successful": True, "reason": ""}]
    daemon.child.wait_for_output(f"parameter ratio of /{name} not streamed")
    error = refused(lambda: client.command("get_parameters", {"node": name,
                                                              "names": ["ratio"]}))
    assert (error.code, error.field) == (ErrorCode.NOT_SUPPORTED, "values.ratio")
    assert "finite doubles" in error.message

    # A value over a STRING's 64 KiB: the observers get a STATUS OVERFLOW instead.
    caller = processes.python("caller", "param_caller.py", f"/{name}", json.dumps(
        {"set": "ratio", "type": "double", "value": 0.5}), json.dumps(
        {"set": "label", "type": "string", "value": "x" * 70_000}))
    assert caller_results(caller, 2) == [{"successful": True, "reason": ""}] * 2
    overflow = client.wait_for(device, lambda m: isinstance(m.body, Status)
                               and m.body.code == StatusCode.OVERFLOW, timeout=20)
    assert "over a STRING's 65535" in overflow.body.text
    assert "use get_parameters" in overflow.body.text
    got = client.command("get_parameters", {"node": name, "names": ["label"]})
    assert got["values"]["label"] == {"type": "string", "value": "x" * 70_000}


def test_server_parameters_nan_by_ros_and_read_only(processes: Processes,
                                                    daemon: RunningDaemon,
                                                    client: Connection) -> None:
    node = client.command("hello")["node"]
    client.command("server_declare_parameter", {
        "name": "odd.gain", "value": {"type": "double", "value": 2.0}})
    client.command("server_declare_parameter", {
        "name": "odd.fixed", "value": {"type": "integer", "value": 7}, "read_only": True})
    device = "params:" + node.rsplit("/", 1)[-1]
    client.wait_for(device, lambda m: isinstance(m.body, String)
                    and values_of(m).get("odd.fixed") == {"type": "integer", "value": 7},
                    timeout=20)

    caller = processes.python("caller", "param_caller.py", node, json.dumps(
        {"set": "odd.gain", "type": "double", "value": NAN}))
    assert caller_results(caller, 1) == [{"successful": True, "reason": ""}]
    daemon.child.wait_for_output("server parameter odd.gain not streamed")
    streamed = client.wait_for(device, lambda m: isinstance(m.body, String)
                               and "odd.gain" not in values_of(m), timeout=20)
    assert values_of(streamed)["odd.fixed"] == {"type": "integer", "value": 7}
    error = refused(lambda: client.command("server_get_parameters", {"names": ["odd.gain"]}))
    assert error.code == ErrorCode.NOT_SUPPORTED and "finite doubles" in error.message

    error = refused(lambda: client.command("server_undeclare_parameter",
                                           {"name": "odd.fixed"}))
    assert (error.code, error.field) == (ErrorCode.ROS_ERROR, "name")
    assert "read-only ones stay" in error.message
    client.command("server_undeclare_parameter", {"name": "odd.gain"})

"""The typed client: requests built from the protocol's op classes, replies parsed into the
results the ops declare (protocol/commands/results.py). No daemon: a recording command
function stands in for the transport."""

from __future__ import annotations

import ast
import contextlib
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Tuple

import pytest

from protocol import commands as c
from slicer_client.bridge_state import BridgeSpec, BridgeState
from slicer_client.transport import request_with

CLIENT_SOURCES = Path(__file__).resolve().parents[2] / "slicer_client"


class Recorder:
    """A command function: records (op, args) and answers with the canned result."""

    def __init__(self, result: Mapping[str, Any]) -> None:
        self.result = dict(result)
        self.sent: List[Tuple[str, Dict[str, Any]]] = []

    def __call__(self, op: str, arguments: Optional[Mapping[str, Any]] = None, *,
                 timeout: float = 10.0) -> Dict[str, Any]:
        self.sent.append((op, dict(arguments or {})))
        return self.result


def _op_literals(path: Path, root: Path = CLIENT_SOURCES.parent) -> List[str]:
    """String constants in `path` that are op names, docstrings left out."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    docstrings = {id(node.body[0].value) for node in ast.walk(tree)
                  if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef,
                                       ast.AsyncFunctionDef))
                  and node.body and isinstance(node.body[0], ast.Expr)
                  and isinstance(node.body[0].value, ast.Constant)}
    return [f"{path.relative_to(root)}:{node.lineno}: {node.value!r}"
            for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and isinstance(node.value, str)
            and node.value in c.REQUEST_TYPES and id(node) not in docstrings]


def test_no_client_or_module_source_names_an_op_by_a_string() -> None:
    # Op names and fields come from the protocol's classes (`c.Publish(...)`, `.op`), so a
    # renamed op or field fails mypy and these tests, not a user at run time.
    found = [hit for path in sorted(CLIENT_SOURCES.rglob("*.py")) for hit in _op_literals(path)]
    assert not found, "op names as string literals (use the op classes):\n" + "\n".join(found)


def test_the_scan_finds_a_literal_op_name(tmp_path: Path) -> None:
    probe = tmp_path / "probe.py"
    probe.write_text('"""publish is named here, in a docstring."""\n'
                     'def f(client):\n    return client.command("publish", {})\n',
                     encoding="utf-8")
    assert [hit.split(": ")[-1] for hit in _op_literals(probe, tmp_path)] == ["'publish'"]


@pytest.mark.parametrize("request_", [
    c.Publish(topic="/cmd", value={"data": 1.5}),
    c.Publish(topic="/cmd", message={"data": "x"}),
    c.GetLastMessage(topic="/a", format="yaml"),
    c.ListParameters(node="/rsp"),
    c.GetParameters(node="/rsp", names=("a", "b")),
    c.SetParameters(node="/rsp", values={"a": c.ParameterValue.infer(2.5)}),
    c.ObserveParameters(node="/rsp", names=("a",), all_changes=True),
    c.LookupTransform(parent="world", child="tool", time=c.Stamp(sec=3, nanosec=4),
                      timeout=0.5),
    c.BroadcastTransform(parent="world", child="tool", stamp=c.Stamp(sec=1),
                         matrix=c.matrix_from([[1.0, 0.0, 0.0, 10.0], [0.0, 1.0, 0.0, 0.0],
                                               [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]],
                                              "matrix")),
    c.CallService(service="/srv", type="std_srvs/srv/Trigger", request={}, timeout=2.0),
    c.DescribeRobotJoints(name="arm"),
    c.SetRobotJoints(name="arm", positions=(("j1", 0.5), ("j2", -1.0)), topic="/js"),
    c.SolveIk(name="arm", tip="tool", seed=(("j1", 0.5),),
              target=c.matrix_from([[1.0, 0.0, 0.0, 300.0], [0.0, 1.0, 0.0, 0.0],
                                    [0.0, 0.0, 1.0, 400.0], [0.0, 0.0, 0.0, 1.0]], "target")),
    c.SendGoal(action="/fib", type="example_interfaces/action/Fibonacci", goal={"order": 3},
               timeout=2.0, result_timeout=9.0, goal_id="0" * 32),
    c.CancelGoal(action="/fib", goal_id="1" * 32, timeout=1.0),
    c.AdvertiseAction(action="/fib", type="example_interfaces/action/Fibonacci",
                      goal_timeout=5.0, decides=True),
    c.UnadvertiseAction(action="/fib"),
    c.ActionFeedback(action="/fib", goal_id="2" * 32, feedback={"sequence": [0, 1]}),
    c.ListTopics(), c.ListServices(), c.ListBridges(),
], ids=lambda r: type(r).__name__)
def test_a_typed_request_is_what_the_daemon_parses(request_: c.Op) -> None:
    command = Recorder({})  # an empty result: what matters here is what was sent
    with pytest.raises(c.ResultFormatError) if isinstance(request_, c.Answered) \
            else contextlib.nullcontext():
        request_with(command, request_)
    [(op, args)] = command.sent
    assert op == request_.op
    assert c.parse_request(op, c.dumps(args)) == request_


@pytest.mark.parametrize("spec", [
    BridgeSpec.of(c.CreateSubscriber(topic="/a", type="String", messages=True,
                                     qos=c.QoS(depth=3))),
    BridgeSpec.of(c.CreatePublisher(topic="/b", type="PoseArray", frame="world",
                                    labels_topic="/labels")),
    BridgeSpec.of(c.CreateParameterClient(node="/rsp")),
    BridgeSpec.of(c.CreateTfLookup(parent="world", child="tool", rate_hz=30.0)),
    BridgeSpec.of(c.CreateTfBroadcaster(parent="world", child="tool", static=True)),
    BridgeSpec.of(c.CreateRobot(name="arm", source=c.RobotSource("file", path="/r.urdf"),
                                tf_prefix="arm/")),
    BridgeSpec.of(c.CreateMarkerSubscriber(topic="/m", type="MarkerArray",
                                           fixed_frame="world")),
], ids=lambda s: s.op)
def test_a_bridge_spec_from_an_op_class_round_trips(spec: BridgeSpec) -> None:
    request = c.parse_request(spec.op, c.dumps(spec.args))
    assert BridgeSpec.of(request) == spec
    assert BridgeState.from_json(BridgeState((spec,)).to_json()).specs == (spec,)


def test_a_bridge_spec_keeps_only_the_fields_chosen() -> None:
    spec = BridgeSpec.of(c.CreateSubscriber(topic="/a", type="String"))
    assert spec == BridgeSpec("create_subscriber", {"topic": "/a", "type": "String"})
    assert BridgeSpec.of(c.CreateSubscriber(topic="/a", type="String", rate_hz=5.0,
                                            messages=True)).args == {
        "topic": "/a", "type": "String", "rate_hz": 5.0, "messages": True}


def test_replies_parse_into_the_declared_results() -> None:
    publish = request_with(Recorder({"topic": "/a", "subscribers": 2}),
                           c.Publish(topic="/a", value="x"))
    assert publish == c.PublishResult(topic="/a", subscribers=2)
    observed = request_with(Recorder({"ready": True, "values": {
        "a": {"type": "double", "value": 1.5}}, "device": "d"}),
        c.ObserveParameters(node="/rsp", names=("a",)))
    assert observed.ready and observed.values["a"] == c.ParameterValue("double", 1.5)
    outcome = request_with(Recorder({"results": {"a": {"ok": False, "reason": "no"}}}),
                           c.SetParameters(node="/n", values={"a": c.ParameterValue.infer(1)}))
    assert outcome.results == {"a": c.ParameterOutcome(ok=False, reason="no")}
    assert observed.device == "d" and outcome.node == ""  # a field left out: its default
    hello = c.Hello().parse_result({"node": "/b", "auth": {"writes": False,
                                                             "challenge": "ab"},
                                    "clock_ms": 7, "heartbeat": 1.0})
    assert hello == c.HelloResult(node="/b", auth=c.HelloAuth(writes=False, challenge="ab"),
                                  heartbeat=1.0, clock_ms=7)
    assert (hello.writes, hello.challenge) == (False, "ab")


@pytest.mark.parametrize("request_, result, field", [
    (c.Publish(topic="/a", value=1), {"subscriber": 2}, "publish.result.subscribers"),
    (c.SendGoal(action="/f", type="example_interfaces/action/Fibonacci"), {"device": 3},
     "send_goal.result.device"),
    (c.LookupTransform(parent="a", child="b"), {"matrix": [[1, 2]]},
     "lookup_transform.result.matrix"),
    (c.SetParameters(node="/n", values={"a": c.ParameterValue.infer(1)}),
     {"results": {"a": {"ok": "yes"}}}, "set_parameters.result.results.a.ok"),
    (c.GetParameters(node="/n", names=("a",)), {"values": {"a": {"type": "double",
                                                                  "value": "x"}}},
     "get_parameters.result.values.a.value"),
], ids=lambda x: x if isinstance(x, str) else "")
def test_a_reply_of_another_shape_names_the_field(request_: Any, result: Dict[str, Any],
                                                   field: str) -> None:
    # A renamed or retyped reply field fails here, saying what was expected and what came.
    with pytest.raises(c.ResultFormatError) as caught:
        request_with(Recorder(result), request_)
    assert caught.value.field == field
    assert "expected" in str(caught.value) and "got" in str(caught.value)


def test_the_client_request_goes_through_its_command_route() -> None:
    from slicer_client.client import Client

    class Stub:
        address, watches_silence, drops_late_values, connected = "stub", False, False, True
        carries_whole_messages, display_hz = True, None

        def __init__(self) -> None:
            self.command = Recorder({"topics": [{"topic": "/a", "types": ["x/msg/Y"]}]})

        def set_listener(self, listener: Any) -> None: ...

        def close(self) -> None: ...

    stub = Stub()
    client = Client(stub, callbacks="spin")  # type: ignore[arg-type]
    try:
        assert client.list_topics() == [{"topic": "/a", "types": ["x/msg/Y"]}]
        assert stub.command.sent[0][0] == c.ListTopics.op
    finally:
        client.close()

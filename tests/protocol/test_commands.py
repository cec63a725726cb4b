"""The JSON command schema (protocol/commands.py)."""

from __future__ import annotations

import json
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Iterator
from unittest.mock import patch

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol import commands as c
from protocol.commands import (
    REQUEST_TYPES,
    SCHEMA_VERSION,
    BadJsonError,
    CommandError,
    CommandFailedError,
    ErrorCode,
    MissingFieldError,
    OutOfRangeError,
    ParameterValue,
    Reply,
    TooLargeError,
    UnknownFieldError,
    UnknownOpError,
    UnsupportedSchemaError,
    WrongTypeError,
    parse_request,
)
from protocol.commands.fields import ROS_NAME, Args
from protocol.errors import ProtocolError
from tests.protocol.op_strategies import NoStrategyError, json_values, strategy_for

# ---------------------------------------------------------------- strategies

def _strategies() -> tuple[dict[type, st.SearchStrategy[Any]], dict[str, str]]:
    """Every op's strategy, derived from its class (tests/protocol/op_strategies.py), and
    the ops whose strategy cannot be built, with why."""
    built: dict[type, st.SearchStrategy[Any]] = {}
    failed: dict[str, str] = {}
    for cls in REQUEST_TYPES.values():
        try:
            built[cls] = strategy_for(cls)
        except NoStrategyError as error:
            failed[cls.op] = str(error)
    return built, failed


STRATEGIES, NO_STRATEGY = _strategies()


def test_every_op_has_a_strategy_and_a_unique_literal_op() -> None:
    assert not NO_STRATEGY, "\n".join(NO_STRATEGY.values())
    assert set(STRATEGIES) == set(REQUEST_TYPES.values())
    assert len(REQUEST_TYPES) == len(STRATEGIES)
    for op, cls in REQUEST_TYPES.items():
        assert cls.op == op
        assert len(op.encode()) <= c.MAX_OP_NAME_BYTES


def test_an_op_whose_field_has_no_strategy_is_named() -> None:
    @dataclass(frozen=True)
    class Odd(c.Op, op="test_odd_field", writes=False):
        widget: complex

        def resources(self) -> tuple[c.Resource, ...]:
            return ()

    try:
        with pytest.raises(NoStrategyError, match=r"Odd \(test_odd_field\): no strategy for "
                                                  r"field 'widget'"):
            strategy_for(Odd)
    finally:
        del REQUEST_TYPES["test_odd_field"]


@pytest.mark.parametrize("cls", list(STRATEGIES), ids=lambda k: k.op)
@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_to_json_parse_round_trip(cls: type, data: st.DataObject) -> None:
    request = data.draw(STRATEGIES[cls])
    op, text = c.encode_request(request)
    assert op == cls.op
    text.encode("ascii")  # ASCII-only JSON: Slicer labels commands US-ASCII
    assert json.loads(text)["schema"] == SCHEMA_VERSION
    parsed = parse_request(op, text)
    assert type(parsed) is cls
    assert parsed == request
    assert cls.from_json(text.encode()) == request
    assert parsed.to_json() == text


# ---------------------------------------------------------------- specific requests

@contextmanager
def _ros_name_reads() -> Iterator[set[str]]:
    """The field paths parsing reads as ROS names (the ROS_NAME pattern), while inside."""
    read: set[str] = set()
    req_str, opt_str = Args.req_str, Args.opt_str

    def recording(method: Any) -> Any:
        def wrapper(self: Args, name: str, *args: Any, **kwargs: Any) -> Any:
            if kwargs.get("pattern") is ROS_NAME:
                read.add(self.path(name))
            return method(self, name, *args, **kwargs)
        return wrapper

    with patch.object(Args, "req_str", recording(req_str)), \
            patch.object(Args, "opt_str", recording(opt_str)):
        yield read


# A robot's namespace is a prefix for its names (placed_source), not a name of its own.
_PREFIXES = {c.CreateRobot: {"namespace"}}


@pytest.mark.parametrize("cls", list(STRATEGIES), ids=lambda k: k.op)
@settings(max_examples=30, deadline=None)
@given(data=st.data())
def test_the_ros_names_a_request_parses_are_declared_and_resolved(
        cls: type, data: st.DataObject) -> None:
    """The dispatcher resolves exactly the declared `ros_names`: a name field left out
    would reach the policy and the handler unresolved (``cmd`` beside ``/cmd``)."""
    request = data.draw(STRATEGIES[cls])
    with _ros_name_reads() as read:
        parse_request(*c.encode_request(request))
    resolved = request.with_names(lambda name, field: f"/resolved/{field}")
    if isinstance(request, c.KeepBridge):  # it names its bridge as that bridge's removal does
        request, resolved, cls = request.bridge, resolved.bridge, type(request.bridge)
    assert read <= set(cls.ros_names) | _PREFIXES.get(cls, set())
    for path in cls.ros_names:
        if path in read and _value_at(request, path):
            assert _value_at(resolved, path) == f"/resolved/{path}"


def _value_at(request: Any, path: str) -> Any:
    head, _, inner = path.partition(".")
    value = getattr(request, head)
    return getattr(value, inner, None) if inner else value


def test_with_frames_maps_each_client_frame_of_the_tf_ops_once() -> None:
    seen: list[tuple[str, str]] = []

    def resolve(frame: str, field: str) -> str:
        seen.append((frame, field))
        return "PSM1/" + frame

    for cls in REQUEST_TYPES.values():
        assert cls.client_frames in ((), ("parent", "child")), cls.op
    request = c.parse_request("lookup_transform", json.dumps({"parent": "base",
                                                              "child": "tool"}))
    mapped = request.with_frames(resolve)
    assert (mapped.parent, mapped.child) == ("PSM1/base", "PSM1/tool")
    assert seen == [("base", "parent"), ("tool", "child")]
    subscribe = c.parse_request("create_subscriber", json.dumps({"topic": "/a", "type": "String"}))
    assert subscribe.with_frames(resolve) is subscribe  # no client frames: untouched


def test_with_names_places_a_robot_s_relative_source_in_its_namespace_first() -> None:
    request = c.parse_request("create_robot", json.dumps({
        "name": "psm", "namespace": "PSM1", "source": {"kind": "topic", "topic": "desc"}}))
    seen: list[tuple[str, str]] = []

    def resolve(name: str, field: str) -> str:
        seen.append((name, field))
        return "/" + name

    resolved = request.with_names(resolve)
    assert seen == [("PSM1/desc", "source.topic")]
    assert resolved.source.topic == "/PSM1/desc"
    assert resolved.with_names(lambda name, field: name) == resolved  # placed once only


def test_create_subscriber_defaults_and_type_resolution() -> None:
    req = c.CreateSubscriber.from_json('{"topic": "/tool", "type": "PoseStamped"}')
    # No depth given: the bridge chooses by type (10, or 1 for images and point clouds).
    assert req == c.CreateSubscriber("/tool", "PoseStamped",
                                     c.QoS(None, "reliable", "volatile"))
    assert req.qos.with_default_depth(10).depth == 10
    assert c.QoS(3).with_default_depth(10).depth == 3
    assert req.ros_type == "geometry_msgs/msg/PoseStamped"
    assert req.rate_hz is None


@pytest.mark.parametrize(
    ("given_type", "resolved"),
    [
        ("String", "std_msgs/msg/String"),
        ("Int", "std_msgs/msg/Int64"),
        ("DoubleTable", "std_msgs/msg/Float64MultiArray"),
        ("vtkMRMLROS2SubscriberStringNode", "std_msgs/msg/String"),
        ("vtkMRMLROS2PublisherPoseStampedNode", "geometry_msgs/msg/PoseStamped"),
        ("sensor_msgs/Image", "sensor_msgs/msg/Image"),
        ("my_pkg/msg/Custom2", "my_pkg/msg/Custom2"),
    ],
)
def test_message_type_names(given_type: str, resolved: str) -> None:
    assert c.resolve_message_type(given_type) == resolved


def test_service_types() -> None:
    assert c.resolve_service_type("turtlesim/Spawn") == "turtlesim/srv/Spawn"
    with pytest.raises(OutOfRangeError) as info:
        c.resolve_service_type("std_msgs/msg/String")
    assert info.value.field == "type"


def test_empty_text_means_no_arguments() -> None:
    assert parse_request("list_bridges", "") == c.ListBridges()
    assert parse_request("hello", b"  ") == c.Hello()


def test_broadcast_transform_matrix_kept_exactly() -> None:
    text = json.dumps({"parent": "world", "child": "tool",
                       "matrix": [[0, -1, 0, 3.1415], [1, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]],
                       "stamp": {"sec": 2**31 + 5, "nanosec": 999_999_999}})
    req = c.BroadcastTransform.from_json(text)
    assert req.matrix[0] == (0.0, -1.0, 0.0, 3.1415)
    assert req.stamp == c.Stamp(2**31 + 5, 999_999_999)


def test_create_robot_sources() -> None:
    default = c.CreateRobot.from_json('{"name": "PSM1"}')
    assert default.source == c.RobotSource("parameter", node="/robot_state_publisher",
                                           parameter="robot_description")
    topic = c.CreateRobot.from_json('{"name": "r", "source": {"kind": "topic"}}')
    assert topic.source.kind == "topic" and topic.source.topic == "/robot_description"
    with pytest.raises(MissingFieldError) as info:
        c.CreateRobot.from_json('{"name": "r", "source": {"kind": "file"}}')
    assert info.value.field == "source.path"


# ---------------------------------------------------------------- validation errors

BAD: list[tuple[str, str, type, str]] = [
    ("nope", "{}", UnknownOpError, "op"),
    ("create_subscriber", '{"type": "String"}', MissingFieldError, "topic"),
    ("create_subscriber", '{"topic": 3, "type": "String"}', WrongTypeError, "topic"),
    ("create_subscriber", '{"topic": "/a b", "type": "String"}', OutOfRangeError, "topic"),
    ("create_subscriber", '{"topic": "/x", "type": "No pe"}', OutOfRangeError, "type"),
    ("create_subscriber", '{"topic": "/x", "type": "String", "qos": {"depth": 0}}',
     OutOfRangeError, "qos.depth"),
    ("create_subscriber", '{"topic": "/x", "type": "String", "qos": {"depth": 1.5}}',
     WrongTypeError, "qos.depth"),
    ("create_subscriber", '{"topic": "/x", "type": "String", "qos": {"reliability": "maybe"}}',
     OutOfRangeError, "qos.reliability"),
    ("create_subscriber", '{"topic": "/x", "type": "String", "qos": {"durable": 1}}',
     UnknownFieldError, "qos.durable"),
    ("create_subscriber", '{"topic": "/x", "type": "String", "qos": []}',
     WrongTypeError, "qos"),
    ("create_subscriber", '{"topic": "/x", "type": "String", "rate_hz": 0}',
     OutOfRangeError, "rate_hz"),
    ("create_subscriber", '{"topic": "/x", "type": "String", "rate_hz": true}',
     WrongTypeError, "rate_hz"),
    ("create_subscriber", '{"topic": "/x", "type": "String", "tpoic": "/y"}',
     UnknownFieldError, "tpoic"),
    ("publish", '{"topic": "/x"}', MissingFieldError, "value"),
    ("get_last_message", '{"topic": "/x", "format": "xml"}', OutOfRangeError, "format"),
    ("get_parameters", '{"node": "/n", "names": "a"}', WrongTypeError, "names"),
    ("get_parameters", '{"node": "/n", "names": ["ok", 3]}', WrongTypeError, "names[1]"),
    ("set_parameters", '{"node": "/n", "values": {}}', OutOfRangeError, "values"),
    ("set_parameters", '{"node": "/n", "values": {"p": {"type": "integer", "value": 3.0}}}',
     WrongTypeError, "values.p.value"),
    ("set_parameters", '{"node": "/n", "values": {"p": {"type": "float", "value": 3.0}}}',
     OutOfRangeError, "values.p.type"),
    ("set_parameters", '{"node": "/n", "values": {"p": {"type": "byte_array", "value": [256]}}}',
     OutOfRangeError, "values.p.value[0]"),
    ("set_parameters", '{"node": "/n", "values": {"p": {"type": "bool", "value": 1}}}',
     WrongTypeError, "values.p.value"),
    ("set_parameters", '{"node": "/n", "values": {"p": {"type": "string"}}}',
     MissingFieldError, "values.p.value"),
    ("set_parameters", '{"node": "/n", "values": {"p": 3}}', WrongTypeError, "values.p"),
    ("server_declare_parameter", '{"name": "1bad", "value": {"type": "bool", "value": true}}',
     OutOfRangeError, "name"),
    ("lookup_transform", '{"parent": "a", "child": "b", "time": {"sec": -1}}',
     OutOfRangeError, "time.sec"),
    ("lookup_transform", '{"parent": "a", "child": "b", "time": {"nanosec": 1}}',
     MissingFieldError, "time.sec"),
    ("lookup_transform", '{"parent": "", "child": "b"}', OutOfRangeError, "parent"),
    ("lookup_transform", '{"parent": " a", "child": "b"}', OutOfRangeError, "parent"),
    ("lookup_transform", '{"parent": "a", "child": "b", "timeout": 1000}',
     OutOfRangeError, "timeout"),
    ("broadcast_transform", '{"parent": "a", "child": "b", "matrix": [[1, 0, 0, 0]]}',
     WrongTypeError, "matrix"),
    ("broadcast_transform",
     '{"parent": "a", "child": "b", "matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,"x",1]]}',
     WrongTypeError, "matrix[3][2]"),
    ("broadcast_transform",
     '{"parent": "a", "child": "b", "matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,1,1]]}',
     OutOfRangeError, "matrix[3]"),
    ("broadcast_transform",
     '{"parent": "a", "child": "b", "matrix": [[2,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}',
     OutOfRangeError, "matrix rotation"),
    ("create_robot", '{"name": "bad name"}', OutOfRangeError, "name"),
    ("create_robot", '{"name": "r", "source": {"kind": "usb"}}', OutOfRangeError, "source.kind"),
    ("call_service", '{"service": "/s", "type": "std_srvs/srv/SetBool", "request": []}',
     WrongTypeError, "request"),
    ("call_service", '{"service": "/s", "type": "std_srvs/srv/SetBool", "timeout": 0}',
     OutOfRangeError, "timeout"),
    ("call_service", '{"service": "/s", "type": "std_msgs/msg/String"}', OutOfRangeError, "type"),
    ("hello", '{"schema": 2}', UnsupportedSchemaError, "schema"),
    ("hello", '{"schema": "1"}', WrongTypeError, "schema"),
    ("hello", "[1, 2]", BadJsonError, "text"),
    ("hello", "{", BadJsonError, "text"),
    ("hello", '{"a": NaN}', BadJsonError, "text"),
    ("hello", '{"client": "a", "client": "b"}', BadJsonError, "client"),
    ("hello", '{"client": ' + "[" * 40 + "]" * 40 + "}", BadJsonError, "text"),
    ("hello", '{"a": ' + "[" * 600_000 + "]" * 600_000 + "}", TooLargeError, "text"),
]


@pytest.mark.parametrize(("op", "text", "error", "fld"), BAD,
                         ids=[f"{op}:{fld}" for op, _, _, fld in BAD])
def test_validation_errors_name_their_field(op: str, text: str, error: type, fld: str) -> None:
    with pytest.raises(error) as info:
        parse_request(op, text)
    err = info.value
    assert isinstance(err, CommandError) and isinstance(err, ProtocolError)
    assert err.field == fld
    assert err.expected
    assert str(err).startswith(f"{fld}: expected ")
    reply = c.error_reply(op, err)
    assert not reply.ok and reply.error is not None
    assert reply.error.field == fld
    assert reply.error.code == err.error_code
    assert reply.metadata()["Status"] == "FAIL"


def test_deep_nesting_within_size_limit_is_refused_cleanly() -> None:
    text = '{"a": ' + "[" * 100_000 + "]" * 100_000 + "}"
    with pytest.raises(BadJsonError) as info:
        c.loads(text, max_bytes=1 << 20)
    assert info.value.field == "text"


def test_non_utf8_bytes() -> None:
    with pytest.raises(BadJsonError) as info:
        parse_request("hello", b'{"client": "\xff"}')
    assert "UTF-8" in info.value.expected


def test_utf8_bytes_accepted_and_written_back_as_ascii() -> None:
    req = parse_request("create_tf_lookup", '{"parent": "wörld", "child": "t"}'.encode())
    assert req == c.CreateTfLookup("wörld", "t")
    assert "\\u00f6" in req.to_json()


def test_op_name_too_long() -> None:
    with pytest.raises(TooLargeError) as info:
        parse_request("x" * 200, "{}")
    assert info.value.field == "op"


# ---------------------------------------------------------------- parameter values

def test_integer_and_double_stay_distinct() -> None:
    i, d = ParameterValue("integer", 3), ParameterValue("double", 3)
    assert d.value == 3.0 and isinstance(d.value, float)
    assert i != d
    req = c.SetParameters("/n", {"i": i, "d": d})
    text = req.to_json()
    assert '"i":{"type":"integer","value":3}' in text
    assert '"d":{"type":"double","value":3.0}' in text
    back = parse_request("set_parameters", text)
    assert isinstance(back, c.SetParameters)
    assert type(back.values["i"].value) is int
    assert type(back.values["d"].value) is float


@pytest.mark.parametrize(
    ("value", "kind"),
    [(True, "bool"), (3, "integer"), (3.0, "double"), ("s", "string"), (b"\x00\xff", "byte_array"),
     ([True], "bool_array"), ([1, 2], "integer_array"), ([1.5, 2], "double_array"),
     (["a"], "string_array"), (None, "not_set")],
)
def test_parameter_infer(value: Any, kind: str) -> None:
    assert ParameterValue.infer(value).type == kind


def test_parameter_value_errors() -> None:
    with pytest.raises(WrongTypeError) as info:
        ParameterValue("integer", True)
    assert info.value.field == "value.value"
    with pytest.raises(OutOfRangeError):
        ParameterValue("integer", 2**63)
    with pytest.raises(OutOfRangeError):
        ParameterValue("double", float("inf"))
    with pytest.raises(WrongTypeError):
        ParameterValue.infer(object())
    assert ParameterValue("byte_array", b"\x01\x02").value == (1, 2)


# ---------------------------------------------------------------- replies

def test_success_reply_round_trip_and_metadata() -> None:
    reply = Reply.success("create_subscriber", {"device": "tool", "topic": "/tool"})
    text = reply.to_json()
    assert json.loads(text) == {"schema": SCHEMA_VERSION, "op": "create_subscriber", "ok": True,
                                "result": {"device": "tool", "topic": "/tool"}}
    assert Reply.from_json(text) == reply
    assert reply.metadata() == {"Status": "SUCCESS"}
    assert c.status_is_success(reply.metadata()["Status"])


def test_failure_reply_round_trip_and_metadata() -> None:
    reply = Reply.failure("remove_subscriber", ErrorCode.NOT_FOUND, "no subscriber on /x", "topic")
    data = json.loads(reply.to_json())
    assert data["error"] == {"code": 20, "name": "NOT_FOUND", "message": "no subscriber on /x",
                             "field": "topic"}
    assert Reply.from_json(reply.to_json()) == reply
    assert reply.metadata() == {"Status": "FAIL", "ErrorMessage": "no subscriber on /x"}
    assert not c.status_is_success("FAIL")


@pytest.mark.parametrize(("value", "ok"), [("SUCCESS", True), ("true", True), ("TRUE", True),
                                           ("FAIL", False), ("false", False), (None, False)])
def test_status_values(value: str | None, ok: bool) -> None:
    assert c.status_is_success(value) is ok


def test_reply_invariants() -> None:
    with pytest.raises(MissingFieldError):
        Reply(ok=False)
    with pytest.raises(OutOfRangeError):
        Reply(ok=True, error=c.ErrorInfo(ErrorCode.INTERNAL, "x"))
    with pytest.raises(WrongTypeError) as info:
        Reply.from_json('{"ok": "yes"}')
    assert info.value.field == "ok"
    with pytest.raises(MissingFieldError) as info2:
        Reply.from_json('{"ok": false}')
    assert info2.value.field == "error"


def test_unknown_future_error_code_still_parses() -> None:
    reply = Reply.from_json('{"ok": false, "error": {"code": 777, "message": "m"}}')
    assert reply.error is not None and reply.error.code == ErrorCode.INTERNAL


def test_command_failed_error_carries_its_code() -> None:
    err = CommandFailedError("topic", "an existing subscriber", "/x", code=ErrorCode.NOT_FOUND)
    reply = c.error_reply("remove_subscriber", err)
    assert reply.error == c.ErrorInfo(ErrorCode.NOT_FOUND,
                                      "topic: expected an existing subscriber, got /x", "topic")


@pytest.mark.parametrize(
    ("exc", "code"),
    [(WrongTypeError("a", "b", "c"), ErrorCode.WRONG_TYPE),
     (ProtocolError("m", "4x4", "3x3"), ErrorCode.OUT_OF_RANGE),
     (RuntimeError("boom"), ErrorCode.INTERNAL)],
)
def test_reply_for_exception(exc: BaseException, code: ErrorCode) -> None:
    reply = c.reply_for_exception("publish", exc)
    assert reply.error is not None and reply.error.code == code
    assert reply.op == "publish"


@given(st.dictionaries(st.text(max_size=8), json_values, max_size=5))
def test_reply_result_round_trip(result: dict[str, Any]) -> None:
    reply = Reply.success("hello", result)
    assert Reply.from_json(reply.to_json()) == reply


def test_error_codes_are_stable() -> None:
    # Clients may switch on the numbers: never renumber.
    expected: dict[str, int] = {
        "BAD_JSON": 1, "TOO_LARGE": 2, "UNKNOWN_OP": 3, "UNSUPPORTED_SCHEMA": 4,
        "MISSING_FIELD": 5, "UNKNOWN_FIELD": 6, "WRONG_TYPE": 7, "OUT_OF_RANGE": 8,
        "NOT_FOUND": 20, "ALREADY_EXISTS": 21, "UNKNOWN_ROS_TYPE": 22, "ROS_ERROR": 23,
        "TIMEOUT": 24, "UNAVAILABLE": 25, "TRANSFORM_UNAVAILABLE": 26, "NOT_SUPPORTED": 27,
        "FORBIDDEN": 28, "LIMIT_REACHED": 29, "REJECTED": 30, "INTERNAL": 99,
    }
    assert {e.name: int(e) for e in ErrorCode} == expected


def test_dumps_refuses_nan_and_infinity_naming_where() -> None:
    with pytest.raises(c.CommandFailedError) as info:
        c.Publish("/x", float("nan")).to_json()
    assert (info.value.error_code, info.value.field) == (ErrorCode.NOT_SUPPORTED, "value")
    reply = c.Reply.success("call_service", {"response": {"values": [
        {"double_value": 1.0}, {"double_value": float("-inf")}], "z": float("nan")}})
    with pytest.raises(c.CommandFailedError) as info:
        reply.to_json()
    assert str(info.value) == ("result.response.values[1].double_value: expected finite "
                               "doubles (JSON has no NaN or infinity), got -inf")
    assert c.not_json_number("values.ratio", "inf").error_code == ErrorCode.NOT_SUPPORTED
    loop: dict[str, object] = {"a": [1.0]}
    loop["b"] = loop  # refused by json as well, and said so without a hunt that never ends
    with pytest.raises(OutOfRangeError, match="Circular reference"):
        c.dumps(loop)


def test_type_names_left_to_the_daemon_and_misspelt_ones() -> None:
    """Issue 43, item 10: a bare name the protocol cannot look up (`Float32`) passes a
    request's parse for the daemon to resolve; a name no look-up could make a type, or one
    close to a known one, is UNKNOWN_ROS_TYPE with the closest known name."""
    c.check_message_type("Float32")
    c.check_message_type("vtkMRMLROS2SubscriberFloat32Node")
    assert c.CreateSubscriber.from_json('{"topic": "/f", "type": "Float32"}').type == "Float32"
    with pytest.raises(c.UnknownTypeError) as misspelt:
        c.resolve_message_type("PoseStampd")
    assert misspelt.value.error_code == c.ErrorCode.UNKNOWN_ROS_TYPE
    assert str(misspelt.value) == ("type: expected pkg/msg/Type, pkg/Type, or a short name "
                                   "such as String or PoseStamped, got 'PoseStampd' (did you "
                                   "mean PoseStamped?)")
    with pytest.raises(c.UnknownTypeError, match="got 'Pose Stamped' \\(did you mean Pose"):
        c.check_message_type("Pose Stamped")

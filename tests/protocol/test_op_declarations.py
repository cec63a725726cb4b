"""Every op of the schema declares what it writes, creates, removes and touches, and the
rest of the project derives its tables from those declarations (issue 11: "the op is the
unit"). Each op carries its examples (`Op.examples`: a valid request and the resources it
must declare); the tests iterate the registry, so a new op without one fails here, named."""

from __future__ import annotations

import ast
import re
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Optional, cast

import pytest

from protocol import commands as c
from protocol.commands import (ActionUse, Bridge, FileUse, FrameUse, Op, ParameterUse,
                               Resource, ServiceUse, TopicUse)


BRIDGE = Path(__file__).resolve().parents[2] / "bridge"


def examples(cls: type[Op]) -> tuple[c.Example, ...]:
    """The op's own examples (`Op.examples`), or a failure naming the op that has none."""
    own = cls.__dict__.get("examples", ())
    assert own, (f"{cls.__name__} ({cls.op}) gives no example: declare examples = "
                 f"(Example(<a valid request's arguments>, <the resources it declares>),) "
                 f"beside its fields")
    return cast("tuple[c.Example, ...]", own)


CASES = [(cls, i) for cls in c.REQUEST_TYPES.values()
         for i in range(len(cls.__dict__.get("examples", ())) or 1)]


def judged(use: Resource) -> tuple[str, str, str]:
    if isinstance(use, TopicUse):
        return "topic", use.field, use.name
    if isinstance(use, ServiceUse):
        return "service", use.field, use.name
    if isinstance(use, ParameterUse):
        return "parameter", use.field, f"{use.node or 'OWN'}.{','.join(use.names)}"
    if isinstance(use, FrameUse):
        return "frame", use.field, use.frame
    if isinstance(use, ActionUse):
        return "action", use.field, use.name
    assert isinstance(use, FileUse)
    return "file", use.field, use.path


@pytest.mark.parametrize(("cls", "index"), CASES, ids=lambda v: getattr(v, "op", str(v)))
def test_each_op_declares_what_it_touches(cls: type[Op], index: int) -> None:
    example = examples(cls)[index]
    op = cls.op
    request = c.parse_request(op, c.dumps(dict(example.args)))
    assert type(request) is cls and isinstance(cls.writes, bool)
    expected = example.declares
    assert "resources" in cls.__dict__  # its own declaration, not an inherited default
    uses = request.resources()
    assert {judged(use) for use in uses} == expected
    names = {f.name for f in fields(request)}
    for use in uses:  # every field a refusal would name is one of the request's
        assert use.field.split(".")[0] in names, (op, use.field)
    # What --read-only refuses: an op that writes through any resource declares writes
    # (some write through none: a player's clock, stopping a recording).
    if any(writes(use) for use in uses):
        assert cls.writes, f"{op} writes through {[u for u in uses if writes(u)]}"


def writes(use: Resource) -> bool:
    if isinstance(use, ServiceUse):
        return True  # calling a service or offering one
    return bool(getattr(use, "writes", False) or getattr(use, "serves", False))


def test_an_op_without_examples_fails_naming_it() -> None:
    @dataclass(frozen=True)
    class Bare(Op, op="test_bare", writes=False):
        def resources(self) -> tuple[Resource, ...]:
            return ()

    try:
        with pytest.raises(AssertionError, match=r"Bare \(test_bare\) gives no example"):
            examples(Bare)
    finally:
        del c.REQUEST_TYPES["test_bare"]


def test_bridge_kinds_pair_create_and_remove_with_their_identity() -> None:
    kinds = c.bridge_kinds()
    assert set(kinds) == {"subscriber", "publisher", "parameter_client", "tf_lookup",
                          "tf_broadcaster", "robot", "served_service", "marker_subscriber",
                          "served_action"}
    for kind in kinds.values():
        assert kind.create.creates is kind.bridge and kind.remove.removes == kind.bridge.kind
        remove_fields = {f.name for f in fields(kind.remove)}
        assert set(kind.bridge.identity) <= remove_fields
    assert [f.op for f in kinds["parameter_client"].follow_ups] == ["observe_parameters"]


def test_a_publisher_declares_its_frame_and_labels_topic() -> None:
    request = c.parse_request("create_publisher", c.dumps({
        "topic": "/m", "type": "shape_msgs/msg/Mesh", "frame": "patient",
        "labels_topic": "/m/labels"}))
    assert {judged(use) for use in request.resources()} == {
        ("topic", "topic", "/m"), ("topic", "labels_topic", "/m/labels"),
        ("frame", "frame", "patient")}
    assert all(use.writes for use in request.resources() if isinstance(use, TopicUse))


def test_derived_tables_follow_the_declarations() -> None:
    from bridge.config import SECTIONS
    from slicer_client.bridge_state import FOLLOW_UP_OPS, REMOVE_OPS

    kinds = c.bridge_kinds().values()
    assert SECTIONS == {k.bridge.section: k.create.op for k in kinds if k.bridge.section}
    assert REMOVE_OPS == {k.create.op: (k.remove.op, k.bridge.identity) for k in kinds
                          if not k.bridge.per_connection}
    assert FOLLOW_UP_OPS == ("observe_parameters",)


def test_an_op_that_declares_nothing_fails_at_import() -> None:
    with pytest.raises(TypeError, match="declares its name"):
        @dataclass(frozen=True)
        class NoName(Op, writes=False):  # type: ignore[call-arg]
            def resources(self) -> tuple[Resource, ...]:
                return ()
    with pytest.raises(TypeError, match="whether it writes"):
        @dataclass(frozen=True)
        class NoWrites(Op, op="test_no_writes"):
            def resources(self) -> tuple[Resource, ...]:
                return ()
    with pytest.raises(TypeError, match="what it touches"):
        @dataclass(frozen=True)
        class NoResources(Op, op="test_no_resources", writes=False):
            pass
    with pytest.raises(TypeError, match="declared twice"):
        @dataclass(frozen=True)
        class Twice(Op, op="hello", writes=False):
            def resources(self) -> tuple[Resource, ...]:
                return ()
    with pytest.raises(TypeError, match="identity field 'topic'"):
        @dataclass(frozen=True)
        class BadIdentity(Op, op="test_bad_identity", writes=False,
                          creates=Bridge("thing", ("topic",))):
            name: str

            def resources(self) -> tuple[Resource, ...]:
                return ()
    with pytest.raises(TypeError, match="its result is declared twice"):
        @dataclass(frozen=True)
        class TwoResults(Op, c.Answered[c.PublishResult], op="test_two_results",
                         writes=False, result=c.PublishResult):
            def resources(self) -> tuple[Resource, ...]:
                return ()
    assert not [op for op in c.REQUEST_TYPES if op.startswith("test_")]


def test_a_create_op_without_its_remove_op_fails_the_pairing() -> None:
    @dataclass(frozen=True)
    class Orphan(Op, op="test_create_orphan", writes=False,
                 creates=Bridge("orphan", ("name",))):
        name: str

        def resources(self) -> tuple[Resource, ...]:
            return ()

    try:
        with pytest.raises(TypeError, match="'orphan' has no create/remove pair"):
            c.bridge_kinds()
    finally:
        del c.REQUEST_TYPES["test_create_orphan"]


def test_action_ops_parse_types_goal_ids_and_limits() -> None:
    goal = c.SendGoal.from_json(c.dumps({
        "action": "fjt", "type": "control_msgs/FollowJointTrajectory",
        "goal_id": "0123ABCD-0123-4567-89ab-0123456789AB", "result_timeout": 2}))
    assert goal.ros_type == "control_msgs/action/FollowJointTrajectory"
    assert goal.goal_id == "0123abcd0123456789ab0123456789ab" and goal.result_timeout == 2.0
    assert goal.goal == {} and goal.timeout == 4.0
    for args, field, code in [
            ({"action": "/a", "type": "control_msgs/msg/X"}, "type", c.ErrorCode.OUT_OF_RANGE),
            ({"action": "/a", "type": "p/A", "goal": []}, "goal", c.ErrorCode.WRONG_TYPE),
            ({"action": "/a", "type": "p/A", "goal_id": "xyz"}, "goal_id",
             c.ErrorCode.OUT_OF_RANGE),
            ({"action": "/a", "type": "p/A", "timeout": 0}, "timeout", c.ErrorCode.OUT_OF_RANGE),
            ({"action": "a b", "type": "p/A"}, "action", c.ErrorCode.OUT_OF_RANGE)]:
        with pytest.raises(c.CommandError) as error:
            c.SendGoal.from_json(c.dumps(args))
        assert (error.value.field, error.value.error_code) == (field, code), args
    assert c.resolve_action_type("pkg/action/Name") == "pkg/action/Name"
    assert c.goal_id_text("A" * 32) == "a" * 32


# ---------------------------------------------------------------- results

def _bridge_modules() -> dict[str, ast.Module]:
    return {str(path.relative_to(BRIDGE.parent)): ast.parse(path.read_text(), str(path))
            for path in sorted(BRIDGE.rglob("*.py"))}


def _handler_tables(modules: dict[str, ast.Module]) -> list[tuple[str, str, ast.expr]]:
    """Every handler table entry in bridge/: (module path, op class name, handler)."""
    entries = []
    for path, tree in modules.items():
        for node in ast.walk(tree):
            if not isinstance(node, ast.Dict):
                continue
            for key, value in zip(node.keys, node.values):
                name = ast.unparse(key).removeprefix("c.") if key is not None else ""
                if isinstance(c.__dict__.get(name), type) and issubclass(c.__dict__[name], Op):
                    entries.append((path, name, value))
    return entries


def _annotations(modules: dict[str, ast.Module]) -> dict[str, dict[str, set[str]]]:
    """Function name -> module path -> the return annotations of the functions so named."""
    found: dict[str, dict[str, set[str]]] = {}
    for path, tree in modules.items():
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) \
                    and node.returns is not None:
                found.setdefault(node.name, {}).setdefault(path, set()).add(
                    ast.unparse(node.returns))
    return found


def _returns(path: str, handler: ast.expr,
             annotations: dict[str, dict[str, set[str]]]) -> Optional[str]:
    """The return annotation of the function a handler entry calls (a method, a lambda
    calling one), found by its name in the entry's module first, then in bridge/."""
    target = handler.body if isinstance(handler, ast.Lambda) else handler
    if isinstance(target, ast.Call):
        target = target.func
    name = target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", "")
    found = annotations.get(name, {})
    mine = found.get(path) or set().union(*found.values())
    return next(iter(mine)) if len(mine) == 1 else None


def test_every_client_op_declares_its_result_and_its_handlers_return_it() -> None:
    """An op's reply is its declared result type (`Op.result`): the dispatcher refuses a
    handler that returns another (INTERNAL, naming both), and here every handler in
    bridge/ says in its annotation that it returns that type (or a subtype)."""
    for op, cls in c.REQUEST_TYPES.items():
        if cls.to_client:
            assert cls.result is None, op  # the client answers these
        else:
            assert isinstance(cls.result, type) and issubclass(cls.result, c.Result), (
                f"{cls.__name__} ({op}) declares no result type: result=... or "
                f"Answered[...] beside its fields")
    served: set[str] = set()
    modules = _bridge_modules()
    annotations = _annotations(modules)
    for path, name, handler in _handler_tables(modules):
        cls = c.__dict__[name]
        returns = _returns(path, handler, annotations)
        assert returns is not None, f"{path}: the {cls.op} handler's return type not found"
        served.add(cls.op)
        named = {c.__dict__.get(word) for word in re.findall(r"\w+", returns)}
        assert any(isinstance(t, type) and issubclass(t, cls.result) for t in named) \
            or returns == "NoReturn", (f"{path}: the {cls.op} handler returns {returns}: "
                                       f"expected {cls.result.__name__}, as its op declares")
    assert served == {op for op, cls in c.REQUEST_TYPES.items() if not cls.to_client}


def test_results_with_keys_of_their_own_keep_the_wire_s_order() -> None:
    """Results whose JSON is not only their fields in order: list_bridges' capability state
    beside its four keys, a bridge kind's extra keys, a last message's null value."""
    listing = c.ListBridgesResult((), ("tool",), (), 0, {"tf_buffer": {"frames": []}})
    assert list(listing.to_dict()) == ["bridges", "devices", "clients", "hub_dropped",
                                       "tf_buffer"]
    assert c.ListBridgesResult.parse("list_bridges", listing.to_dict()) == listing
    bridge = c.TopicBridge("publisher", "/b", "std_msgs/msg/String", "pub:b", "STRING",
                           {"depth": 10}, 2, extra={"subscribers": 1, "frame": "w"},
                           message_device="msg:b")
    assert list(bridge.to_dict()) == ["kind", "topic", "type", "device", "igtl_type", "qos",
                                      "messages", "subscribers", "frame", "message_device"]
    empty = c.GetLastMessageResult("/a", "std_msgs/msg/Empty", 0, False)
    assert empty.to_dict() == {"topic": "/a", "type": "std_msgs/msg/Empty", "count": 0,
                               "received": False}
    held = c.GetLastMessageResult("/a", "std_msgs/msg/Empty", 1, True, "{}\n", None)
    assert list(held.to_dict().items())[-2:] == [("text", "{}\n"), ("value", None)]
    assert c.GetLastMessageResult.parse("get_last_message", held.to_dict()) == held


@pytest.mark.parametrize("result", [
    c.TfLookupBridge("tf_lookup", "world", "tool", "tf:world>tool", "TRANSFORM", "error", 3,
                     error="no frame tool"),
    c.OwnParameter("speed", c.ParameterValue("double", 0.5), existed=False),
    c.BroadcastTransformResult("/tf", c.Stamp(5, 7), 2),
    c.ObstacleDistancesResult("arm", "tool", {"j1": 0.5}, ({"obstacle": "skull"},), (), ()),
    c.RecordingResult("/data/a.mcap", 1, 0.5, 3, 0, 100, 0, False,
                      ({"topic": "/a", "type": "std_msgs/msg/String"},), error="disk full"),
    c.ListActionsResult(({"action": "/fjt", "types": ["control_msgs/action/X"]},)),
], ids=lambda r: type(r).__name__)
def test_a_result_reads_back_what_it_wrote(result: c.Result) -> None:
    """`Result.read`, derived from the field types, reads `Result.to_dict` back (through
    JSON text, as a client gets it)."""
    data = c.loads(c.dumps(result.to_dict()))
    assert type(result).parse("op", data) == result
    with pytest.raises(c.ResultFormatError, match=r"op\.result\.\w+(\[0\])?: expected"):
        type(result).parse("op", {**data, next(iter(data)): [1]})

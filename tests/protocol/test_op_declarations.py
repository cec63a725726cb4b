"""Every op of the schema declares what it writes, creates, removes and touches, and the
rest of the project derives its tables from those declarations (issue 11: "the op is the
unit"). Each op carries its examples (`Op.examples`: a valid request and the resources it
must declare); the tests iterate the registry, so a new op without one fails here, named."""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import cast

import pytest

from protocol import commands as c
from protocol.commands import (ActionUse, Bridge, FileUse, FrameUse, Op, ParameterUse,
                               Resource, ServiceUse, TopicUse)


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

"""Security inside content is declared by the op (`Op.content`) and attached by the
dispatcher: the policy builds one `ContentGuard` per request for what its op declares, the
handler gets it as its third argument, and no capability holds the policy."""

from __future__ import annotations

import ast
import asyncio
import inspect
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import pytest

import bridge
from bridge.actions import ActionBridges
from bridge.core.dispatch import Dispatcher
from bridge.core.hub import Hub
from bridge.core.security import NameRules, SecurityPolicy
from bridge.markers.capability import MarkerBridges
from bridge.parameters.capability import ParameterBridges
from bridge.robots.capability import RobotBridges
from bridge.services.capability import ServiceBridges
from bridge.tf.capability import TfBridges
from bridge.topics.capability import TopicBridges
from protocol import commands as c

POLICY = SecurityPolicy(frames=NameRules(deny=("secret*",)),
                        parameters=NameRules(allow=("/arm.speed",)))
CAPABILITIES = (TopicBridges, TfBridges, ParameterBridges, ServiceBridges, ActionBridges,
                RobotBridges, MarkerBridges)


def test_an_op_declares_content_of_known_kinds_only() -> None:
    with pytest.raises(TypeError, match="content 'pixels' is not one of messages, frames"):
        @dataclass(frozen=True)
        class Odd(c.Op, op="odd_content_op", writes=False, content=("pixels",)):
            def resources(self) -> tuple[c.Resource, ...]:
                return ()
    assert "odd_content_op" not in c.REQUEST_TYPES


def test_the_guard_serves_only_what_its_op_declares() -> None:
    robot = c.parse_request("create_robot", c.dumps(
        {"name": "r", "source": {"kind": "parameter", "node": "/rsp"}}))
    guard = POLICY.content_guard(robot)
    assert guard.declared == ("frames", "files")
    assert guard.frame_refusal("base") is None
    assert guard.frame_refusal("secret_room") == ("frame 'secret_room' refused by the frame "
                                                  "policy: expected a name not matching the "
                                                  "deny glob 'secret*'")
    with pytest.raises(c.ForbiddenError) as refused:
        guard.check_frame("fixed_frame", "secret_room")
    assert (refused.value.field, refused.value.got) == ("fixed_frame", "secret_room")
    assert guard.visible_frames(["base", "secret_a", "tool"]) == ["base", "tool"]
    # Parameters were not declared by create_robot: reading them is a bug, not an open door.
    with pytest.raises(TypeError, match="op 'create_robot' reads its content's parameters"):
        guard.visible_parameters("/arm", ["speed"])
    with pytest.raises(TypeError, match="messages"):
        guard.message_filter()


def test_parameter_content_is_judged_as_node_dot_name() -> None:
    listing = c.parse_request("list_parameters", c.dumps({"node": "/arm"}))
    guard = POLICY.content_guard(listing)
    assert guard.visible_parameters("/arm", ["speed", "limit"]) == ["speed"]
    assert guard.visible_parameters("/other", ["speed"]) == []
    assert SecurityPolicy().content_guard(listing).visible_parameters("/x", ["a"]) == ["a"]
    with pytest.raises(TypeError, match="frames"):
        guard.frame_refusal("base")


def test_every_op_that_declares_content_gets_its_guard_and_no_other_does() -> None:
    """The arity the dispatcher checks at start-up, for the daemon's real handlers."""

    async def build() -> Dispatcher:
        hub = Hub(asyncio.get_running_loop())
        return Dispatcher(None, hub, [_Handlers()], policy=POLICY)  # type: ignore[arg-type]

    dispatcher = asyncio.run(build())
    assert dispatcher is not None
    for cls in c.REQUEST_TYPES.values():
        if cls.content:
            assert not cls.to_client, cls.op  # the daemon never hands a client's op a guard

    class Wrong(_Handlers):
        def handlers(self) -> Mapping[type[c.Op], Any]:
            return {c.CreateRobot: lambda request, client: {}}

    async def build_wrong() -> None:
        Dispatcher(None, Hub(asyncio.get_running_loop()), [Wrong()],  # type: ignore[arg-type]
                   policy=POLICY)

    with pytest.raises(TypeError, match=r"create_robot handler takes 2 arguments: expected "
                                        r"\(request, client, guard\)"):
        asyncio.run(build_wrong())


class _Handlers:
    """A capability serving two ops, one that declares content and one that does not."""

    def handlers(self) -> Mapping[type[c.Op], Any]:
        return {c.CreateRobot: lambda request, client, guard: {},
                c.ListRobots: lambda request, client: {}}

    def describe(self) -> list[dict[str, Any]]:
        return []

    def state(self, guard: Any) -> Mapping[str, Any]:
        return {}

    def close(self) -> None:
        pass


def test_no_capability_holds_the_policy() -> None:
    """Capabilities get guards from the dispatcher; none imports the policy or its rules,
    and none is built with them."""
    root = Path(bridge.__file__).parent
    for folder in ("topics", "tf", "parameters", "services", "actions", "robots", "markers",
                   "types"):
        for path in sorted((root / folder).rglob("*.py")):
            tree = ast.parse(path.read_text(), str(path))
            for node in ast.walk(tree):
                if isinstance(node, ast.ImportFrom) and node.module == "bridge.core.security":
                    names = {alias.name for alias in node.names}
                    assert not names & {"SecurityPolicy", "NameRules"}, (path, names)
    for capability in CAPABILITIES:
        taken = set(inspect.signature(capability.__init__).parameters)
        assert not taken & {"policy", "frame_rules"}, capability.__name__


def test_files_content_names_are_read_inside_the_robot_folders_unless_the_operators_own() -> None:
    """A URDF from a parameter or a topic, or a marker's mesh, can be changed by any client
    or ROS peer: its meshes are read only inside the robot folders, whoever asked. Only a
    URDF file the operator's config names is trusted to name meshes anywhere."""
    policy = SecurityPolicy(robot_dirs=("/opt/robots", "/ws/src"))
    by_file = c.parse_request("create_robot", c.dumps(
        {"name": "r", "source": {"kind": "file", "path": "/opt/robots/r.urdf"}}))
    by_parameter = c.parse_request("create_robot", c.dumps(
        {"name": "r", "source": {"kind": "parameter", "node": "/rsp"}}))
    markers = c.parse_request("create_marker_subscriber", c.dumps(
        {"topic": "/m", "type": "MarkerArray", "fixed_frame": "world"}))
    roots = (Path("/opt/robots"), Path("/ws/src"))
    assert policy.content_guard(by_file, from_client=False).readable_roots() is None
    assert policy.content_guard(by_file, from_client=True).readable_roots() == roots
    assert policy.content_guard(by_parameter, from_client=False).readable_roots() == roots
    assert policy.content_guard(markers, from_client=False).readable_roots() == roots
    assert SecurityPolicy().content_guard(markers).readable_roots() == ()  # none: no file
    listing = c.parse_request("list_parameters", c.dumps({"node": "/arm"}))
    with pytest.raises(TypeError, match="files"):
        policy.content_guard(listing).readable_roots()

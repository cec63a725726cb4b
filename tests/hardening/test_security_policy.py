"""The security policy on its own: name rules, networks, limits, config merging (no ROS)."""

from __future__ import annotations

import ipaddress
from pathlib import Path

import pytest

from bridge.config import ConfigError, build_security, load_config_file
from bridge.core.security import (OPERATOR, BridgeOwners, BridgeQuota, NameRules, SecurityPolicy,
                                  is_loopback_host, strip_frame)
from protocol import commands as c
from protocol.commands import ErrorCode, ForbiddenError, LimitReachedError


def resolve(name: str, field: str) -> str:
    # What the daemon does with namespace "/lab": relative names go under it.
    return name if name.startswith("/") else "/lab/" + name


def parsed(op: str, args: dict) -> c.Request:
    """A request as the dispatcher hands it to the policy: its ROS names resolved."""
    return c.parse_request(op, c.dumps(args)).with_names(resolve)


def check(policy: SecurityPolicy, op: str, args: dict) -> None:
    policy.check_request(parsed(op, args), "/lab/slicer_bridge")


def test_recordings_write_only_inside_the_record_folders(tmp_path: Path) -> None:
    inside_dir = tmp_path / "bags"
    inside_dir.mkdir()
    (inside_dir / "out").symlink_to("/etc")  # a link inside pointing outside
    (inside_dir / "x.mcap").symlink_to("/etc/x.mcap")
    policy = SecurityPolicy(record_dirs=(str(inside_dir),))
    check(policy, "start_recording", {"path": f"{inside_dir}/a.mcap"})
    check(policy, "start_recording", {"path": f"{inside_dir}/new_folder/a.mcap"})
    for path in ("/etc/a.mcap", f"{inside_dir}/../a.mcap", f"{inside_dir}/out/a.mcap",
                 f"{inside_dir}/x.mcap"):
        with pytest.raises(ForbiddenError) as refused:
            check(policy, "start_recording", {"path": path})
        assert refused.value.field == "path" and "--record-dir" in str(refused.value), path
    with pytest.raises(ForbiddenError, match="none: start the daemon with --record-dir"):
        check(SecurityPolicy(), "start_recording", {"path": f"{inside_dir}/a.mcap"})
    # The operator's own config is trusted (as its robots' files are).
    SecurityPolicy().check_request(parsed("start_recording", {"path": "/etc/a.mcap"}),
                                   "/lab/slicer_bridge", from_client=False)


def test_deny_wins_and_any_allow_glob_makes_an_allow_list() -> None:
    rules = NameRules(allow=("/robot/*",), deny=("/robot/cmd_*",))
    assert rules.permits("/robot/joint_states")
    assert not rules.permits("/robot/cmd_vel")  # allowed by a glob, denied by another
    assert not rules.permits("/camera/image")  # not in the allow list
    assert NameRules(deny=("/cmd_vel",)).permits("/camera/image")  # deny only: rest allowed
    assert NameRules().permits("/anything")


def test_read_only_refuses_every_write_op_and_allows_receiving() -> None:
    policy = SecurityPolicy(read_only=True)
    # Every op's own example (`Op.examples`): what it declares is what read-only judges.
    for op, cls in c.REQUEST_TYPES.items():
        args = dict(cls.examples[0].args)
        if cls.writes:
            with pytest.raises(ForbiddenError) as refused:
                check(policy, op, args)
            assert refused.value.error_code == ErrorCode.FORBIDDEN, op
            assert refused.value.field == "op" and "read-only" in str(refused.value), op
        elif cls.removes is None and not cls.to_client:  # removals: by who made the bridge
            check(policy, op, args)
    # Watching an action: its goal status topic.
    check(policy, "create_subscriber", {"topic": "/a/_action/status",
                                        "type": "action_msgs/msg/GoalStatusArray"})


def test_relative_names_are_judged_fully_qualified() -> None:
    policy = SecurityPolicy(topics=NameRules(deny=("/lab/cmd_vel",)))
    with pytest.raises(ForbiddenError) as refused:
        check(policy, "create_publisher", {"topic": "cmd_vel", "type": "geometry_msgs/msg/Twist"})
    assert refused.value.field == "topic" and refused.value.got == "/lab/cmd_vel"
    assert "'/lab/cmd_vel'" in str(refused.value)  # names the glob that denied it
    check(policy, "create_subscriber", {"topic": "odom", "type": "String"})


def test_service_globs() -> None:
    policy = SecurityPolicy(services=NameRules(allow=("/safe/*",)))
    check(policy, "call_service", {"service": "/safe/reset", "type": "std_srvs/srv/Trigger"})
    with pytest.raises(ForbiddenError) as refused:
        check(policy, "advertise_service", {"service": "/arm/enable",
                                            "type": "std_srvs/srv/SetBool"})
    assert refused.value.field == "service" and "/safe/*" in str(refused.value)


def test_parameters_are_judged_as_node_dot_name() -> None:
    policy = SecurityPolicy(parameters=NameRules(allow=("/robot_state_publisher.*",
                                                        "/lab/slicer_bridge.ui_*"),
                                                 deny=("*.use_sim_time",)))
    check(policy, "get_parameters", {"node": "/robot_state_publisher",
                                     "names": ["robot_description"]})
    with pytest.raises(ForbiddenError):
        check(policy, "get_parameters", {"node": "/robot_state_publisher",
                                         "names": ["robot_description", "use_sim_time"]})
    with pytest.raises(ForbiddenError) as refused:
        check(policy, "set_parameters", {"node": "/arm",
                                         "values": {"speed": {"type": "double", "value": 9.0}}})
    assert refused.value.got == "/arm.speed"
    # The daemon's own parameters are <its node>.<name>.
    check(policy, "server_set_parameter", {"name": "ui_colour",
                                           "value": {"type": "string", "value": "red"}})
    with pytest.raises(ForbiddenError):
        check(policy, "server_declare_parameter", {"name": "gain",
                                                   "value": {"type": "double", "value": 1.0}})
    # "All of them" cannot be judged name by name.
    with pytest.raises(ForbiddenError) as refused:
        check(policy, "server_get_parameters", {})
    assert refused.value.field == "names"


def test_read_only_clients_remove_nothing() -> None:
    policy = SecurityPolicy(read_only=True)
    removals = [op for op, cls in c.REQUEST_TYPES.items() if cls.removes is not None]
    assert len(removals) == len(c.bridge_kinds())
    for op in removals:
        identity = c.bridge_kinds()[c.REQUEST_TYPES[op].removes].bridge.identity
        args = {name: {"topic": "/t", "service": "/s", "node": "/n", "parent": "a",
                       "child": "b", "name": "r", "action": "/a"}[name] for name in identity}
        with pytest.raises(ForbiddenError) as refused:
            check(policy, op, args)
        assert refused.value.field == "op" and "remove nothing" in str(refused.value)


def test_no_client_removes_the_operators_bridges() -> None:
    owners, client, other = BridgeOwners(), object(), object()
    owners.created(("subscriber", ("/a",)), OPERATOR)
    owners.created(("subscriber", ("/b",)), client)
    owners.created(("subscriber", ("/a",)), client)  # asked again: still the operator's
    with pytest.raises(ForbiddenError) as refused:
        owners.check_removal(("subscriber", ("/a",)), "topic", other)
    assert refused.value.field == "topic" and "operator" in str(refused.value)
    owners.check_removal(("subscriber", ("/b",)), "topic", other)  # a client's: any client
    owners.check_removal(("subscriber", ("/a",)), "topic", None)  # the operator itself
    owners.forget(client, {"served_service"})
    assert owners.owner(("subscriber", ("/b",))) is client  # bridges outlive their client


def test_a_bridges_audience_is_its_holders_until_it_stays() -> None:
    """Who receives a bridge's streams (docs/security.md, "Who owns a bridge")."""
    owners, maker, joiner = BridgeOwners(), object(), object()
    mine, operators = ("subscriber", ("/mine",)), ("subscriber", ("/op",))
    owners.created(operators, OPERATOR)
    owners.created(operators, maker)  # asked for the operator's: it goes to everyone
    owners.created(mine, maker)
    assert owners.audience(operators) is None and owners.audience(mine) == {maker}
    owners.created(mine, joiner)
    assert owners.audience(mine) == {maker, joiner}
    owners.left(maker)
    assert owners.audience(mine) == {joiner}
    assert owners.keep(mine) and owners.audience(mine) is None


def test_a_request_class_the_schema_does_not_declare_is_refused() -> None:
    class Fake:  # looks like an op, is not one of the schema's
        op = "create_subscriber"
        writes = False
        removes = None
        to_client = False

        def resources(self) -> tuple:
            return ()

    with pytest.raises(ForbiddenError) as refused:
        SecurityPolicy().check_request(Fake(), "/n")  # type: ignore[arg-type]
    assert refused.value.field == "op" and refused.value.got == "Fake"
    # ... and the daemon's own messages to clients are not ops a client may send
    with pytest.raises(ForbiddenError):
        check(SecurityPolicy(), "service_request", {"service": "/s", "type": "a/B",
                                                    "request": {}})


@pytest.mark.parametrize("address,admitted", [
    ("127.0.0.1", True), ("10.1.2.3", True), ("192.168.0.1", False),
    ("::1", True), ("::ffff:10.0.0.7", True), ("fe80::1%eth0", False), ("garbage", False),
])
def test_networks(address: str, admitted: bool) -> None:
    policy = SecurityPolicy(allowed_networks=(ipaddress.ip_network("127.0.0.1/32"),
                                              ipaddress.ip_network("10.0.0.0/8"),
                                              ipaddress.ip_network("::1/128")))
    assert policy.admits(address) is admitted
    assert SecurityPolicy().admits(address)  # no --allow: any peer that reaches the socket


def test_loopback_hosts() -> None:
    assert is_loopback_host("127.0.0.1") and is_loopback_host("::1")
    assert is_loopback_host("localhost") and is_loopback_host("127.0.0.2")
    assert not is_loopback_host("0.0.0.0") and not is_loopback_host("::")
    assert not is_loopback_host("myhost.example") and not is_loopback_host("192.168.1.5")


def test_quota_counts_live_bridges_per_client() -> None:
    quota = BridgeQuota(2)
    a, b = object(), object()
    for _ in range(2):
        reserved = quota.reserve(a, "create_subscriber")
        quota.settle(a, reserved, succeeded=True, existed=False)
    with pytest.raises(LimitReachedError) as refused:
        quota.reserve(a, "create_tf_lookup")
    assert refused.value.error_code == ErrorCode.LIMIT_REACHED
    assert "at most 2 bridges per client" in str(refused.value)
    assert "--max-bridges-per-client" in str(refused.value)
    quota.settle(b, quota.reserve(b, "create_robot"), succeeded=False, existed=False)  # free
    quota.settle(b, quota.reserve(b, "create_robot"), succeeded=True, existed=True)
    assert quota.count(b) == 0
    assert not quota.reserve(a, "remove_subscriber")  # a removal takes no slot...
    quota.release(a)  # ... and frees one of the bridge's maker, whoever removed it
    assert quota.count(a) == 1
    assert not quota.reserve(a, "hello")  # not a creation: nothing to count
    quota.forget(a)
    assert quota.count(a) == 0


GRIPPER = "control_msgs/action/GripperCommand"


@pytest.mark.parametrize("op,args", [
    ("send_goal", {"action": "/arm/fjt", "type": GRIPPER}),
    ("cancel_goal", {"action": "arm/fjt", "goal_id": "0" * 32}),  # relative: /lab/arm/fjt
    ("advertise_action", {"action": "/arm/fjt", "type": GRIPPER}),
    ("action_feedback", {"action": "/arm/fjt", "goal_id": "0" * 32}),
    # The hidden services and topics an action is made of are the action too.
    ("call_service", {"service": "/arm/fjt/_action/send_goal",
                      "type": "std_srvs/srv/Trigger"}),
    ("call_service", {"service": "/arm/fjt/_action/cancel_goal",
                      "type": "action_msgs/srv/CancelGoal"}),
    ("advertise_service", {"service": "/arm/fjt/_action/get_result",
                           "type": "std_srvs/srv/Trigger"}),
    ("create_subscriber", {"topic": "/arm/fjt/_action/feedback", "type": "String"}),
    ("create_publisher", {"topic": "/arm/fjt/_action/status",
                          "type": "action_msgs/msg/GoalStatusArray"}),
    ("get_last_message", {"topic": "/arm/fjt/_action/status"}),
    ("publish", {"topic": "/arm/fjt/_action/feedback", "value": {}}),
])
def test_action_globs_judge_every_route_to_an_action(op: str, args: dict) -> None:
    for policy in (SecurityPolicy(actions=NameRules(deny=("/*/fjt",))),
                   SecurityPolicy(actions=NameRules(allow=("/safe/*",)))):
        with pytest.raises(ForbiddenError) as refused:
            check(policy, op, args)
        assert refused.value.got in ("/arm/fjt", "/lab/arm/fjt"), refused.value
        assert "action" in str(refused.value)
    check(SecurityPolicy(actions=NameRules(deny=("/other/*",))), op, args)


def test_action_globs_leave_look_alike_names_alone() -> None:
    policy = SecurityPolicy(actions=NameRules(deny=("/arm/*",)))
    check(policy, "call_service", {"service": "/arm/_action", "type": "std_srvs/srv/Trigger"})
    check(policy, "create_subscriber", {"topic": "/arm/_action/other", "type": "String"})
    check(policy, "list_actions", {})


def test_action_options_merge(tmp_path: Path) -> None:
    path = tmp_path / "bridge.yaml"
    path.write_text("security:\n  deny_actions: ['/arm/*']\n")
    policy, _ = build_security(load_config_file(path).security,
                               {"allow_actions": ["/arm/*", "/demo/*"]})
    assert policy.actions == NameRules(allow=("/arm/*", "/demo/*"), deny=("/arm/*",))
    assert "actions allow=" in policy.describe()


def test_command_line_and_config_file_merge(tmp_path: Path) -> None:
    path = tmp_path / "bridge.yaml"
    path.write_text("security:\n  read_only: false\n  allow: [10.0.0.0/8]\n"
                    "  deny_topics: ['/cmd_vel']\n  max_clients: 4\n  max_message_bytes: 1000\n"
                    "subscribers:\n  - {topic: /a, type: String}\n")
    file = load_config_file(path)
    assert [s.op for s in file.startup] == ["create_subscriber"]
    policy, limits = build_security(file.security, {
        "read_only": True, "allow": ["::1"], "deny_topics": ["/estop"], "max_clients": 2,
        "max_send_buffer_bytes": 5000, "max_bridges_per_client": None})
    assert policy.read_only
    assert [str(n) for n in policy.allowed_networks] == ["10.0.0.0/8", "::1/128"]
    assert policy.topics.deny == ("/cmd_vel", "/estop")
    assert policy.max_clients == 2  # the command line wins
    assert limits.max_message_bytes == 1000 and limits.max_oneshot_bytes == 5000


@pytest.mark.parametrize("section,message", [
    ("security: [1]", "must be a mapping"),
    ("security: {read_only: 'yes'}", "read_only: expected true or false"),
    ("security: {allow: [10.0.0.0/33]}", "expected an IPv4 or IPv6 address or CIDR"),
    ("security: {deny_topics: [3]}", "expected a list of non-empty strings"),
    ("security: {max_clients: 0}", "max_clients: expected a positive integer, got 0"),
    ("security: {max_client: 3}", "unknown key 'max_client'"),
])
def test_config_errors_name_the_key(tmp_path: Path, section: str, message: str) -> None:
    path = tmp_path / "bridge.yaml"
    path.write_text(section + "\n")
    with pytest.raises(ConfigError) as error:
        build_security(load_config_file(path).security, {})
    assert message in str(error.value)


# ---------------------------------------------------------------------------- tf frames

# Every op naming a client's frames (`Op.client_frames`) but removals, with its example's
# other arguments.
FRAME_OPS = {op: {k: v for k, v in cls.examples[0].args.items() if k not in ("parent", "child")}
             for op, cls in c.REQUEST_TYPES.items()
             if cls.client_frames == ("parent", "child") and cls.removes is None}


def test_every_tf_op_judges_both_frames_deny_wins_and_allow_lists() -> None:
    assert {"lookup_transform", "broadcast_transform"} <= set(FRAME_OPS)
    policy = SecurityPolicy(frames=NameRules(allow=("PSM1/*", "world"),
                                             deny=("PSM1/secret*",)))
    for op, extra in FRAME_OPS.items():
        check(policy, op, {"parent": "world", "child": "PSM1/tool", **extra})
        for args, field, got, glob in (
                ({"parent": "world", "child": "PSM1/secret_tool"}, "child",
                 "PSM1/secret_tool", "'PSM1/secret*'"),  # allowed by one glob, denied by another
                ({"parent": "PSM2/base", "child": "PSM1/tool"}, "parent", "PSM2/base",
                 "PSM1/*"),  # not in the allow list
                ({"parent": "world", "child": "/PSM1/secret_x"}, "child", "PSM1/secret_x",
                 "'PSM1/secret*'")):  # a leading / does not slip past
            with pytest.raises(ForbiddenError) as refused:
                check(policy, op, {**args, **extra})
            assert refused.value.error_code == ErrorCode.FORBIDDEN, op
            assert (refused.value.field, refused.value.got) == (field, got), op
            assert glob in str(refused.value) and "tf frame" in str(refused.value), op


def test_frames_are_judged_as_the_tf_buffer_resolves_them() -> None:
    # What the dispatcher maps a request's frames with under --frame-prefix PSM1/
    # (TfBridges.resolve_client_frame), before the policy sees them.
    def with_prefix(frame: str, field: str) -> str:
        return frame.lstrip("/") if frame.startswith("/") else "PSM1/" + frame

    policy = SecurityPolicy(frames=NameRules(allow=("PSM1/*",)))
    policy.check_request(parsed("create_tf_lookup", {"parent": "base", "child": "/PSM1/tool"})
                         .with_frames(with_prefix), "/n")
    with pytest.raises(ForbiddenError) as refused:
        policy.check_request(parsed("lookup_transform", {"parent": "base",
                                                         "child": "/PSM2/tool"})
                             .with_frames(with_prefix), "/n")
    assert (refused.value.field, refused.value.got) == ("child", "PSM2/tool")
    # Without a prefix, /world and world are one frame.
    assert strip_frame("/world") == strip_frame("world") == "world"


def test_frame_globs_leave_other_ops_and_removals_alone() -> None:
    policy = SecurityPolicy(frames=NameRules(deny=("*",)))
    check(policy, "remove_tf_lookup", {"parent": "a", "child": "b"})  # never created
    check(policy, "create_subscriber", {"topic": "/t", "type": "String"})
    check(policy, "create_robot", {"name": "r"})  # robot frames come from its URDF


# ---------------------------------------------------------------------------- robots


def robot(source: dict | None = None, namespace: str = "") -> dict:
    args: dict = {"name": "r"}
    if source is not None:
        args["source"] = source
    if namespace:
        args["namespace"] = namespace
    return args


@pytest.mark.parametrize("args,field,got", [
    (robot(), "source.parameter", "/robot_state_publisher.robot_description"),
    (robot(namespace="PSM2"), "source.parameter",  # a relative namespace is the daemon's
     "/lab/PSM2/robot_state_publisher.robot_description"),
    # relative: the robot's namespace (itself under the daemon's /lab), then the daemon's
    (robot({"kind": "parameter", "node": "rsp", "parameter": "urdf"}, "/PSM2"),
     "source.parameter", "/PSM2/rsp.urdf"),
    (robot({"kind": "parameter", "node": "rsp"}), "source.parameter", "/lab/rsp.robot_description"),
    # an absolute node other than the default keeps its name whatever the namespace
    (robot({"kind": "parameter", "node": "/PSM2/rsp"}, "PSM1"), "source.parameter",
     "/PSM2/rsp.robot_description"),
    (robot({"kind": "topic"}, "/PSM2"), "source.topic", "/PSM2/robot_description"),
    (robot({"kind": "topic", "topic": "/other/urdf"}, "/PSM1"), "source.topic", "/other/urdf"),
])
def test_robot_sources_are_judged_like_reading_them(args: dict, field: str, got: str) -> None:
    policy = SecurityPolicy(parameters=NameRules(allow=("/PSM1/*",)),
                            topics=NameRules(allow=("/PSM1/*",)))
    with pytest.raises(ForbiddenError) as refused:
        check(policy, "create_robot", args)
    assert refused.value.error_code == ErrorCode.FORBIDDEN
    assert (refused.value.field, refused.value.got) == (field, got)
    assert "/PSM1/*" in str(refused.value)


@pytest.mark.parametrize("args", [
    robot(namespace="/PSM1"),
    robot({"kind": "parameter", "node": "/PSM1/robot_state_publisher"}, "/PSM2"),
    robot({"kind": "topic"}, "/PSM1"),
    robot({"kind": "topic", "topic": "description"}, "/PSM1"),
])
def test_robot_sources_that_the_globs_allow(args: dict) -> None:
    check(SecurityPolicy(parameters=NameRules(allow=("/PSM1/*",)),
                         topics=NameRules(allow=("/PSM1/*",))), "create_robot", args)
    # read-only does not stop robots: they only receive
    check(SecurityPolicy(read_only=True), "create_robot", args)


def test_a_robot_file_is_judged_by_the_robot_dirs_not_the_globs() -> None:
    args = robot({"kind": "file", "path": "/opt/robots/psm.urdf"})
    with pytest.raises(ForbiddenError) as refused:  # no --robot-dir: no file (fail closed)
        check(SecurityPolicy(parameters=NameRules(allow=("/PSM1/*",))), "create_robot", args)
    assert refused.value.field == "source.path" and "--robot-dir" in str(refused.value)


def test_frame_options_merge_and_are_checked(tmp_path: Path) -> None:
    path = tmp_path / "bridge.yaml"
    path.write_text("security:\n  allow_frames: ['PSM1/*']\n  deny_frames: PSM1/secret*\n")
    policy, _ = build_security(load_config_file(path).security,
                               {"allow_frames": ["world"], "deny_frames": []})
    assert policy.frames == NameRules(allow=("PSM1/*", "world"), deny=("PSM1/secret*",))
    assert "frames allow=['PSM1/*', 'world']" in policy.describe()
    path.write_text("security: {deny_frames: [7]}\n")
    with pytest.raises(ConfigError) as error:
        build_security(load_config_file(path).security, {})
    assert "deny_frames: expected a list of non-empty strings" in str(error.value)


# ---------------------------------------------------------------------------- other routes


def call(service: str, kind: str, request: dict) -> dict:
    return {"service": service, "type": f"rcl_interfaces/srv/{kind}", "request": request}


def test_any_nodes_parameter_services_are_judged_by_the_parameter_globs() -> None:
    policy = SecurityPolicy(parameters=NameRules(allow=("/arm.speed",)))
    check(policy, "call_service", call("/arm/get_parameters", "GetParameters",
                                       {"names": ["speed"]}))
    for service, kind, request, got in (
            ("/arm/get_parameters", "GetParameters", {"names": ["speed", "limit"]},
             "/arm.limit"),
            ("arm/set_parameters", "SetParameters",  # relative: judged resolved
             {"parameters": [{"name": "limit", "value": {"type": 2}}]}, "/lab/arm.limit"),
            ("/arm/set_parameters_atomically", "SetParametersAtomically",
             {"parameters": [{"name": "limit"}]}, "/arm.limit"),
            ("/arm/describe_parameters", "DescribeParameters", {"names": ["limit"]},
             "/arm.limit"),
            ("/arm/get_parameter_types", "GetParameterTypes", {"names": ["limit"]},
             "/arm.limit"),
            ("/arm/get_parameters", "GetParameters", {}, "all parameters of /arm"),
            # a parameter type under another name is still a node's parameter service
            ("/arm/renamed", "GetParameters", {"names": ["limit"]}, "/arm.limit")):
        with pytest.raises(ForbiddenError) as refused:
            check(policy, "call_service", call(service, kind, request))
        assert refused.value.got == got, service
    # a parameter service name with another type: its names cannot be read, so refused
    with pytest.raises(ForbiddenError):
        check(policy, "call_service", {"service": "/arm/set_parameters",
                                       "type": "std_srvs/srv/Trigger"})
    # listing is allowed; its response shows only the allowed names
    check(policy, "call_service", call("/arm/list_parameters", "ListParameters", {}))
    response = {"result": {"names": ["speed", "limit"], "prefixes": ["lim"]}}
    listing = c.parse_request("call_service", c.dumps(
        call("/arm/list_parameters", "ListParameters", {})))
    assert policy.content_guard(listing).service_reply(response) == \
        {"result": {"names": ["speed"], "prefixes": []}}
    other = c.parse_request("call_service", c.dumps(call("/arm/get_parameters", "GetParameters",
                                                         {"names": ["speed"]})))
    assert policy.content_guard(other).service_reply(response) == response  # not a listing
    with pytest.raises(ForbiddenError):  # serving a node's parameters: all of them
        check(policy, "advertise_service", {"service": "/ghost/get_parameters",
                                            "type": "rcl_interfaces/srv/GetParameters"})
    # without parameter globs nothing changes
    check(SecurityPolicy(), "call_service", call("/arm/set_parameters", "SetParameters", {}))


class _Stamped:
    def __init__(self, parent: str, child: str) -> None:
        self.header = type("H", (), {"frame_id": parent})()
        self.child_frame_id = child


class _TfMessage:
    def __init__(self, transforms: list) -> None:
        self.transforms = transforms


def test_tf_topics_are_judged_transform_by_transform() -> None:
    policy = SecurityPolicy(frames=NameRules(allow=("PSM1/*", "world")))
    def messages(policy: SecurityPolicy, op: str, topic: str, ros_type: str):
        request = c.parse_request(op, c.dumps({"topic": topic, "type": ros_type}))
        guard = policy.content_guard(request)
        return guard.message_filter(), guard.message_check()

    keep, sent = messages(policy, "create_publisher", "/robot/tf",
                          "tf2_msgs/msg/TFMessage")  # by type
    assert keep is not None and sent is not None
    assert messages(policy, "create_subscriber", "/tf", "std_msgs/msg/String")[0] is not None
    assert messages(policy, "create_subscriber", "/x", "std_msgs/msg/String") == (None, None)
    assert messages(SecurityPolicy(), "create_subscriber", "/tf",
                    "tf2_msgs/msg/TFMessage") == (None, None)
    allowed, denied = _Stamped("world", "PSM1/tool"), _Stamped("/world", "PSM2/tool")
    kept = keep(_TfMessage([allowed, denied]))
    assert kept is not None and kept.transforms == [allowed]
    assert keep(_TfMessage([denied])) is None
    sent(_TfMessage([allowed]))
    with pytest.raises(ForbiddenError) as refused:
        sent(_TfMessage([allowed, denied]))
    assert (refused.value.field, refused.value.got) == \
        ("value.transforms[1].child_frame_id", "PSM2/tool")
    # only a TFMessage can be judged on a tf topic
    with pytest.raises(ForbiddenError) as refused:
        check(policy, "create_publisher", {"topic": "/tf", "type": "String"})
    assert refused.value.field == "type"


def test_robot_files_refused_and_missing_get_one_answer(tmp_path: Path) -> None:
    inside, outside = tmp_path / "robots", tmp_path / "elsewhere"
    inside.mkdir()
    outside.mkdir()
    (inside / "a.urdf").write_text("<robot/>")
    (outside / "b.urdf").write_text("<robot/>")
    (inside / "link.urdf").symlink_to(outside / "b.urdf")
    policy = SecurityPolicy(robot_dirs=(str(inside),))

    def judge(path: Path, from_client: bool = True) -> None:
        policy.check_request(parsed("create_robot", {
            "name": "r", "source": {"kind": "file", "path": str(path)}}), "/n",
            from_client=from_client, resolve_file=lambda spec: spec)

    judge(inside / "a.urdf")
    answers = []
    for path in (outside / "b.urdf", outside / "none.urdf", inside / "none.urdf",
                 inside / "link.urdf"):
        with pytest.raises(ForbiddenError) as refused:
            judge(path)
        answers.append(str(refused.value).replace(str(path), "P"))
    assert len(set(answers)) == 1, answers
    judge(outside / "b.urdf", from_client=False)  # the operator's config is trusted

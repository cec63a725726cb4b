"""The security policy on its own: name rules, networks, limits, config merging (no ROS)."""

from __future__ import annotations

import ipaddress
from pathlib import Path

import pytest

from bridge.config import ConfigError, build_security, load_config_file
from bridge.security import (BridgeQuota, NameRules, SecurityPolicy, TARGETS, WRITE_OPS,
                             is_loopback_host)
from protocol import commands as c
from protocol.commands import ErrorCode, ForbiddenError, LimitReachedError


def resolve(name: str, field: str) -> str:
    # What the daemon does with namespace "/lab": relative names go under it.
    return name if name.startswith("/") else "/lab/" + name


def check(policy: SecurityPolicy, op: str, args: dict) -> None:
    policy.check_request(c.parse_request(op, c.dumps(args)), resolve, "/lab/slicer_bridge")


def test_deny_wins_and_any_allow_glob_makes_an_allow_list() -> None:
    rules = NameRules(allow=("/robot/*",), deny=("/robot/cmd_*",))
    assert rules.permits("/robot/joint_states")
    assert not rules.permits("/robot/cmd_vel")  # allowed by a glob, denied by another
    assert not rules.permits("/camera/image")  # not in the allow list
    assert NameRules(deny=("/cmd_vel",)).permits("/camera/image")  # deny only: rest allowed
    assert NameRules().permits("/anything")


def test_read_only_refuses_every_write_op_and_allows_receiving() -> None:
    policy = SecurityPolicy(read_only=True)
    writes = {
        "create_publisher": {"topic": "/t", "type": "String"},
        "publish": {"topic": "/t", "value": "x"},
        "create_tf_broadcaster": {"parent": "a", "child": "b"},
        "broadcast_transform": {"parent": "a", "child": "b",
                                "matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0],
                                           [0, 0, 0, 1]]},
        "set_parameters": {"node": "/n", "values": {"p": {"type": "integer", "value": 1}}},
        "server_declare_parameter": {"name": "p", "value": {"type": "integer", "value": 1}},
        "server_set_parameter": {"name": "p", "value": {"type": "integer", "value": 1}},
        "server_undeclare_parameter": {"name": "p"},
        "call_service": {"service": "/s", "type": "std_srvs/srv/Trigger"},
        "advertise_service": {"service": "/s", "type": "std_srvs/srv/Trigger"},
    }
    assert set(writes) == WRITE_OPS
    for op, args in writes.items():
        with pytest.raises(ForbiddenError) as refused:
            check(policy, op, args)
        assert refused.value.error_code == ErrorCode.FORBIDDEN
        assert refused.value.field == "op" and "read-only" in str(refused.value)
    for op, args in {"create_subscriber": {"topic": "/t", "type": "String"},
                     "create_tf_lookup": {"parent": "a", "child": "b"},
                     "get_parameters": {"node": "/n", "names": ["p"]},
                     "hello": {}}.items():
        check(policy, op, args)


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


def test_every_judged_field_exists_on_its_request_class() -> None:
    for op, target in TARGETS.items():
        names = {f for f in c.REQUEST_TYPES[op].__dataclass_fields__}
        assert target.field in names, op
        assert target.node_field is None or target.node_field in names, op


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
        quota.settle(a, "create_subscriber", reserved, {"existed": False})
    with pytest.raises(LimitReachedError) as refused:
        quota.reserve(a, "create_tf_lookup")
    assert refused.value.error_code == ErrorCode.LIMIT_REACHED
    assert "at most 2 bridges per client" in str(refused.value)
    assert "--max-bridges-per-client" in str(refused.value)
    quota.settle(b, "create_robot", quota.reserve(b, "create_robot"), None)  # failed: free
    quota.settle(b, "create_robot", quota.reserve(b, "create_robot"), {"existed": True})
    assert quota.count(b) == 0
    quota.settle(a, "remove_subscriber", quota.reserve(a, "remove_subscriber"), {})
    assert quota.count(a) == 1
    assert not quota.reserve(a, "hello")  # not a creation: nothing to count
    quota.forget(a)
    assert quota.count(a) == 0


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

"""Device names and ros2.* metadata (protocol/naming.py)."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from protocol.header import TDATA_NAME_MAX_BYTES
from protocol.naming import (
    DEFAULT_HASH_LENGTH,
    KEY_CHILD,
    KEY_FRAME,
    KEY_LINK,
    KEY_PARENT,
    KEY_ROBOT,
    KEY_ROLE,
    KEY_TOPIC,
    KEY_TYPE,
    KEY_UNITS,
    KEY_VISUAL,
    MAX_DEVICE_NAME_BYTES,
    METADATA_KEYS,
    DeviceNameRegistry,
    NameKey,
    NamingError,
    Role,
    device_name_for,
    is_hashed_name,
    key_from_metadata,
    metadata_for,
)


@pytest.mark.parametrize(
    ("key", "name"),
    [
        (NameKey.subscriber("/tool"), "tool"),
        (NameKey.subscriber("tool"), "tool"),
        (NameKey.subscriber("/PSM1/measured_cp"), "PSM1/measured_cp"),
        (NameKey.subscriber_messages("/tool"), "msg:tool"),
        (NameKey.publisher("/tool"), "pub:tool"),
        (NameKey.tf_lookup("world", "tool"), "tf:world>tool"),
        (NameKey.tf_broadcaster("world", "tool"), "tfb:world>tool"),
        (NameKey.robot_link("PSM1", "base_link"), "PSM1:base_link"),
        (NameKey.robot_visual("PSM1", "base_link", 2), "PSM1:base_link:2"),
        (NameKey.robot_description("PSM1"), "urdf:PSM1"),
        (NameKey.robot_poses("PSM1"), "poses:PSM1"),
        (NameKey.parameter_client("/turtlesim"), "param:turtlesim"),
        (NameKey.parameter_server("/slicer"), "params:slicer"),
        (NameKey.service_client("/spawn"), "srvc:spawn"),
        (NameKey.service_server("/spawn"), "srv:spawn"),
        (NameKey.action_server("/fjt"), "act:fjt"),
    ],
)
def test_short_names_stay_readable(key: NameKey, name: str) -> None:
    assert device_name_for(key) == name
    assert not is_hashed_name(name)


def test_lookup_and_subscriber_of_same_name_do_not_collide() -> None:
    names = {
        device_name_for(NameKey.subscriber("/tool")),
        device_name_for(NameKey.publisher("/tool")),
        device_name_for(NameKey.tf_lookup("world", "tool")),
        device_name_for(NameKey.tf_broadcaster("world", "tool")),
        device_name_for(NameKey.robot_link("world", "tool")),
        device_name_for(NameKey.parameter_client("/tool")),
    }
    assert len(names) == 6


def test_long_topics_shorten_their_namespaces_then_hash() -> None:
    key = NameKey.subscriber("/my_robot/arm/end_effector/measured_pose")
    name = device_name_for(key)
    assert len(name.encode("ascii")) <= MAX_DEVICE_NAME_BYTES
    assert is_hashed_name(name)
    body, digest = name.split("~")
    assert len(digest) == DEFAULT_HASH_LENGTH
    # Initials do not fit ("m/a/e/measured_pose"): the last name, which says the most, stays.
    assert body == "measured_pose"
    # sha256-based: the same on every run and machine (hash() would be salted).
    assert name == device_name_for(NameKey.subscriber("my_robot/arm/end_effector/measured_pose"))
    assert device_name_for(NameKey.subscriber("/robot/arm/measured_cp")).startswith(
        "r/a/measured_cp~")
    assert device_name_for(NameKey.publisher("/my_robot/arm/end_effector/measured_pose")) != name


def test_hash_is_stable_across_versions() -> None:
    # Pinned: changing it would orphan users' saved Slicer scenes. (Changed once: a robot
    # link's device names its element in the robot's TDATA, which Slicer's library reads
    # only up to 19 bytes; it was "PSM1:tool_tip_l~gafc".)
    assert device_name_for(NameKey.robot_link("PSM1", "tool_tip_link_very_long")) == (
        "PSM1:tool_tip_~gafc")
    assert device_name_for(NameKey.robot_visual("PSM1", "tool_tip_link_very_long", 0)) == (
        "PSM1:tool_tip~yyll:0")  # unchanged: a visual is no TDATA element


def test_a_robot_link_s_device_fits_a_tdata_element_name_slicer_reads() -> None:
    for link in ("tool_tip_link_very_long", "a" * 40, "wrist_3_link", "base"):
        for robot in ("PSM1", "saved_arm", "r" * 30):
            name = device_name_for(NameKey.robot_link(robot, link))
            assert len(name.encode()) <= TDATA_NAME_MAX_BYTES == 19, name


@pytest.mark.parametrize(
    ("key", "name"),
    [
        # The cases a plain OpenIGTLinkIF user met (issue: `er_arm_link:0~dk4syk`).
        (NameKey.robot_visual("demo", "upper_arm_link", 0), "demo:upper_ar~dk4s:0"),
        (NameKey.tf_lookup("base_link", "tool_flange"), "tf:base>tool_fl~ndef"),
        # Long frames: noise suffixes go first, then namespaces, then the ends of names.
        (NameKey.tf_lookup("world", "PSM1/tool_tip_link"), "tf:world>tool_t~ubma"),
        (NameKey.tf_broadcaster("camera_optical_frame", "marker_7"), "tfb:camera>mark~74ab"),
        # A robot's name is cut to 6 characters before the link goes below 3.
        (NameKey.robot_visual("dvrk_PSM1", "tool_wrist_sca_shaft_link", 3),
         "dvrk_P:tool_w~djqj:3"),
        (NameKey.robot_description("a_very_long_robot_name_here"), "urdf:a_very_lon~kymh"),
    ],
)
def test_long_names_are_abbreviated_readable_first(key: NameKey, name: str) -> None:
    assert device_name_for(key) == name
    assert len(name) <= MAX_DEVICE_NAME_BYTES


def _robot_links(urdf: str) -> list[str]:
    import xml.etree.ElementTree as ElementTree

    return [link.get("name", "") for link in ElementTree.fromstring(urdf).iter("link")]


def _demo_links() -> list[str]:
    from bridge.robots.demo.urdf import DEMO_URDF

    return _robot_links(DEMO_URDF)


def _omni_links() -> list[str]:
    from support import require_shared

    urdf = require_shared("robots/sensable_omni_model/urdf/omni.urdf")
    return _robot_links(urdf.read_text())


@pytest.mark.parametrize(("robot", "links"), [("demo", _demo_links), ("omni", _omni_links),
                                               ("sensable_omni_model", _omni_links)])
def test_robot_names_keep_the_link_start_and_the_visual_index(robot: str, links: object) -> None:
    registry = DeviceNameRegistry()
    names: set[str] = set()
    for link in links():  # type: ignore[operator]
        for index in (0, 1, 12):
            key = NameKey.robot_visual(robot, link, index)
            name = registry.register(key)
            assert len(name.encode("ascii")) <= MAX_DEVICE_NAME_BYTES
            assert name.endswith(f":{index}")
            if not is_hashed_name(name):
                assert name == f"{robot}:{link}:{index}"
                continue
            robot_part, link_part = name.split("~")[0].split(":")
            assert robot.startswith(robot_part) and len(robot_part) >= 3
            # The link's start survives (less a `_link` suffix), never only its end.
            assert link.startswith(link_part) and len(link_part) >= 3
            names.add(name)
        link_name = registry.register(NameKey.robot_link(robot, link))
        assert len(link_name) <= MAX_DEVICE_NAME_BYTES
        if is_hashed_name(link_name):
            assert link.startswith(link_name.split("~")[0].split(":")[1])
    assert len(registry) == len(set(registry))


def test_separator_characters_force_hashing() -> None:
    a = NameKey.tf_lookup("a>b", "c")
    b = NameKey.tf_lookup("a", "b>c")
    assert device_name_for(a) != device_name_for(b)
    assert is_hashed_name(device_name_for(a)) and is_hashed_name(device_name_for(b))


def test_reserved_robot_name_cannot_pose_as_publisher() -> None:
    assert device_name_for(NameKey.robot_link("pub", "x")) != device_name_for(
        NameKey.publisher("/x"))
    assert is_hashed_name(device_name_for(NameKey.robot_link("pub", "x")))


def test_non_ascii_frames_become_ascii() -> None:
    name = device_name_for(NameKey.tf_lookup("wörld", "werkzeug"))
    name.encode("ascii")
    assert is_hashed_name(name)
    assert name != device_name_for(NameKey.tf_lookup("w_rld", "werkzeug"))


ros_text = st.text(min_size=1, max_size=80).filter(lambda s: "\x00" not in s and s.strip("/"))


@given(st.lists(st.tuples(ros_text, ros_text), min_size=1, max_size=30))
def test_registry_names_always_fit_and_are_unique(pairs: list[tuple[str, str]]) -> None:
    registry = DeviceNameRegistry()
    keys = {NameKey.tf_lookup(p, c) for p, c in pairs} | {NameKey.subscriber(p) for p, _ in pairs}
    names = {}
    for key in keys:
        name = registry.register(key)
        name.encode("ascii")
        assert 0 < len(name) <= MAX_DEVICE_NAME_BYTES
        names[name] = key
        assert registry.lookup(name) == key
    assert len(names) == len(keys)


class _CollidingRegistry(DeviceNameRegistry):
    """Every shortest hash is the same: forces the collision path."""

    def _candidate(self, key: NameKey, hash_length: int) -> str:
        name = super()._candidate(key, hash_length)
        if hash_length == DEFAULT_HASH_LENGTH and is_hashed_name(name):
            return "topic~" + "a" * DEFAULT_HASH_LENGTH
        return name


def test_forced_collision_lengthens_hash() -> None:
    registry = _CollidingRegistry()
    first = NameKey.subscriber("/a/very/long/namespace/one/topic")
    second = NameKey.subscriber("/another/long/namespace/two/topic")
    n1 = registry.register(first)
    n2 = registry.register(second)
    assert n1 == "topic~" + "a" * DEFAULT_HASH_LENGTH
    assert n2 != n1 and n2.startswith("a/l/n/t/topic~")
    assert len(n2.split("~")[1]) == DEFAULT_HASH_LENGTH + 1
    assert len(n2) <= MAX_DEVICE_NAME_BYTES
    assert registry.lookup(n1) == first
    assert registry.lookup(n2) == second
    # Idempotent, and releasing frees the name for its key only.
    assert registry.register(second) == n2
    assert registry.release(first) == n1
    assert n1 not in registry
    assert registry.lookup(n1) is None
    assert registry.release(first) is None
    assert len(registry) == 1


def test_registry_basic_mapping() -> None:
    registry = DeviceNameRegistry()
    key = NameKey.tf_lookup("world", "tool")
    assert registry.name_of(key) is None
    name = registry.register(key)
    assert name == "tf:world>tool"
    assert name in registry
    assert registry.name_of(key) == name
    assert dict(iter(registry)) == {name: key}
    assert key.named_parts() == {KEY_PARENT: "world", KEY_CHILD: "tool"}


def test_metadata_for_subscriber() -> None:
    meta = metadata_for(NameKey.subscriber("tool"), ros_type="geometry_msgs/msg/PoseStamped",
                        frame="world", units="mm")
    assert meta == {
        KEY_ROLE: "subscriber",
        KEY_TOPIC: "/tool",
        KEY_TYPE: "geometry_msgs/msg/PoseStamped",
        KEY_FRAME: "world",
        KEY_UNITS: "mm",
    }
    assert set(meta) <= set(METADATA_KEYS)
    for k in meta:
        k.encode("ascii")


def test_metadata_for_robot_visual() -> None:
    meta = metadata_for(NameKey.robot_visual("PSM1", "tool", 0), units="mm")
    assert meta[KEY_ROBOT] == "PSM1" and meta[KEY_LINK] == "tool" and meta[KEY_VISUAL] == "0"
    assert meta[KEY_ROLE] == "robot_visual"


ALL_KEYS = [
    NameKey.subscriber("/a/b"), NameKey.subscriber_messages("/a/b"), NameKey.publisher("x"),
    NameKey.tf_lookup("w", "t"),
    NameKey.tf_broadcaster("wörld", "t"), NameKey.robot_link("R", "l"),
    NameKey.robot_visual("R", "l", 3), NameKey.robot_description("R"),
    NameKey.robot_poses("R"), NameKey.parameter_client("/n"), NameKey.parameter_server("/s"),
    NameKey.service_client("/c"), NameKey.service_server("/c"),
    NameKey.marker("/m", "", 0), NameKey.marker("/m", "ns x", -3),
    NameKey.marker_frame("world", "base"), NameKey.marker_topic("/m"),
    NameKey.action_server("/a"), NameKey.action_goal("/a", "0123456789abcdef0123456789abcdef"),
]


@pytest.mark.parametrize(("key", "name"), [
    (NameKey.marker("/markers", "shapes", 3), "mk:markers:shapes:3"),
    (NameKey.marker("/markers", "", 0), "mk:markers::0"),
    (NameKey.marker("/visualization_marker", "", -12), "mk:visualiz~u2x7:-12"),
    (NameKey.marker_frame("world", "base_link"), "mkf:world>base_link"),
    (NameKey.marker_topic("/markers"), "mks:markers"),
])
def test_marker_names_are_readable_and_keep_the_id(key: NameKey, name: str) -> None:
    assert device_name_for(key) == name
    many = {device_name_for(NameKey.marker("/visualization_marker_array", ns, i))
            for ns in ("", "a", "b") for i in range(50)}
    assert len(many) == 150 and all(len(n) <= 20 for n in many)



def test_goal_devices_are_short_readable_and_one_per_goal() -> None:
    first = NameKey.action_goal("/arm/follow_joint_trajectory", "3f2a" + "0" * 28)
    second = NameKey.action_goal("/arm/follow_joint_trajectory", "3f2a" + "1" * 28)
    names = [device_name_for(first), device_name_for(second)]
    assert all(n.startswith("goal:follow") and ":3f2" in n for n in names), names
    assert all(len(n.encode()) <= 20 and is_hashed_name(n) for n in names)
    assert names[0] != names[1]
    meta = metadata_for(first)
    assert meta["ros2.action"] == "/arm/follow_joint_trajectory"
    assert meta["ros2.goal_id"] == "3f2a" + "0" * 28 and meta["ros2.role"] == "action_goal"
    assert key_from_metadata(meta) == first


def test_every_role_has_an_example() -> None:
    assert {k.role for k in ALL_KEYS} == set(Role)


@pytest.mark.parametrize("key", ALL_KEYS, ids=lambda k: k.role.value)
def test_metadata_round_trip(key: NameKey) -> None:
    assert key_from_metadata(metadata_for(key)) == key


@pytest.mark.parametrize(
    ("build", "fld"),
    [
        (lambda: NameKey.subscriber("/"), KEY_TOPIC),
        (lambda: NameKey.subscriber(""), KEY_TOPIC),
        (lambda: NameKey.tf_lookup("world", ""), KEY_CHILD),
        (lambda: NameKey.robot_visual("R", "l", -1), KEY_VISUAL),
        (lambda: NameKey.robot_link("R", 3), KEY_LINK),
        (lambda: NameKey(Role.TF_LOOKUP, ("only",)), "parts"),
        (lambda: key_from_metadata({KEY_ROLE: "nope"}), KEY_ROLE),
        (lambda: key_from_metadata({KEY_ROLE: "tf_lookup", KEY_PARENT: "w"}), KEY_CHILD),
        (lambda: device_name_for(NameKey.subscriber("x" * 40), hash_length=2), "hash_length"),
    ],
)
def test_errors_name_their_field(build: object, fld: str) -> None:
    with pytest.raises(NamingError) as info:
        build()  # type: ignore[operator]
    assert info.value.field == fld

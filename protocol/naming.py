"""OpenIGTLink device names for ROS entities, and the metadata that carries the full names.

A device name is at most 20 bytes and 3D Slicer uses it as the MRML node name (and finds
the node again by it after a reconnect), so a name must be short, readable, stable across
runs and machines, and never shared by two different ROS entities.

Scheme (every role has its own shape, so roles never collide):

====================  =========================  ============================
role                  ROS identity               readable device name
====================  =========================  ============================
subscriber            topic ``/tool``            ``tool``
publisher             topic ``/cmd``             ``pub:cmd``
tf_lookup             parent, child              ``tf:world>tool``
tf_broadcaster        parent, child              ``tfb:world>tool``
robot_link            robot, link                ``PSM1:base_link``
robot_visual          robot, link, index         ``PSM1:base_link:0``
robot_description     robot                      ``urdf:PSM1``
robot_poses           robot                      ``poses:PSM1``
parameter_client      node ``/rsp``              ``param:rsp``
parameter_server      node (the daemon's)        ``params:bridge``
service_client        service ``/spawn``         ``srvc:spawn``
service_server        service ``/spawn``         ``srv:spawn``
marker                topic, ns, id              ``mk:markers:shapes:3``
marker_frame          fixed frame, frame         ``mkf:world>base``
marker_topic          topic ``/markers``         ``mks:markers``
action_server         action ``/fjt``            ``act:fjt``
action_goal           action, goal UUID (hex)    ``goal:fjt:3f2~k2xq``
====================  =========================  ============================

A marker's ``ns`` may be empty (``mk:markers::0``); its id is kept last when the name must
be abbreviated, as a robot visual's index. An action goal's UUID never fits: its device is
always the abbreviated form (the action, the UUID's first hex digits, a hash), unique per
goal; ``ros2.goal_id`` has the whole UUID.

* A leading ``/`` is dropped (topics, node names, services and frames are taken as
  absolute: ``/tool`` and ``tool`` are the same); inner ``/`` of namespaces is kept.
* The readable form is used only when it fits in 20 bytes and every part is made of
  ``A-Z a-z 0-9 _ . / -`` (and a robot name is not one of the role prefixes). Those
  characters exclude the separators ``: > ~``, so two different entities can never share a
  readable name.
* Otherwise the name is abbreviated, readable first, then made unique with a short hash:
  ``<prefix><abbreviation>~<hash>`` (a robot visual keeps its index last:
  ``demo:upper_ar~dk4s:0``). The abbreviation keeps the shape of the readable form:
  link and frame names lose a ``_link``/``_frame`` suffix; namespaces become initials
  (``/robot/arm/measured_cp`` -> ``r/a/measured_cp``), then go; then parts are cut from
  their ends: a robot's name or a parent frame first, down to 6 characters (they are
  shared by many devices; the link or child frame tells them apart), then the others, then
  the first again; each keeps at least its first 3 characters. The hash is base32
  SHA-256 of the role and the exact ROS names, so it is the same on every run and machine.
  Only these names contain ``~``.
* `DeviceNameRegistry` remembers what it handed out; if two entities' names ever collide,
  the later one gets a longer hash, and it maps device names back to the ROS entity.

Every message also carries metadata ``ros2.*`` with the full names (see `metadata_for`);
3D Slicer copies it onto the node as attributes ``OpenIGTLink.<key>``.
"""

from __future__ import annotations

import base64
import enum
import hashlib
import re
from collections.abc import Iterator
from dataclasses import dataclass

from protocol.errors import ProtocolError
from protocol.header import TDATA_NAME_MAX_BYTES

__all__ = [
    "DEFAULT_HASH_LENGTH",
    "KEY_ACTION",
    "KEY_CHILD",
    "KEY_COLOR",
    "KEY_COUNT",
    "KEY_DROPPED",
    "KEY_ENCODING",
    "KEY_FORMAT",
    "KEY_LABELS",
    "KEY_LINK_COUNT",
    "KEY_LINK_DEVICES",
    "KEY_LINE_WIDTH",
    "KEY_MARKER_ID",
    "KEY_MARKER_NS",
    "KEY_MARKER_TYPE",
    "KEY_MARKERS",
    "KEY_DELETED",
    "KEY_POINT_COLORS",
    "KEY_POINT_SIZE",
    "KEY_POSITION",
    "KEY_TEXT_HEIGHT",
    "KEY_VISUAL_COUNT",
    "KEY_WARNINGS",
    "KEY_FRAME",
    "KEY_GOAL_ID",
    "KEY_GOAL_STATUS",
    "KEY_LINK",
    "KEY_MARKER_ID",
    "KEY_MARKER_NS",
    "KEY_NODE",
    "KEY_PARENT",
    "KEY_PARENT_DEVICE",
    "KEY_ROBOT",
    "KEY_ROLE",
    "KEY_SERVICE",
    "KEY_SHAPE",
    "KEY_TOPIC",
    "KEY_TYPE",
    "KEY_UNITS",
    "KEY_VISUAL",
    "MAX_DEVICE_NAME_BYTES",
    "METADATA_KEYS",
    "UNITS_MM",
    "DeviceNameRegistry",
    "NameKey",
    "NamingError",
    "Role",
    "device_name_for",
    "is_hashed_name",
    "key_from_metadata",
    "metadata_for",
]

MAX_DEVICE_NAME_BYTES = 20
# 4 base32 characters = 20 bits. Two names collide only if their abbreviations match too,
# and the registry resolves even that by lengthening the newcomer's hash.
DEFAULT_HASH_LENGTH = 4
_MAX_HASH_LENGTH = 16
_HASH_SEPARATOR = "~"

_SAFE_PART = re.compile(r"[A-Za-z0-9_./-]+\Z")
_UNSAFE_CHAR = re.compile(r"[^A-Za-z0-9_./-]")
# Dropped from link and frame names before anything is cut: they say nothing in a name.
_NOISE_SUFFIXES = ("_link", "_frame")
_MIN_KEPT = 3  # an abbreviated part keeps at least this many leading characters
_SHORT_NAME = 6  # a robot's or parent frame's name is cut to this before the others


class NamingError(ProtocolError):
    """A ROS name cannot be turned into a device name (empty, wrong count of parts...)."""


class Role(str, enum.Enum):
    """What a device name stands for; also the value of metadata ``ros2.role``."""

    SUBSCRIBER = "subscriber"
    SUBSCRIBER_MESSAGES = "subscriber_messages"
    PUBLISHER = "publisher"
    TF_LOOKUP = "tf_lookup"
    TF_BROADCASTER = "tf_broadcaster"
    ROBOT_LINK = "robot_link"
    ROBOT_VISUAL = "robot_visual"
    ROBOT_DESCRIPTION = "robot_description"
    ROBOT_POSES = "robot_poses"  # every link's pose in one TDATA (elements: link devices)
    PARAMETER_CLIENT = "parameter_client"
    PARAMETER_SERVER = "parameter_server"
    SERVICE_CLIENT = "service_client"
    SERVICE_SERVER = "service_server"
    MARKER = "marker"
    MARKER_FRAME = "marker_frame"
    MARKER_TOPIC = "marker_topic"
    ACTION_SERVER = "action_server"
    ACTION_GOAL = "action_goal"


# Prefix of the readable form, and the names of the parts (also their metadata keys).
_PREFIX: dict[Role, str] = {
    Role.SUBSCRIBER: "",
    Role.SUBSCRIBER_MESSAGES: "msg:",
    Role.PUBLISHER: "pub:",
    Role.TF_LOOKUP: "tf:",
    Role.TF_BROADCASTER: "tfb:",
    Role.ROBOT_LINK: "",
    Role.ROBOT_VISUAL: "",
    Role.ROBOT_DESCRIPTION: "urdf:",
    Role.ROBOT_POSES: "poses:",
    Role.PARAMETER_CLIENT: "param:",
    Role.PARAMETER_SERVER: "params:",
    Role.SERVICE_CLIENT: "srvc:",
    Role.SERVICE_SERVER: "srv:",
    Role.MARKER: "mk:",
    Role.MARKER_FRAME: "mkf:",
    Role.MARKER_TOPIC: "mks:",
    Role.ACTION_SERVER: "act:",
    Role.ACTION_GOAL: "goal:",
}
_RESERVED_ROBOT_NAMES = frozenset(p.rstrip(":") for p in _PREFIX.values() if p)

KEY_TOPIC = "ros2.topic"
KEY_TYPE = "ros2.type"
KEY_FRAME = "ros2.frame"
KEY_PARENT = "ros2.parent"
KEY_CHILD = "ros2.child"
KEY_ROBOT = "ros2.robot"
KEY_LINK = "ros2.link"
KEY_VISUAL = "ros2.visual"
KEY_NODE = "ros2.node"
KEY_SERVICE = "ros2.service"
KEY_ROLE = "ros2.role"
KEY_ACTION = "ros2.action"
KEY_GOAL_ID = "ros2.goal_id"  # a goal's UUID, 32 lower-case hex digits
KEY_GOAL_STATUS = "ros2.status"  # a goal event's status (accepted, executing, succeeded...)
KEY_UNITS = "ros2.units"
# A robot visual's model: the device of the link it goes under (its TDATA element), and its colour
# ("r g b a", floats 0..1), so a Slicer script can parent and colour it from attributes.
KEY_PARENT_DEVICE = "ros2.parent_device"
KEY_COLOR = "ros2.color"
# On a robot's description device (STATUS OK once loaded): how many links and visuals it has.
KEY_LINK_COUNT = "ros2.links"
# A loaded robot's links: JSON {link: device}, its elements' names in the robot's TDATA.
KEY_LINK_DEVICES = "ros2.link_devices"
KEY_VISUAL_COUNT = "ros2.visuals"
KEY_WARNINGS = "ros2.warnings"  # JSON list of the load's warnings (missing meshes...)
# What the codecs add about a message's content.
KEY_SHAPE = "ros2.shape"  # "2x3": shape of a multi-array / table
KEY_ENCODING = "ros2.encoding"  # sensor_msgs/Image encoding of the ROS side ("bgr8")
KEY_FORMAT = "ros2.format"  # "text" or "json": how to read a STRING body
KEY_LABELS = "ros2.labels"  # JSON list of MultiArrayDimension labels
KEY_DROPPED = "ros2.dropped"  # points left out of a cloud for a NaN/inf coordinate
# On a subscriber's message stream (``msg:`` devices): how many messages the daemon's
# subscription had received when it sent this one (exact even when a slow client's
# stream was coalesced).
KEY_COUNT = "ros2.count"
# A marker's identity and kind (visualization_msgs/Marker ns, id, and its type as a word:
# "cube", "line_strip", ..., or "path", "polygon", "point" for the other marker sources).
# A model sent from Slicer as a Marker takes its ns and id from the same two keys.
KEY_MARKER_NS = "ros2.ns"
KEY_MARKER_ID = "ros2.id"
KEY_MARKER_TYPE = "ros2.marker_type"
# A TEXT_VIEW_FACING marker is a STRING (its text) placed by these: "x y z" mm in the marker's
# frame, and the text height in mm (scale.z).
KEY_POSITION = "ros2.position"
KEY_TEXT_HEIGHT = "ros2.text_height"
KEY_LINE_WIDTH = "ros2.line_width"  # mm: LINE_STRIP/LINE_LIST scale.x
KEY_POINT_SIZE = "ros2.point_size"  # mm: "w h" of POINTS (scale.x, scale.y)
# "1" when a model's RGBA point colours differ (per-point colours): show them directly.
KEY_POINT_COLORS = "ros2.point_colors"
# On a marker topic's device (STATUS): JSON lists of the devices of the live markers and of
# those just deleted (DELETE, DELETEALL, lifetime): the client removes what is not live.
KEY_MARKERS = "ros2.markers"
KEY_DELETED = "ros2.deleted"
METADATA_KEYS: tuple[str, ...] = (
    KEY_TOPIC, KEY_TYPE, KEY_FRAME, KEY_PARENT, KEY_CHILD, KEY_ROBOT, KEY_LINK,
    KEY_VISUAL, KEY_NODE, KEY_SERVICE, KEY_ROLE, KEY_UNITS, KEY_PARENT_DEVICE, KEY_COLOR,
    KEY_LINK_COUNT, KEY_LINK_DEVICES, KEY_VISUAL_COUNT, KEY_WARNINGS, KEY_MARKER_NS, KEY_MARKER_ID,
    KEY_MARKER_TYPE, KEY_ACTION, KEY_GOAL_ID, KEY_GOAL_STATUS,
)
UNITS_MM = "mm"

_PART_KEYS: dict[Role, tuple[str, ...]] = {
    Role.SUBSCRIBER: (KEY_TOPIC,),
    Role.SUBSCRIBER_MESSAGES: (KEY_TOPIC,),
    Role.PUBLISHER: (KEY_TOPIC,),
    Role.TF_LOOKUP: (KEY_PARENT, KEY_CHILD),
    Role.TF_BROADCASTER: (KEY_PARENT, KEY_CHILD),
    Role.ROBOT_LINK: (KEY_ROBOT, KEY_LINK),
    Role.ROBOT_VISUAL: (KEY_ROBOT, KEY_LINK, KEY_VISUAL),
    Role.ROBOT_DESCRIPTION: (KEY_ROBOT,),
    Role.ROBOT_POSES: (KEY_ROBOT,),
    Role.PARAMETER_CLIENT: (KEY_NODE,),
    Role.PARAMETER_SERVER: (KEY_NODE,),
    Role.SERVICE_CLIENT: (KEY_SERVICE,),
    Role.SERVICE_SERVER: (KEY_SERVICE,),
    Role.MARKER: (KEY_TOPIC, KEY_MARKER_NS, KEY_MARKER_ID),
    Role.MARKER_FRAME: (KEY_PARENT, KEY_CHILD),
    Role.MARKER_TOPIC: (KEY_TOPIC,),
    Role.ACTION_SERVER: (KEY_ACTION,),
    Role.ACTION_GOAL: (KEY_ACTION, KEY_GOAL_ID),
}
# Parts that are absolute ROS graph names: metadata gives them with their leading '/'.
_GRAPH_NAME_KEYS = frozenset({KEY_TOPIC, KEY_NODE, KEY_SERVICE, KEY_ACTION})


def _strip(name: str) -> str:
    return name.lstrip("/")


@dataclass(frozen=True)
class NameKey:
    """The ROS identity behind one device name: a role and its normalised name parts.

    Build it with the class methods (``NameKey.subscriber('/tool')``...), which drop
    leading slashes so ``/tool`` and ``tool`` give the same key.
    """

    role: Role
    parts: tuple[str, ...]

    def __post_init__(self) -> None:
        if not isinstance(self.role, Role):
            raise NamingError(field="role", expected="a Role", got=repr(self.role))
        want = len(_PART_KEYS[self.role])
        if len(self.parts) != want:
            raise NamingError(field="parts", expected=f"{want} name parts for {self.role.value}",
                              got=f"{len(self.parts)}")
        for key, part in zip(_PART_KEYS[self.role], self.parts):
            if self.role == Role.MARKER and key == KEY_MARKER_NS and isinstance(part, str):
                pass  # a marker's namespace may be empty (RViz's default)
            elif not isinstance(part, str) or not part:
                raise NamingError(field=key, expected="a non-empty string", got=repr(part))
            if "\x00" in part:
                raise NamingError(field=key, expected="a name without NUL", got=repr(part))

    # -- constructors, one per role
    @classmethod
    def subscriber(cls, topic: str) -> NameKey:
        return cls(Role.SUBSCRIBER, (_clean(topic, KEY_TOPIC),))

    @classmethod
    def subscriber_messages(cls, topic: str) -> NameKey:
        return cls(Role.SUBSCRIBER_MESSAGES, (_clean(topic, KEY_TOPIC),))

    @classmethod
    def publisher(cls, topic: str) -> NameKey:
        return cls(Role.PUBLISHER, (_clean(topic, KEY_TOPIC),))

    @classmethod
    def tf_lookup(cls, parent: str, child: str) -> NameKey:
        return cls(Role.TF_LOOKUP, (_clean(parent, KEY_PARENT), _clean(child, KEY_CHILD)))

    @classmethod
    def tf_broadcaster(cls, parent: str, child: str) -> NameKey:
        return cls(Role.TF_BROADCASTER, (_clean(parent, KEY_PARENT), _clean(child, KEY_CHILD)))

    @classmethod
    def robot_link(cls, robot: str, link: str) -> NameKey:
        return cls(Role.ROBOT_LINK, (_clean(robot, KEY_ROBOT), _clean(link, KEY_LINK)))

    @classmethod
    def robot_visual(cls, robot: str, link: str, index: int) -> NameKey:
        if isinstance(index, bool) or not isinstance(index, int) or index < 0:
            raise NamingError(field=KEY_VISUAL, expected="an integer >= 0", got=repr(index))
        return cls(Role.ROBOT_VISUAL,
                   (_clean(robot, KEY_ROBOT), _clean(link, KEY_LINK), str(index)))

    @classmethod
    def robot_description(cls, robot: str) -> NameKey:
        return cls(Role.ROBOT_DESCRIPTION, (_clean(robot, KEY_ROBOT),))

    @classmethod
    def robot_poses(cls, robot: str) -> NameKey:
        return cls(Role.ROBOT_POSES, (_clean(robot, KEY_ROBOT),))

    @classmethod
    def marker(cls, topic: str, ns: str, marker_id: int) -> NameKey:
        if isinstance(marker_id, bool) or not isinstance(marker_id, int):
            raise NamingError(field=KEY_MARKER_ID, expected="an integer", got=repr(marker_id))
        if not isinstance(ns, str):
            raise NamingError(field=KEY_MARKER_NS, expected="a string", got=repr(ns))
        return cls(Role.MARKER, (_clean(topic, KEY_TOPIC), ns, str(marker_id)))

    @classmethod
    def marker_frame(cls, fixed: str, frame: str) -> NameKey:
        return cls(Role.MARKER_FRAME, (_clean(fixed, KEY_PARENT), _clean(frame, KEY_CHILD)))

    @classmethod
    def marker_topic(cls, topic: str) -> NameKey:
        return cls(Role.MARKER_TOPIC, (_clean(topic, KEY_TOPIC),))

    @classmethod
    def parameter_client(cls, node: str) -> NameKey:
        return cls(Role.PARAMETER_CLIENT, (_clean(node, KEY_NODE),))

    @classmethod
    def parameter_server(cls, node: str) -> NameKey:
        return cls(Role.PARAMETER_SERVER, (_clean(node, KEY_NODE),))

    @classmethod
    def service_client(cls, service: str) -> NameKey:
        return cls(Role.SERVICE_CLIENT, (_clean(service, KEY_SERVICE),))

    @classmethod
    def service_server(cls, service: str) -> NameKey:
        return cls(Role.SERVICE_SERVER, (_clean(service, KEY_SERVICE),))

    @classmethod
    def action_server(cls, action: str) -> NameKey:
        return cls(Role.ACTION_SERVER, (_clean(action, KEY_ACTION),))

    @classmethod
    def action_goal(cls, action: str, goal_id: str) -> NameKey:
        return cls(Role.ACTION_GOAL, (_clean(action, KEY_ACTION), _clean(goal_id, KEY_GOAL_ID)))

    def named_parts(self) -> dict[str, str]:
        """The parts keyed by metadata key; graph names get back their leading ``/``."""
        out: dict[str, str] = {}
        for key, part in zip(_PART_KEYS[self.role], self.parts):
            out[key] = "/" + part if key in _GRAPH_NAME_KEYS else part
        return out


def _clean(name: str, field: str) -> str:
    if not isinstance(name, str):
        raise NamingError(field=field, expected="a string", got=type(name).__name__)
    stripped = _strip(name)
    if not stripped:
        raise NamingError(field=field, expected="a non-empty name", got=repr(name))
    return stripped


def _readable_body(key: NameKey) -> str:
    if key.role in (Role.TF_LOOKUP, Role.TF_BROADCASTER, Role.MARKER_FRAME):
        return f"{key.parts[0]}>{key.parts[1]}"
    return ":".join(key.parts)


def _is_lossless(key: NameKey) -> bool:
    if key.role == Role.MARKER:  # ns may be empty; the id is an integer (maybe negative)
        return (all(_SAFE_PART.match(p) for p in key.parts[:1])
                and (not key.parts[1] or bool(_SAFE_PART.match(key.parts[1]))))
    if not all(_SAFE_PART.match(p) for p in key.parts):
        return False
    if key.role in (Role.ROBOT_LINK, Role.ROBOT_VISUAL) and key.parts[0] in _RESERVED_ROBOT_NAMES:
        return False
    return not (key.role == Role.ROBOT_VISUAL and not key.parts[2].isdigit())


def _digest(key: NameKey) -> str:
    material = "\x00".join((key.role.value,) + key.parts).encode("utf-8")
    raw = hashlib.sha256(material).digest()
    return base64.b32encode(raw).decode("ascii").lower().rstrip("=")


# A robot link's device also names its element in the robot's TDATA, where 19 bytes is
# what 3D Slicer's library reads back (protocol.header.TDATA_NAME_MAX_BYTES).
_MAX_BYTES = {Role.ROBOT_LINK: TDATA_NAME_MAX_BYTES}


def device_name_for(key: NameKey, hash_length: int = DEFAULT_HASH_LENGTH) -> str:
    """The deterministic device name of ``key`` (ASCII, at most 20 bytes; a robot link's
    at most 19).

    ``hash_length`` only matters for names that must be abbreviated; the registry raises it
    on a collision.
    """
    prefix = _PREFIX[key.role]
    readable = prefix + _readable_body(key)
    limit = _MAX_BYTES.get(key.role, MAX_DEVICE_NAME_BYTES)
    if _is_lossless(key) and len(readable) <= limit:
        return readable
    if not 4 <= hash_length <= _MAX_HASH_LENGTH:
        raise NamingError(field="hash_length", expected=f"4..{_MAX_HASH_LENGTH}",
                          got=str(hash_length))
    parts = [_UNSAFE_CHAR.sub("_", part) for part in key.parts]
    suffix = ""
    if key.role == Role.ROBOT_VISUAL:
        suffix = ":" + (parts.pop() if key.parts[2].isdigit() else "x")
    elif key.role == Role.MARKER:
        suffix = ":" + parts.pop()  # the id, always whole: it tells a topic's markers apart
        if not parts[1]:
            parts.pop()  # an empty ns: nothing to abbreviate
    mark = _HASH_SEPARATOR + _digest(key)[:hash_length]
    room = limit - len(prefix) - len(mark) - len(suffix)
    return f"{prefix}{_abbreviate(key.role, parts, room)}{mark}{suffix}"


def _abbreviate(role: Role, parts: list[str], room: int) -> str:
    """The readable body of ``parts`` shortened to ``room`` characters, in steps that keep
    it readable: noise suffixes go, then namespaces become initials, then go, then parts
    are cut from their ends (their starts stay)."""
    if role in (Role.TF_LOOKUP, Role.TF_BROADCASTER, Role.MARKER_FRAME):
        separator = ">"
    elif role in (Role.SUBSCRIBER, Role.PUBLISHER, Role.PARAMETER_CLIENT,
                  Role.PARAMETER_SERVER, Role.SERVICE_CLIENT, Role.SERVICE_SERVER,
                  Role.MARKER_TOPIC, Role.ACTION_SERVER):
        separator = ""  # one graph name
    else:
        separator = ":"
    # A robot's own name is kept whole as long as possible: it says which robot.
    first = 1 if role in (Role.ROBOT_LINK, Role.ROBOT_VISUAL) else 0

    def length() -> int:
        return len(separator.join(parts))

    for step in (_without_noise, _namespaces_to_initials, _without_namespaces):
        for i in range(first, len(parts)):
            if length() <= room:
                return separator.join(parts)
            parts[i] = step(parts[i])
    # Then ends are cut. A robot's name or a parent frame is shared by many devices and
    # the link or child frame tells them apart, so the first part goes first, but only
    # down to a short name (PSM1, world) until the others are at their minimum.
    for i, floor in [(0, _SHORT_NAME)] + [(i, _MIN_KEPT) for i in range(1, len(parts))] \
            + [(0, _MIN_KEPT)]:
        excess = length() - room
        if excess <= 0:
            break
        parts[i] = parts[i][:max(min(floor, len(parts[i])), len(parts[i]) - excess)]
    if length() > room:  # every part at its minimum: cut the whole
        return separator.join(parts)[:max(room, 0)].rstrip(":>/")
    return separator.join(parts).rstrip(":>/")


def _without_noise(part: str) -> str:
    for noise in _NOISE_SUFFIXES:
        if part.endswith(noise) and len(part) > len(noise):
            return part[:-len(noise)]
    return part


def _without_namespaces(part: str) -> str:
    names = [name for name in part.split("/") if name]
    return names[-1] if names else part


def _namespaces_to_initials(part: str) -> str:
    """``robot/arm/pose`` -> ``r/a/pose``: the last name says the most."""
    *namespaces, last = part.split("/")
    return "/".join([name[:1] for name in namespaces] + [last])


def is_hashed_name(device_name: str) -> bool:
    """True for device names of the shortened ``<tail>~<hash>`` form."""
    return _HASH_SEPARATOR in device_name


class DeviceNameRegistry:
    """Hands out device names within one daemon; no two keys ever share one.

    Registering is idempotent: the same key always gets the name it got first. On a hash
    collision the newcomer's hash is lengthened until the name is free.
    """

    def __init__(self) -> None:
        self._by_key: dict[NameKey, str] = {}
        self._by_name: dict[str, NameKey] = {}

    def register(self, key: NameKey) -> str:
        """Return the device name for ``key``, reserving it if new."""
        known = self._by_key.get(key)
        if known is not None:
            return known
        for length in range(DEFAULT_HASH_LENGTH, _MAX_HASH_LENGTH + 1):
            name = self._candidate(key, length)
            if name not in self._by_name:
                self._by_key[key] = name
                self._by_name[name] = key
                return name
        # 16 base32 characters of SHA-256 colliding as well: not a realistic input.
        raise NamingError(field="device_name", expected="a free device name",
                          got=f"every candidate for {key!r} taken")

    def _candidate(self, key: NameKey, hash_length: int) -> str:
        # Overridable seam: tests force collisions through it.
        return device_name_for(key, hash_length)

    def release(self, key: NameKey) -> str | None:
        """Forget ``key``; returns the device name it had, or None if unknown."""
        name = self._by_key.pop(key, None)
        if name is not None:
            del self._by_name[name]
        return name

    def lookup(self, device_name: str) -> NameKey | None:
        """The ROS identity behind a device name handed out here, or None."""
        return self._by_name.get(device_name)

    def name_of(self, key: NameKey) -> str | None:
        """The device name already given to ``key``, or None (does not register)."""
        return self._by_key.get(key)

    def __contains__(self, device_name: object) -> bool:
        return device_name in self._by_name

    def __len__(self) -> int:
        return len(self._by_key)

    def __iter__(self) -> Iterator[tuple[str, NameKey]]:
        return iter(list(self._by_name.items()))


def metadata_for(
    key: NameKey,
    *,
    ros_type: str | None = None,
    frame: str | None = None,
    units: str | None = None,
) -> dict[str, str]:
    """Metadata for every message of ``key``: role, full ROS names, and the optional type
    (``pkg/msg/Type``), header frame id and units (``"mm"`` for anything geometric).

    Keys are ASCII; values are str and may be any UTF-8 (frame names are free text).
    """
    meta: dict[str, str] = {KEY_ROLE: key.role.value}
    meta.update(key.named_parts())
    if ros_type:
        meta[KEY_TYPE] = ros_type
    if frame:
        meta[KEY_FRAME] = frame
    if units:
        meta[KEY_UNITS] = units
    return meta


def key_from_metadata(metadata: dict[str, str]) -> NameKey:
    """Rebuild the `NameKey` from a message's ``ros2.*`` metadata (inverse of
    `metadata_for`); raises `NamingError` naming the missing or bad key."""
    role_text = metadata.get(KEY_ROLE)
    try:
        role = Role(role_text)
    except ValueError:
        raise NamingError(field=KEY_ROLE, expected="one of " + ", ".join(r.value for r in Role),
                          got=repr(role_text)) from None
    parts = []
    for part_key in _PART_KEYS[role]:
        value = metadata.get(part_key)
        if role == Role.MARKER and part_key == KEY_MARKER_NS and value is not None:
            parts.append(value)
            continue
        if not value:
            raise NamingError(field=part_key, expected=f"a name for role {role.value}",
                              got=repr(value))
        parts.append(value)
    if role == Role.ROBOT_VISUAL:
        if not parts[2].isdigit():
            raise NamingError(field=KEY_VISUAL, expected="an integer >= 0", got=repr(parts[2]))
        return NameKey.robot_visual(parts[0], parts[1], int(parts[2]))
    if role == Role.MARKER:
        try:
            marker_id = int(parts[2])
        except ValueError:
            raise NamingError(field=KEY_MARKER_ID, expected="an integer",
                              got=repr(parts[2])) from None
        return NameKey.marker(parts[0], parts[1], marker_id)
    return NameKey(role, tuple(_clean(p, k) for p, k in zip(parts, _PART_KEYS[role])))

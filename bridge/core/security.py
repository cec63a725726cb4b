"""Who may connect and what a client may do: the daemon's security policy, in one place.

An OpenIGTLink peer has no authentication, and this daemon can publish to a robot, so the
policy decides from what can be known: the peer's address (at accept, `admits`), and the
request itself (in the dispatcher, `check_request`, before any capability runs). Start-up
bridges from the YAML config go through the same dispatcher, so they are judged alike.

The policy judges resources, never op names: each request declares what it touches
(`protocol.commands.op`: topics, services, actions, parameters, tf frames, files) and whether it
writes, and every declared resource is judged by the rules of its kind. A request class the
schema does not declare cannot be judged, and is refused (fail closed). Some resources are
named inside content rather than requests: a tf topic's transforms, a robot's links, a
parameter service's or a parameter event's parameters. An op declares that content
(`Op.content`) and `content_guard` applies the same rules there, so no route reaches a
resource that another route refuses.

Name rules follow rosbridge / foxglove_bridge: shell-style globs on fully qualified names
(``*`` also matches ``/``); a deny glob always wins; once any allow glob is given for a
kind, only names matching one of them are allowed. tf frames get the same rules, judged as
the tf buffer holds them (``--frame-prefix`` applied, no leading ``/``); parameters are
judged as ``<node>.<name>``.

docs/security.md is the threat model and the user's guide to these options.
"""

from __future__ import annotations

import ipaddress
import logging
import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from fnmatch import fnmatchcase
from typing import Any, Callable, Optional, Union

from bridge.codecs.errors import CodecError
from bridge.codecs.registry import resolve_type  # bare names: looked up as capabilities do
from bridge.core.logging_limits import RateLimitedLog
from protocol.auth import KeyFileError, read_key_text
from bridge.core.content_guards import (PARAMETER_EVENT_TYPE, TF_MESSAGE_TYPE, ContentGuard,
                                        HeaderFrameGuard, MessageGuard, ParameterEventGuard,
                                        TfMessageGuard)
from protocol.commands import (REQUEST_TYPES, ActionUse, FileUse, ForbiddenError, FrameUse,
                               LimitReachedError, Op, OutOfRangeError, ParameterUse, Resource,
                               ServiceUse, TopicUse, resolve_service_type)

__all__ = ["WRITES", "DEFAULT_MAX_BRIDGES", "WriteGrant", "read_key_file",
           "DEFAULT_MAX_BRIDGES_PER_CLIENT", "DEFAULT_MAX_CLIENTS",
           "DEFAULT_MAX_MARKER_BYTES",
           "OPERATOR",
           "PARAMETER_SERVICES", "SECURITY_KEYS", "BridgeOwners", "BridgeQuota", "NameRules",
           "PolicyError", "RateLimitedLog", "SecurityPolicy", "hidden_action", "inside",
           "is_loopback_host", "open_permissions",
           "parameter_service", "parse_network", "positive_int", "strip_frame"]

log = logging.getLogger(__name__)

Network = Union[ipaddress.IPv4Network, ipaddress.IPv6Network]
FileResolver = Callable[[str], "os.PathLike[str] | str"]  # a robot file source -> its path

# Who made a bridge that no client made: the operator's start-up config.
OPERATOR = "operator"

# The parameter services every rclcpp/rclpy node offers (service name suffix -> type and
# the request field that names the parameters; None: the call lists them).
PARAMETER_SERVICES: dict[str, tuple[str, Optional[str]]] = {
    "get_parameters": ("rcl_interfaces/srv/GetParameters", "names"),
    "get_parameter_types": ("rcl_interfaces/srv/GetParameterTypes", "names"),
    "describe_parameters": ("rcl_interfaces/srv/DescribeParameters", "names"),
    "set_parameters": ("rcl_interfaces/srv/SetParameters", "parameters"),
    "set_parameters_atomically": ("rcl_interfaces/srv/SetParametersAtomically",
                                  "parameters"),
    "list_parameters": ("rcl_interfaces/srv/ListParameters", None),
}
_TF_TOPICS = ("/tf", "/tf_static")
# An action is made of hidden services and topics under ``<action>/_action/``: whatever
# names them is judged as a use of the action too (else the action globs could be routed
# around with call_service or a publisher). Calling send_goal/cancel_goal sends goals;
# serving any of them or publishing feedback/status serves the action; subscribing watches.
ACTION_SERVICES = ("send_goal", "cancel_goal", "get_result")
ACTION_TOPICS = ("feedback", "status")
_ACTION_PART = "/_action/"


def hidden_action(name: str, kinds: tuple[str, ...]) -> Optional[str]:
    """The action a fully qualified hidden service or topic name belongs to
    (``/fjt/_action/send_goal`` -> ``/fjt``), or None."""
    action, part, suffix = name.rpartition(_ACTION_PART)
    if not part or not action or suffix not in kinds:
        return None
    return action


def parameter_service(service: str, ros_type: Optional[str]) -> Optional[tuple[str, str]]:
    """(node, suffix) if `service` (fully qualified) is a node's standard parameter service,
    by its name or by its type; else None."""
    node, _, suffix = service.rpartition("/")
    if suffix not in PARAMETER_SERVICES:
        by_type = [s for s, (kind, _) in PARAMETER_SERVICES.items() if kind == ros_type]
        if not by_type:
            return None
        suffix = by_type[0]
    return node or "/", suffix


def _request_names(request: Mapping[str, Any], names_field: str) -> tuple[str, ...]:
    """The parameter names a standard parameter service request carries (``names``, or
    the ``name`` of each of ``parameters``); anything else in their place is judged as
    naming every parameter."""
    value = request.get(names_field)
    if not isinstance(value, list):
        return ()
    if names_field == "parameters":
        value = [p.get("name") if isinstance(p, dict) else None for p in value]
    if not value or not all(isinstance(n, str) and n for n in value):
        return ()
    return tuple(value)


def _resolved(resolve: Callable[[str], str], text: Optional[str]) -> Optional[str]:
    """A type as given -> ``pkg/msg|srv/Type``, or None (the capability says why it cannot
    use a bad one)."""
    if text is None:
        return None
    try:
        return resolve(text)
    except (OutOfRangeError, CodecError):
        return None


def inside(path: str, folders: Iterable[str]) -> bool:
    """Is `path` (already real: symlinks resolved) inside one of `folders`?"""
    for folder in folders:
        root = os.path.realpath(folder)
        if os.path.commonpath([path, root]) == root:
            return True
    return False


def strip_frame(frame: str) -> str:
    """The frame resolver of a daemon without ``--frame-prefix``: tf2 ids have no leading
    ``/``, so ``/base`` and ``base`` are one frame (and one name to judge)."""
    return frame.lstrip("/")


DEFAULT_MAX_CLIENTS = 64
DEFAULT_MAX_BRIDGES_PER_CLIENT = 1000
# Over all clients, past and present: bridges outlive their client, so a per-client count
# alone would let a client that reconnects make as many again.
DEFAULT_MAX_BRIDGES = 2000
DEFAULT_MAX_MARKER_BYTES = 256 * 1024 * 1024


class PolicyError(ValueError):
    """A security option or config entry is invalid; says which and what was expected."""


@dataclass(frozen=True)
class WriteGrant:
    """Whether one connection may change ROS (ops that write or remove, data sent to
    publishers and broadcasters), and, when not, why: the refusal says it."""

    writes: bool
    why: str = ""


WRITES = WriteGrant(True)


@dataclass(frozen=True)
class NameRules:
    """Allow and deny globs for one kind of name (topics, services, parameters, frames)."""

    allow: tuple[str, ...] = ()
    deny: tuple[str, ...] = ()

    def permits(self, name: str) -> bool:
        if any(fnmatchcase(name, glob) for glob in self.deny):
            return False
        return not self.allow or any(fnmatchcase(name, glob) for glob in self.allow)

    def why_not(self, name: str) -> str:
        """What the rules expected, for an error naming them."""
        denied = [glob for glob in self.deny if fnmatchcase(name, glob)]
        if denied:
            return f"a name not matching the deny glob {denied[0]!r}"
        return "a name matching an allow glob (" + ", ".join(self.allow) + ")"

    @property
    def active(self) -> bool:
        return bool(self.allow or self.deny)


@dataclass(frozen=True)
class SecurityPolicy:
    read_only: bool = False
    # Client addresses allowed to connect; empty = any address that reaches the socket.
    allowed_networks: tuple[Network, ...] = ()
    topics: NameRules = NameRules()
    services: NameRules = NameRules()
    actions: NameRules = NameRules()
    parameters: NameRules = NameRules()
    frames: NameRules = NameRules()
    max_clients: int = DEFAULT_MAX_CLIENTS
    max_bridges_per_client: int = DEFAULT_MAX_BRIDGES_PER_CLIENT
    max_bridges: int = DEFAULT_MAX_BRIDGES  # made by clients, all together
    # Bytes of marker models kept, all topics together (a topic may hold half of it).
    max_marker_bytes: int = DEFAULT_MAX_MARKER_BYTES
    # Folders whose URDF files clients may load by path (`--robot-dir`, and the daemon adds
    # every `--package-path` folder): a client must not make the daemon read any file.
    robot_dirs: tuple[str, ...] = ()
    # Folders clients' recordings may write bags in (`--record-dir`; the daemon's default is
    # the system's temporary folder): a client must not make the daemon write any file.
    record_dirs: tuple[str, ...] = ()
    # The writers' shared key (`--key-file`, protocol/auth.py); None: no key.
    key: Optional[bytes] = field(default=None, repr=False)
    key_path: Optional[str] = None  # its file, checked for open permissions at start
    # Networks whose plain connections may write without a key (`--trust`).
    trusted_networks: tuple[Network, ...] = ()
    # Listening beyond loopback (set by the daemon from --host): then, without a key, only
    # this machine's own connections and --trust networks may write.
    beyond_loopback: bool = False
    # How a request's type name becomes ``pkg/msg/Type``: among the packages installed
    # (the daemon), or among a bag's types (the player, which imports no ROS package).
    resolve_type: Callable[[str], str] = field(default=resolve_type, repr=False, compare=False)

    # --- who may write ---------------------------------------------------------------------
    def grant_at_accept(self, address: str) -> WriteGrant:
        """What a new connection from `address` may do before it presents a key."""
        if self.read_only:
            return WriteGrant(False, "the daemon runs --read-only: clients change and "
                                     "remove nothing")
        if _in_networks(address, self.trusted_networks):
            return WRITES
        if self.key is not None:
            return WriteGrant(False, "this connection has not presented the daemon's key "
                                     "(slicer_client: connect(key_file=...); the ROS2Bridge "
                                     "module: its key file setting); a plain OpenIGTLink "
                                     "client may write only from a network the operator "
                                     "names with --trust")
        if not self.beyond_loopback or _in_networks(address, _LOOPBACK):
            return WRITES
        return WriteGrant(False, "a client on another machine may write only with a key (the "
                                 "operator starts the daemon with --key-file) or from a "
                                 "network the operator names with --trust")

    def grant_after_proof(self) -> WriteGrant:
        """What a connection may do once it has presented the key."""
        return self.grant_at_accept("") if self.read_only else WRITES

    # --- at accept -----------------------------------------------------------------------
    def admits(self, address: str) -> bool:
        """May a client from `address` (an IP literal) connect?"""
        return not self.allowed_networks or _in_networks(address, self.allowed_networks)

    # --- per request ---------------------------------------------------------------------
    def check_request(self, request: Op, own_node: str, *,
                      from_client: bool = True,
                      resolve_file: Optional[FileResolver] = None,
                      grant: WriteGrant = WRITES) -> None:
        """Raise `ForbiddenError` if the policy refuses this parsed request.

        The request's ROS names come fully qualified and its client frame ids as the tf
        buffer holds them (`Op.with_names`, `Op.with_frames`, in the dispatcher), so
        ``cmd_vel`` cannot slip past a deny glob on ``/cmd_vel``, nor ``--frame-prefix``
        past a frame glob; `own_node` is the daemon's node, owner of the ``server_*``
        parameters; `resolve_file` turns a robot's file source into the path the daemon would read.
        `from_client` is False for the operator's own start-up config, whose file paths are
        trusted; `grant` is what the requesting connection may do (`grant_at_accept`).
        """
        cls = type(request)
        if REQUEST_TYPES.get(cls.op) is not cls:  # fail closed: nothing undeclared runs
            raise ForbiddenError("op", "an op the command schema declares", cls.__name__)
        if cls.to_client:
            raise ForbiddenError("op", "an op a client sends (the daemon sends this one)",
                                 cls.op)
        if cls.writes or cls.removes is not None:
            refusal = self.grant_at_accept("") if self.read_only else grant
            if not refusal.writes:
                raise ForbiddenError("op", f"an op that only receives ({refusal.why})",
                                     cls.op)
        for use in request.resources():
            self._judge(use, own_node, from_client, resolve_file)

    def _judge(self, use: Resource, own_node: str,
               from_client: bool,
               resolve_file: Optional[FileResolver]) -> None:
        if isinstance(use, TopicUse):
            self._judge_topic(use, use.name)
        elif isinstance(use, ServiceUse):
            self._judge_service(use, use.name)
        elif isinstance(use, ActionUse):
            self._judge_action(use.field, use.name)
        elif isinstance(use, ParameterUse):
            node = use.node if use.node is not None else own_node
            self._judge_parameters(node, use.names, use.field)
        elif isinstance(use, FrameUse):
            if self.frames.active:
                # Judged as the buffer holds it; an empty result is the tf capability's error.
                frame = strip_frame(use.frame)
                if frame and not self.frames.permits(frame):
                    raise ForbiddenError(use.field, "a tf frame this daemon exposes: "
                                         + self.frames.why_not(frame), frame)
        elif isinstance(use, FileUse):
            if from_client:  # without a resolver, the path is judged as it is written
                self._judge_file(use, resolve_file or str)
        else:  # a new kind of resource that this policy does not know yet: fail closed
            raise ForbiddenError("op", "resources this daemon's policy can judge",
                                 type(use).__name__)

    def _judge_action(self, field: str, action: str) -> None:
        if self.actions.active and not self.actions.permits(action):
            raise ForbiddenError(field, "an action this daemon exposes: "
                                 + self.actions.why_not(action), action)

    def _judge_topic(self, use: TopicUse, topic: str) -> None:
        if self.topics.active and not self.topics.permits(topic):
            raise ForbiddenError(use.field, "a topic this daemon exposes: "
                                 + self.topics.why_not(topic), topic)
        action = hidden_action(topic, ACTION_TOPICS)
        if action is not None:
            self._judge_action(use.field, action)
        ros_type = _resolved(self.resolve_type, use.type)
        # A tf topic carries frames: only a TFMessage can be judged transform by transform
        # (the bridge's MessageGuard does it); another type on /tf cannot be judged.
        if self.frames.active and topic in _TF_TOPICS and use.type is not None \
                and ros_type != TF_MESSAGE_TYPE:
            raise ForbiddenError("type", f"{TF_MESSAGE_TYPE} on a tf topic (frame globs are "
                                 f"set)", use.type)

    def _judge_service(self, use: ServiceUse, service: str) -> None:
        if self.services.active and not self.services.permits(service):
            raise ForbiddenError(use.field, "a service this daemon exposes: "
                                 + self.services.why_not(service), service)
        action = hidden_action(service, ACTION_SERVICES)
        if action is not None:
            self._judge_action(use.field, action)
        ros_type = _resolved(resolve_service_type, use.type)
        found = parameter_service(service, ros_type)
        if found is None or not self.parameters.active:
            return
        node, suffix = found
        kind, names_field = PARAMETER_SERVICES[suffix]
        if use.serves:  # answering for a node's parameters: all of them, unjudgeable
            self._judge_parameters(node, (), use.field)
            return
        if names_field is None:
            return  # listing: the reply shows only the names the globs allow
        if ros_type != kind:  # the request's parameter names cannot be read by its type
            self._judge_parameters(node, (), use.field)
            return
        self._judge_parameters(node, _request_names(use.request or {}, names_field),
                               f"request.{names_field}")

    def _judge_parameters(self, node: str, names: Iterable[str], field: str) -> None:
        if not self.parameters.active:
            return
        names = tuple(names)
        if not names:
            # "All parameters" cannot be judged name by name before they are known.
            raise ForbiddenError(field, "explicit parameter names (parameter globs are set)",
                                 f"all parameters of {node}")
        for name in names:
            full = f"{node}.{name}"
            if not self.parameters.permits(full):
                raise ForbiddenError(field, "a parameter this daemon exposes: "
                                     + self.parameters.why_not(full), full)

    def _judge_written_file(self, use: FileUse) -> None:
        # Its folder is judged (the file is made later): symlinks followed, so a link inside
        # an allowed folder cannot point outside it.
        allowed = ", ".join(self.record_dirs) or "none: start the daemon with --record-dir"
        folder = os.path.realpath(os.path.dirname(use.path) or ".")
        target = os.path.join(folder, os.path.basename(use.path))
        real = os.path.realpath(target)  # an existing link at the path itself, too
        if not (inside(folder, self.record_dirs) and inside(real, self.record_dirs)):
            raise ForbiddenError(use.field, f"a path inside a --record-dir folder ({allowed})",
                                 use.path)

    def _judge_file(self, use: FileUse, resolve_file: FileResolver) -> None:
        if use.writes:
            self._judge_written_file(use)
            return
        # A missing file and a refused one get one answer: the reply must not tell a client
        # whether a path it chose exists. Symlinks are followed, so a link inside an
        # allowed folder cannot point outside it.
        allowed = ", ".join(self.robot_dirs) or "none: start the daemon with --robot-dir"
        refused = ForbiddenError(use.field, f"an existing file inside a --robot-dir or "
                                 f"--package-path folder ({allowed})", use.path)
        try:
            real = os.path.realpath(resolve_file(use.path))
        except Exception:  # noqa: BLE001 - unresolvable is answered as refused
            raise refused from None
        if not inside(real, self.robot_dirs) or not os.path.isfile(real):
            raise refused

    # --- inside content ------------------------------------------------------------------
    def content_guard(self, request: Op, *, from_client: bool = True) -> ContentGuard:
        """The guard for what `request`'s op declares it carries (`Op.content`), judged by
        the same rules as the request's own names, so no route reaches a name another
        route refuses. Its names are resolved already (the dispatcher). Files named by
        content are read only inside the robot folders, unless the content is a file the
        operator's own config names (`from_client` False): a description from a parameter or
        a topic can be changed by any client or ROS peer."""
        cls = type(request)
        declared = cls.content
        uses = request.resources()
        operators_file = not from_client and any(isinstance(use, FileUse) for use in uses)
        guard = ContentGuard(cls.op, declared, frames=self.frames, parameters=self.parameters,
                             file_roots=None if operators_file else self.robot_dirs)
        if "messages" in declared:
            topic = next(use for use in uses if isinstance(use, TopicUse))
            guard = replace(guard, messages=self._message_guard(
                topic.name, _resolved(self.resolve_type, topic.type) or "", topic.writes))
        if "parameters" in declared:
            for use in uses:
                if isinstance(use, ServiceUse):
                    found = parameter_service(use.name,
                                              _resolved(resolve_service_type, use.type))
                    if found is not None and found[1] == "list_parameters":
                        guard = replace(guard, lists_parameters_of=found[0])
        return guard

    def _message_guard(self, topic: str, ros_type: str, writes: bool) -> Optional[MessageGuard]:
        """What a topic bridge judges in each message: by its type (tf frames, parameter
        events); a publisher, with frame globs set, also the frame its header names."""
        if self.frames.active and (ros_type == TF_MESSAGE_TYPE or topic in _TF_TOPICS):
            return TfMessageGuard(self.frames.permits, self.frames.why_not)
        if self.parameters.active and ros_type == PARAMETER_EVENT_TYPE:
            return ParameterEventGuard(self.parameters.permits, self.parameters.why_not)
        if writes and self.frames.active:
            return HeaderFrameGuard(self.frames.permits, self.frames.why_not)
        return None

    # --- construction --------------------------------------------------------------------
    @classmethod
    def from_settings(cls, settings: Mapping[str, Any], where: str) -> SecurityPolicy:
        """Build from the keys of the YAML ``security:`` section (see SECURITY_KEYS)."""
        unknown = sorted(set(settings) - set(SECURITY_KEYS))
        if unknown:
            raise PolicyError(f"{where}: unknown key {unknown[0]!r}; expected one of "
                              f"{', '.join(SECURITY_KEYS)}")
        policy = cls()
        if "read_only" in settings:
            value = settings["read_only"]
            if not isinstance(value, bool):
                raise PolicyError(f"{where}.read_only: expected true or false, got {value!r}")
            policy = replace(policy, read_only=value)
        networks = tuple(parse_network(text, f"{where}.allow")
                         for text in _globs(settings, "allow", where))
        trusted = tuple(parse_network(text, f"{where}.trust")
                        for text in _globs(settings, "trust", where))
        policy = replace(policy, allowed_networks=networks, trusted_networks=trusted)
        if settings.get("key_file") is not None:
            policy = replace(policy, key=read_key_file(settings["key_file"],
                                                       f"{where}.key_file"),
                             key_path=str(settings["key_file"]))
        # Fields named one by one (not **{kind: ...}): mypy checks each against its type.
        rules = {kind: NameRules(allow=_globs(settings, f"allow_{kind}", where),
                                 deny=_globs(settings, f"deny_{kind}", where))
                 for kind in ("topics", "services", "actions", "parameters", "frames")}
        policy = replace(policy, topics=rules["topics"], services=rules["services"],
                         actions=rules["actions"], parameters=rules["parameters"],
                         frames=rules["frames"])
        dirs = _globs(settings, "robot_dirs", where)
        policy = replace(policy, robot_dirs=tuple(dirs),
                         record_dirs=tuple(_globs(settings, "record_dirs", where)))

        def limit(key: str, default: int) -> int:
            if settings.get(key) is None:
                return default
            return positive_int(settings[key], f"{where}.{key}")

        policy = replace(policy, max_clients=limit("max_clients", policy.max_clients),
                         max_bridges_per_client=limit("max_bridges_per_client",
                                                      policy.max_bridges_per_client),
                         max_bridges=limit("max_bridges", policy.max_bridges),
                         max_marker_bytes=limit("max_marker_bytes", policy.max_marker_bytes))
        return policy

    def grant_summary(self) -> str:
        if self.read_only:
            return "none (read-only)"
        who = ["connections that present the key"] if self.key is not None else []
        if self.key is None:
            who.append("this machine's own connections" if self.beyond_loopback
                       else "every connection (listening on loopback only)")
        who += [f"plain connections from {net}" for net in self.trusted_networks]
        return ", ".join(who)

    def describe(self) -> str:
        """One log line: what is locked down."""
        parts = ["read-only" if self.read_only else "read-write",
                 "clients from " + (", ".join(map(str, self.allowed_networks))
                                    if self.allowed_networks else "any address"),
                 f"at most {self.max_clients} clients",
                 f"{self.max_bridges_per_client} bridges per client, "
                 f"{self.max_bridges} from all clients",
                 f"{self.max_marker_bytes} bytes of marker models",
                 "who may change ROS: " + self.grant_summary()]
        for kind in ("topics", "services", "actions", "parameters", "frames"):
            rules: NameRules = getattr(self, kind)
            if rules.active:
                parts.append(f"{kind} allow={list(rules.allow)} deny={list(rules.deny)}")
        return "; ".join(parts)


# Keys of the YAML `security:` section; the command-line options of the same names (with
# dashes, singular for the repeatable ones) add to them.
SECURITY_KEYS: tuple[str, ...] = (
    "read_only", "allow",
    "allow_topics", "deny_topics", "allow_services", "deny_services",
    "allow_actions", "deny_actions",
    "allow_parameters", "deny_parameters", "allow_frames", "deny_frames",
    "max_clients", "max_bridges_per_client", "max_bridges", "max_message_bytes",
    "max_send_buffer_bytes", "max_marker_bytes",
    "robot_dirs", "record_dirs", "key_file", "trust",
)


def read_key_file(path: Any, where: str) -> bytes:
    """The writers' key from its file (made by `slicer-ros2-bridge keygen`)."""
    if not isinstance(path, (str, os.PathLike)) or not str(path):
        raise PolicyError(f"{where}: expected the path of a key file, got {path!r}")
    try:
        with open(path, encoding="ascii", errors="replace") as file:
            text = file.read(4096)
    except OSError as error:
        raise PolicyError(f"{where}: expected a readable key file, got {path!r} "
                          f"({error.strerror})") from None
    try:
        return read_key_text(text, f"{where} ({path})")
    except KeyFileError as error:
        raise PolicyError(str(error)) from None


def open_permissions(path: str, what: str) -> Optional[str]:
    """One warning line if the secret file at `path` may be read by its group or others
    (as ssh warns of a private key); None if only its owner may (or it cannot be read)."""
    try:
        mode = os.stat(path).st_mode & 0o777
    except OSError:
        return None
    if not mode & 0o077:
        return None
    return (f"{what} {path} has permissions {mode:04o}: readable by "
            f"{'others' if mode & 0o007 else 'its group'}, who could then "
            f"{'write through the daemon' if what == '--key-file' else 'pose as the daemon'}; "
            f"expected 0600 (chmod 600 {path})")


def parse_network(text: str, where: str) -> Network:
    """``10.0.0.0/8``, ``::1``, ``192.168.1.20`` (one host) -> a network."""
    try:
        return ipaddress.ip_network(str(text).strip(), strict=False)
    except ValueError:
        raise PolicyError(f"{where}: expected an IPv4 or IPv6 address or CIDR block "
                          f"(10.0.0.0/8, ::1), got {text!r}") from None


def positive_int(value: Any, where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise PolicyError(f"{where}: expected a positive integer, got {value!r}")
    return value


def _globs(settings: Mapping[str, Any], key: str, where: str) -> tuple[str, ...]:
    value = settings.get(key)
    if value is None:
        return ()
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) and v
                                                       for v in value):
        raise PolicyError(f"{where}.{key}: expected a list of non-empty strings, "
                          f"got {value!r}")
    return tuple(value)


_LOOPBACK = (ipaddress.ip_network("127.0.0.0/8"), ipaddress.ip_network("::1/128"))


def _in_networks(address: str, networks: Iterable[Network]) -> bool:
    """Is `address` (an IP literal, as a socket reports its peer) inside one of them?"""
    try:
        ip = ipaddress.ip_address(address.split("%", 1)[0])
    except ValueError:  # not an IP peer (a Unix socket): no network rule can name it
        return False
    if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
        ip = ip.ipv4_mapped  # a dual-stack socket reports IPv4 peers as ::ffff:a.b.c.d
    return any(ip.version == net.version and ip in net for net in networks)


def is_loopback_host(host: str) -> bool:
    """Does listening on `host` keep the daemon reachable from this machine only?"""
    if host == "localhost":
        return True
    try:
        address = ipaddress.ip_address(host)
    except ValueError:
        return False  # a host name: whatever it resolves to may be reachable from outside
    mapped = address.ipv4_mapped if isinstance(address, ipaddress.IPv6Address) else None
    return (mapped or address).is_loopback  # ::ffff:127.0.0.1 is a dual-stack socket's


BridgeKey = tuple[str, tuple[str, ...]]  # (bridge kind, its identity values)


class BridgeOwners:
    """Who holds each live bridge, and so when it ends (docs/security.md, "Who owns a
    bridge").

    A bridge's holders are the live clients that asked for it (its maker, then any client
    that asked again: they share it). The operator's start-up config holds its bridges for
    good, and a client may mark one kept (`keep`): both stay when every client has left.
    Otherwise a bridge ends when its last holder leaves (`left` names it; the dispatcher
    removes it). Its maker is kept apart: the maker's quota slot is what its removal frees.

    Removal: no client removes the operator's bridges; a client may remove any bridge a
    client made, its own or another's, held or kept (removal is for everyone holding it);
    a ``--read-only`` daemon's clients remove nothing (`SecurityPolicy.check_request`).
    """

    def __init__(self) -> None:
        self._makers: dict[BridgeKey, object] = {}
        self._holders: dict[BridgeKey, set[object]] = {}
        self._kept: set[BridgeKey] = set()

    def created(self, key: BridgeKey, owner: object) -> None:
        """`owner` made `key` or asked for it again (then it shares it). The operator's
        config always claims its own bridges: no client holds one of them."""
        if owner == OPERATOR:
            self._makers[key] = OPERATOR
            self._holders[key] = set()
            return
        if key not in self._makers:
            self._makers[key] = owner
            self._holders[key] = set()
        if self._makers[key] != OPERATOR:
            self._holders[key].add(owner)

    def owner(self, key: BridgeKey) -> Optional[object]:
        """Who made `key` (`OPERATOR` or a client, perhaps gone), None if it is not live."""
        return self._makers.get(key)

    def holders(self, key: BridgeKey) -> frozenset[object]:
        return frozenset(self._holders.get(key, ()))

    def audience(self, key: BridgeKey) -> Optional[frozenset[object]]:
        """Who receives the streams of `key`: None (every client) if it stays (the
        operator's, or kept), else its live holders."""
        return None if self.stays(key) else self.holders(key)

    def keep(self, key: BridgeKey) -> bool:
        """Mark `key` to stay when its holders have left; False if no such bridge lives."""
        if key not in self._makers:
            return False
        self._kept.add(key)
        return True

    def stays(self, key: BridgeKey) -> bool:
        """Whether `key` outlives its clients (the operator's, or kept)."""
        return key in self._kept or self._makers.get(key) == OPERATOR

    def orphaned(self, key: BridgeKey) -> bool:
        """Whether `key` lives with no holder left and nothing keeping it: it ends."""
        return key in self._makers and not self._holders[key] and not self.stays(key)

    def removed(self, key: BridgeKey) -> Optional[object]:
        """`key` is gone; returns who made it (whose quota slot it frees)."""
        self._holders.pop(key, None)
        self._kept.discard(key)
        return self._makers.pop(key, None)

    def forget(self, client: object, kinds: Iterable[str]) -> list[BridgeKey]:
        """`client` left: its bridges of `kinds` (those that die with their connection, which
        their capability ends) are gone; returns them."""
        kinds = set(kinds)
        gone = [k for k, maker in self._makers.items() if maker is client and k[0] in kinds]
        for key in gone:
            self.removed(key)
        return gone

    def left(self, client: object) -> list[BridgeKey]:
        """`client` left: it holds nothing any more. Returns the bridges that end with it
        (it was their last holder and nothing keeps them), in the order they were made."""
        ending = []
        for key, holders in self._holders.items():
            if client in holders:
                holders.discard(client)
                if self.orphaned(key):
                    ending.append(key)
        return ending

    def check_removal(self, key: BridgeKey, field: str, client: object) -> None:
        """Raise `ForbiddenError` if `client` (None: the operator) may not remove `key`."""
        if client is not None and self._makers.get(key) == OPERATOR:
            raise ForbiddenError(field, f"a {key[0]} a client created (the operator's "
                                 f"start-up bridges stay)", "/".join(key[1]))


class BridgeQuota:
    """Counts live client-made bridges: each client's against ``limit`` and all of them,
    whoever made them and whether or not that client is still here, against ``total``.

    A creation reserves a slot before it runs (so a burst of slow async creations cannot
    overshoot) and gives it back if it fails or found an existing bridge; the removal of a
    bridge (by whichever client) frees the slot of the client that made it. A client that
    leaves takes its own count with it, not the total: what it made and others still hold
    or kept lives on, and frees its slot of the total when removed.
    """

    def __init__(self, limit: int, total: int = DEFAULT_MAX_BRIDGES) -> None:
        self.limit = limit
        self.total_limit = total
        self.total = 0
        self._counts: dict[object, int] = {}

    def reserve(self, client: object, op: str) -> bool:
        """Before `op` runs for `client`; True if a slot was taken (to `settle` later)."""
        cls = REQUEST_TYPES.get(op)
        if cls is None or cls.creates is None:
            return False
        count = self._counts.get(client, 0)
        if count >= self.limit:
            raise LimitReachedError("op", f"at most {self.limit} bridges per client "
                                          f"(--max-bridges-per-client)",
                                    f"a bridge more ({op})")
        if self.total >= self.total_limit:
            raise LimitReachedError("op", f"at most {self.total_limit} bridges made by "
                                          f"clients, all together (--max-bridges; remove some)",
                                    f"a bridge more ({op})")
        self._counts[client] = count + 1
        self.total += 1
        return True

    def settle(self, client: object, reserved: bool, *, succeeded: bool,
               existed: bool) -> None:
        """After a creation for `client` finished: the slot goes back unless it made one."""
        if reserved and (not succeeded or existed):
            self.release(client)

    def forget(self, client: object) -> None:
        """The client left: its count goes (its bridges that others hold or kept live on)."""
        self._counts.pop(client, None)

    def count(self, client: object) -> int:
        return self._counts.get(client, 0)

    def release(self, client: object, bridges: int = 1) -> None:
        """`bridges` that `client` made are gone (the client may have left)."""
        self.total = max(0, self.total - bridges)
        count = self._counts.get(client, 0) - bridges
        if count > 0:
            self._counts[client] = count
        else:
            self._counts.pop(client, None)

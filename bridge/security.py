"""Who may connect and what a client may do: the daemon's security policy, in one place.

An OpenIGTLink peer has no authentication, and this daemon can publish to a robot, so the
policy decides from what can be known: the peer's address (at accept, `admits`), and the
request itself (in the dispatcher, `check_request`, before any capability runs). Start-up
bridges from the YAML config go through the same dispatcher, so they are judged alike.

Name rules follow rosbridge / foxglove_bridge: shell-style globs on fully qualified names
(``*`` also matches ``/``); a deny glob always wins; once any allow glob is given for a
kind, only names matching one of them are allowed. tf frames get the same rules, judged as
the tf buffer holds them (``--frame-prefix`` applied, no leading ``/``).

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

from protocol.commands import CreateRobot, ForbiddenError, LimitReachedError, RobotSource

log = logging.getLogger(__name__)

Network = Union[ipaddress.IPv4Network, ipaddress.IPv6Network]
NameResolver = Callable[[str, str], str]  # (name, field) -> fully qualified name
FrameResolver = Callable[[str], str]  # a client's frame id -> the tf buffer's
FileResolver = Callable[[str], "os.PathLike[str] | str"]  # a robot file source -> its path

# Ops a --read-only daemon refuses: everything that changes the ROS graph or its state.
# Receiving (subscribers, lookups, robots, reading parameters, listings) stays allowed.
WRITE_OPS: frozenset[str] = frozenset({
    "create_publisher", "publish",
    "create_tf_broadcaster", "broadcast_transform",
    "set_parameters", "server_declare_parameter", "server_set_parameter",
    "server_undeclare_parameter",
    "call_service", "advertise_service",
})

# Ops that create one bridge (counted against --max-bridges-per-client) and the op that
# removes it again.
CREATE_OPS: frozenset[str] = frozenset({
    "create_subscriber", "create_publisher", "create_tf_lookup", "create_tf_broadcaster",
    "create_parameter_client", "create_robot", "advertise_service",
})
REMOVE_OPS: dict[str, str] = {
    "remove_subscriber": "create_subscriber", "remove_publisher": "create_publisher",
    "remove_tf_lookup": "create_tf_lookup", "remove_tf_broadcaster": "create_tf_broadcaster",
    "remove_parameter_client": "create_parameter_client", "remove_robot": "create_robot",
    "unadvertise_service": "advertise_service",
}


@dataclass(frozen=True)
class Target:
    """Which request field names the ROS resource an op touches.

    ``kind`` is ``topic``, ``service`` or ``parameter``. For parameters, ``node_field``
    names the node field (``None``: the daemon's own node) and the judged name is
    ``<node>.<parameter>`` (``/robot_state_publisher.robot_description``), as in
    foxglove_bridge.
    """

    kind: str
    field: str
    node_field: Optional[str] = None


# op -> what the name rules judge. Removals are not judged: a denied bridge never exists.
TARGETS: dict[str, Target] = {
    "create_subscriber": Target("topic", "topic"),
    "create_publisher": Target("topic", "topic"),
    "publish": Target("topic", "topic"),
    "get_last_message": Target("topic", "topic"),
    "call_service": Target("service", "service"),
    "advertise_service": Target("service", "service"),
    "get_parameters": Target("parameter", "names", "node"),
    "set_parameters": Target("parameter", "values", "node"),
    "observe_parameters": Target("parameter", "names", "node"),
    "server_declare_parameter": Target("parameter", "name"),
    "server_set_parameter": Target("parameter", "name"),
    "server_get_parameters": Target("parameter", "names"),
    "server_undeclare_parameter": Target("parameter", "name"),
}

# op -> its request fields that name tf frames (both ends: a lookup reveals, a broadcaster
# writes, the pose of the child relative to the parent). A TRANSFORM sent to a broadcaster's
# device needs no check of its own: it carries the frames of a broadcaster that exists, and
# one whose frames the policy denies is never created.
FRAME_FIELDS: dict[str, tuple[str, ...]] = {
    "create_tf_lookup": ("parent", "child"),
    "lookup_transform": ("parent", "child"),
    "create_tf_broadcaster": ("parent", "child"),
    "broadcast_transform": ("parent", "child"),
}


def strip_frame(frame: str) -> str:
    """The frame resolver of a daemon without ``--frame-prefix``: tf2 ids have no leading
    ``/``, so ``/base`` and ``base`` are one frame (and one name to judge)."""
    return frame.lstrip("/")


DEFAULT_MAX_CLIENTS = 64
DEFAULT_MAX_BRIDGES_PER_CLIENT = 1000


class PolicyError(ValueError):
    """A security option or config entry is invalid; says which and what was expected."""


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
    parameters: NameRules = NameRules()
    frames: NameRules = NameRules()
    max_clients: int = DEFAULT_MAX_CLIENTS
    max_bridges_per_client: int = DEFAULT_MAX_BRIDGES_PER_CLIENT
    # Folders whose URDF files clients may load by path (`--robot-dir`, and the daemon adds
    # every `--package-path` folder): a client must not make the daemon read any file.
    robot_dirs: tuple[str, ...] = ()

    # --- at accept -----------------------------------------------------------------------
    def admits(self, address: str) -> bool:
        """May a client from `address` (an IP literal) connect?"""
        if not self.allowed_networks:
            return True
        try:
            ip = ipaddress.ip_address(address.split("%", 1)[0])
        except ValueError:  # not an IP peer (a Unix socket): no network rule can admit it
            return False
        if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
            ip = ip.ipv4_mapped  # a dual-stack socket reports IPv4 peers as ::ffff:a.b.c.d
        return any(ip.version == net.version and ip in net for net in self.allowed_networks)

    # --- per request ---------------------------------------------------------------------
    def check_request(self, request: Any, resolve: NameResolver, own_node: str,
                      resolve_frame: FrameResolver = strip_frame, *,
                      from_client: bool = True,
                      resolve_file: Optional[FileResolver] = None) -> None:
        """Raise `ForbiddenError` if the policy refuses this parsed request.

        `resolve(name, field)` makes a topic, service or node name fully qualified (so
        ``cmd_vel`` cannot slip past a deny glob on ``/cmd_vel``); `own_node` is the
        daemon's node, owner of the ``server_*`` parameters; `resolve_frame` turns a
        client's frame id into the one the tf buffer uses (the daemon passes the tf
        capability's, so ``--frame-prefix`` cannot be used to slip past a frame glob);
        `resolve_file` turns a robot's file source into the path the daemon would read.
        `from_client` is False for the operator's own start-up config, whose file paths are
        trusted.
        """
        op = request.op
        if self.read_only and op in WRITE_OPS:
            raise ForbiddenError("op", "an op that only receives (the daemon runs "
                                       "--read-only)", op)
        if op in FRAME_FIELDS:
            self._check_frames(request, FRAME_FIELDS[op], resolve_frame)
            return
        if isinstance(request, CreateRobot):
            if request.fixed_frame:  # links are judged when the URDF loads
                self._check_frames(request, ("fixed_frame",), strip_frame)
            self._check_robot_source(request, resolve)
            if from_client and request.source.kind == "file" and resolve_file is not None:
                self._check_robot_file(str(request.source.path), resolve_file)
            return
        target = TARGETS.get(op)
        if target is None:
            return
        rules = self._rules(target.kind)
        if not rules.active:
            return
        if target.kind == "parameter":
            self._check_parameters(request, target, rules, resolve, own_node)
            return
        name = resolve(getattr(request, target.field), target.field)
        if not rules.permits(name):
            raise ForbiddenError(target.field, f"a {target.kind} this daemon exposes: "
                                 + rules.why_not(name), name)

    def _check_frames(self, request: Any, fields: tuple[str, ...],
                      resolve_frame: FrameResolver) -> None:
        if not self.frames.active:
            return
        for name in fields:
            # Judged as the buffer holds it; an empty result is the tf capability's error.
            frame = strip_frame(resolve_frame(getattr(request, name)))
            if frame and not self.frames.permits(frame):
                raise ForbiddenError(name, "a tf frame this daemon exposes: "
                                     + self.frames.why_not(frame), frame)

    def _check_robot_source(self, request: CreateRobot, resolve: NameResolver) -> None:
        """A robot reads its URDF from a parameter or a topic: the same rules as reading
        them directly (else create_robot would read a denied parameter). A file source
        names no ROS resource: nothing to judge here."""
        source = request.source
        if source.kind == "parameter" and self.parameters.active:
            node = _robot_source_name(request, source.node, RobotSource.node,
                                      "source.node", resolve)
            full = f"{node}.{source.parameter}"
            if not self.parameters.permits(full):
                raise ForbiddenError("source.parameter", "a parameter this daemon exposes: "
                                     + self.parameters.why_not(full), full)
        elif source.kind == "topic" and self.topics.active:
            topic = _robot_source_name(request, source.topic, RobotSource.topic,
                                       "source.topic", resolve)
            if not self.topics.permits(topic):
                raise ForbiddenError("source.topic", "a topic this daemon exposes: "
                                     + self.topics.why_not(topic), topic)

    def _check_robot_file(self, spec: str, resolve_file: FileResolver) -> None:
        # Symlinks followed, so a link inside an allowed folder cannot point outside it.
        real = os.path.realpath(resolve_file(spec))
        for folder in self.robot_dirs:
            root = os.path.realpath(folder)
            if os.path.commonpath([real, root]) == root:
                return
        allowed = ", ".join(self.robot_dirs) or "none: start the daemon with --robot-dir"
        raise ForbiddenError("source.path", f"a URDF file inside a --robot-dir or "
                             f"--package-path folder ({allowed})", spec)

    def _check_parameters(self, request: Any, target: Target, rules: NameRules,
                          resolve: NameResolver, own_node: str) -> None:
        node = (resolve(getattr(request, target.node_field), target.node_field)
                if target.node_field else own_node)
        value = getattr(request, target.field)
        names: Iterable[str] = (value,) if isinstance(value, str) else tuple(value)
        if not names:
            # "All parameters" cannot be judged name by name before they are known.
            raise ForbiddenError(target.field, "explicit parameter names (parameter globs "
                                 "are set)", "all parameters")
        for name in names:
            full = f"{node}.{name}"
            if not rules.permits(full):
                raise ForbiddenError(target.field, "a parameter this daemon exposes: "
                                     + rules.why_not(full), full)

    def _rules(self, kind: str) -> NameRules:
        return {"topic": self.topics, "service": self.services,
                "parameter": self.parameters}[kind]

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
        policy = replace(policy, allowed_networks=networks)
        for kind in ("topics", "services", "parameters", "frames"):
            rules = NameRules(allow=_globs(settings, f"allow_{kind}", where),
                              deny=_globs(settings, f"deny_{kind}", where))
            policy = replace(policy, **{kind: rules})
        dirs = _globs(settings, "robot_dirs", where)
        policy = replace(policy, robot_dirs=tuple(dirs))
        for key in ("max_clients", "max_bridges_per_client"):
            if settings.get(key) is not None:
                policy = replace(policy, **{key: positive_int(settings[key], f"{where}.{key}")})
        return policy

    def describe(self) -> str:
        """One log line: what is locked down."""
        parts = ["read-only" if self.read_only else "read-write",
                 "clients from " + (", ".join(map(str, self.allowed_networks))
                                    if self.allowed_networks else "any address"),
                 f"at most {self.max_clients} clients",
                 f"{self.max_bridges_per_client} bridges per client"]
        for kind in ("topics", "services", "parameters", "frames"):
            rules: NameRules = getattr(self, kind)
            if rules.active:
                parts.append(f"{kind} allow={list(rules.allow)} deny={list(rules.deny)}")
        return "; ".join(parts)


# Keys of the YAML `security:` section; the command-line options of the same names (with
# dashes, singular for the repeatable ones) add to them.
SECURITY_KEYS: tuple[str, ...] = (
    "read_only", "allow",
    "allow_topics", "deny_topics", "allow_services", "deny_services",
    "allow_parameters", "deny_parameters", "allow_frames", "deny_frames",
    "max_clients", "max_bridges_per_client", "max_message_bytes", "max_send_buffer_bytes",
    "robot_dirs",
)


def _robot_source_name(request: CreateRobot, name: str, default: str, field: str,
                       resolve: NameResolver) -> str:
    """The node or topic a robot reads, as RobotBridges._resolve_source places it: the
    robot's ``namespace`` applies to relative names and to the default, then the daemon's
    (``{"namespace": "PSM1"}`` reads ``/PSM1/robot_state_publisher``). Kept in step with it
    by tests/hardening/test_security_frames_daemon.py, which asks a running daemon."""
    if request.namespace:
        namespace = resolve(request.namespace, "namespace")
        if name == default or not name.startswith("/"):
            name = f"{namespace.rstrip('/')}/{name.lstrip('/')}"
    return resolve(name, field)


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


def is_loopback_host(host: str) -> bool:
    """Does listening on `host` keep the daemon reachable from this machine only?"""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False  # a host name: whatever it resolves to may be reachable from outside


class BridgeQuota:
    """Counts each client's live bridges against ``max_bridges_per_client``.

    A creation reserves a slot before it runs (so a burst of slow async creations cannot
    overshoot) and gives it back if it fails or found an existing bridge; a removal by the
    same client frees one.
    """

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self._counts: dict[object, int] = {}

    def reserve(self, client: object, op: str) -> bool:
        """Before `op` runs for `client`; True if a slot was taken (to `settle` later)."""
        if op not in CREATE_OPS:
            return False
        count = self._counts.get(client, 0)
        if count >= self.limit:
            raise LimitReachedError("op", f"at most {self.limit} bridges per client "
                                          f"(--max-bridges-per-client)",
                                    f"a bridge more ({op})")
        self._counts[client] = count + 1
        return True

    def settle(self, client: object, op: str, reserved: bool,
               result: Optional[Mapping[str, Any]]) -> None:
        """After `op` for `client` finished (`result` None: it failed)."""
        if reserved and (result is None or result.get("existed") is True):
            self._release(client)
        elif op in REMOVE_OPS and result is not None:
            self._release(client)

    def forget(self, client: object) -> None:
        """The client left: its bridges live on (they are daemon-wide), its count goes."""
        self._counts.pop(client, None)

    def count(self, client: object) -> int:
        return self._counts.get(client, 0)

    def _release(self, client: object) -> None:
        count = self._counts.get(client, 0)
        if count > 1:
            self._counts[client] = count - 1
        else:
            self._counts.pop(client, None)


_DENIED_LOG_INTERVAL_S = 5.0


@dataclass
class RateLimitedLog:
    """Logs a repeated warning at most once per interval per key, counting the rest."""

    logger: logging.Logger = log
    interval_s: float = _DENIED_LOG_INTERVAL_S
    _last: dict[str, float] = field(default_factory=dict)
    _suppressed: dict[str, int] = field(default_factory=dict)

    def warning(self, key: str, now: float, message: str, *args: object) -> None:
        last = self._last.get(key)
        if last is not None and now - last < self.interval_s:
            self._suppressed[key] = self._suppressed.get(key, 0) + 1
            return
        self._last[key] = now
        suppressed = self._suppressed.pop(key, 0)
        if suppressed:
            message += f" ({suppressed} more like it not logged)"
        self.logger.warning(message, *args)

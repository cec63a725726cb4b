"""The daemon's configuration: command-line options, and a YAML file of start-up bridges.

The YAML file lets a plain OpenIGTLinkIF user (no client code) get streams at start-up.
Each entry of a section is exactly the JSON arguments of the command named beside it, so
the file is checked by the same schema, and gets the same errors, as a client's commands:

    subscribers:            # create_subscriber
      - {topic: /tool_pose, type: PoseStamped, max_rate_hz: 60}
    publishers:             # create_publisher
      - {topic: /target, type: geometry_msgs/msg/PoseStamped}

A ``security:`` section (docs/security.md) locks the daemon down; the command-line options
of the same names add to it (globs, networks) or override it (limits):

    security:
      read_only: true
      allow: [127.0.0.1/32, 10.0.0.0/8]
      key_file: /etc/slicer-ros2-bridge/writers.key   # writers present it (docs/deployment.md)
      trust: [10.0.0.5/32]                            # plain clients that may write
      deny_topics: ["/cmd_vel", "/rosout*"]
      max_clients: 8
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
import ssl
from typing import Any, Mapping, Optional

import yaml

from bridge.core.security import PolicyError, SecurityPolicy, positive_int
from bridge.core.session import SessionLimits
from protocol.commands import bridge_kinds

# Section name in the YAML file -> the command each of its entries is: every creating op
# that declares a section (`protocol.commands.Bridge.section`).
SECTIONS: dict[str, str] = {kind.bridge.section: kind.create.op
                            for kind in bridge_kinds().values()
                            if kind.bridge.section is not None}
SECURITY_SECTION = "security"

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 18944
DEFAULT_TLS_PORT = 18945


class ConfigError(Exception):
    """The configuration file cannot be used; says where and what was expected."""


@dataclass(frozen=True)
class StartupCommand:
    op: str
    arguments: dict[str, Any]
    where: str  # "config.yaml: subscribers[2]", for error messages


@dataclass(frozen=True)
class FastPaths:
    """Which compiled fast paths the daemon takes where they are built. Each has a slower
    twin that gives the same results; turning one off is for comparing them (bench/) or
    ruling one out (bridge/platform/README.md)."""

    compiled_tf: bool = True  # --tf-store: compiled, or the pure-Python reference store
    rcl_take: bool = True  # --ros-take: rcl without the interpreter's lock, or rclpy
    send_batch: bool = True  # --send-batch: one io_uring call for all clients, or one each


# The host workarounds (bridge/platform/) a daemon can run without, to weigh each one.
WORKAROUNDS = ("receive-slice", "gil-switch", "collector", "mmap-threshold")


@dataclass(frozen=True)
class DaemonConfig:
    host: str = DEFAULT_HOST
    port: int = DEFAULT_PORT
    node_name: str = "slicer_bridge"
    namespace: str = ""
    log_level: str = "INFO"
    limits: SessionLimits = field(default_factory=SessionLimits)
    security: SecurityPolicy = field(default_factory=SecurityPolicy)
    startup: tuple[StartupCommand, ...] = ()
    package_paths: tuple[tuple[str, str], ...] = ()
    # Put before clients' relative tf frame ids ("PSM1/"): one daemon per robot instance.
    frame_prefix: str = ""
    # After a stop signal, the process exits after this long even if ROS's teardown hangs.
    stop_timeout_s: float = 10.0
    # What followed --ros-args (remaps, __node, __ns, ...), for the daemon's node to apply.
    ros_args: tuple[str, ...] = ()
    # A second listener, OpenIGTLink over TLS, for the project's own clients (--tls-cert).
    tls: Optional[TlsListener] = None
    # SCHED_FIFO priority of the DDS receive threads (bridge/platform/receive_priority.py).
    receive_priority: Optional[int] = None
    fast_paths: FastPaths = field(default_factory=FastPaths)
    # Host workarounds left out (`--without`; names from WORKAROUNDS).
    without: frozenset[str] = frozenset()


@dataclass(frozen=True)
class TlsListener:
    """The TLS port: a certificate chain and its private key (PEM files), checked at
    start-up (`context`), so a bad file stops the daemon with one line."""

    cert_file: str
    key_file: str
    port: int = DEFAULT_TLS_PORT

    def context(self) -> ssl.SSLContext:
        context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
        context.minimum_version = ssl.TLSVersion.TLSv1_2
        try:
            context.load_cert_chain(self.cert_file, self.key_file)
        except (OSError, ssl.SSLError) as error:
            raise ConfigError(f"--tls-cert/--tls-key: expected a PEM certificate chain and "
                              f"its private key, got {self.cert_file!r} and "
                              f"{self.key_file!r} ({error})") from None
        return context


@dataclass(frozen=True)
class ConfigFile:
    startup: tuple[StartupCommand, ...] = ()
    security: Mapping[str, Any] = field(default_factory=dict)  # the raw `security:` section
    name: str = ""


def load_config_file(path: Path) -> ConfigFile:
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as error:
        raise ConfigError(f"cannot read the config file {path}: {error.strerror}") from None
    try:
        document = yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise ConfigError(f"{path} is not valid YAML: {error}") from None
    if document is None:
        return ConfigFile(name=path.name)
    expected = ", ".join((*SECTIONS, SECURITY_SECTION))
    if not isinstance(document, dict):
        raise ConfigError(f"{path}: expected a mapping of sections ({expected}), got "
                          f"{type(document).__name__}")
    commands: list[StartupCommand] = []
    security: Mapping[str, Any] = {}
    for section, entries in document.items():
        if section == SECURITY_SECTION:
            if not isinstance(entries, dict):
                raise ConfigError(f"{path}: section {section!r} must be a mapping, got "
                                  f"{type(entries).__name__}")
            security = entries
            continue
        if section not in SECTIONS:
            raise ConfigError(f"{path}: unknown section {section!r}; expected one of "
                              f"{expected}")
        if not isinstance(entries, list):
            raise ConfigError(f"{path}: section {section!r} must be a list, got "
                              f"{type(entries).__name__}")
        for index, entry in enumerate(entries):
            where = f"{path.name}: {section}[{index}]"
            if not isinstance(entry, dict):
                raise ConfigError(f"{where}: expected a mapping of arguments, got "
                                  f"{type(entry).__name__}")
            commands.append(StartupCommand(SECTIONS[section], dict(entry), where))
    return ConfigFile(tuple(commands), security, path.name)


def build_security(file_settings: Mapping[str, Any], cli_settings: Mapping[str, Any],
                   where: str = "security") -> tuple[SecurityPolicy, SessionLimits]:
    """The policy and session limits from the config's ``security:`` section and the
    command line (same keys): lists add up, ``read_only`` is on if either says so, a limit
    given on the command line wins over the file's."""
    merged: dict[str, Any] = dict(file_settings)
    for key, value in cli_settings.items():
        if value is None or value == [] or value is False:
            continue
        if isinstance(value, list):
            previous = merged.get(key) or []
            merged[key] = [*([previous] if isinstance(previous, str) else previous), *value]
        else:
            merged[key] = value
    try:
        policy = SecurityPolicy.from_settings(merged, where)
        limits = SessionLimits()
        for key, attribute in (("max_message_bytes", "max_message_bytes"),
                               ("max_send_buffer_bytes", "max_oneshot_bytes")):
            if merged.get(key) is not None:
                limits = replace(limits, **{attribute: positive_int(merged[key],
                                                                    f"{where}.{key}")})
    except PolicyError as error:
        raise ConfigError(str(error)) from None
    return policy, limits

"""The daemon's configuration: command-line options, and a YAML file of start-up bridges.

The YAML file lets a plain OpenIGTLinkIF user (no client code) get streams at start-up.
Each entry of a section is exactly the JSON arguments of the command named beside it, so
the file is checked by the same schema, and gets the same errors, as a client's commands:

    subscribers:            # create_subscriber
      - {topic: /tool_pose, type: PoseStamped, max_rate_hz: 60}
    publishers:             # create_publisher
      - {topic: /target, type: geometry_msgs/msg/PoseStamped}
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from bridge.session import SessionLimits

# Section name in the YAML file -> the command each of its entries is.
SECTIONS: dict[str, str] = {
    "subscribers": "create_subscriber",
    "publishers": "create_publisher",
    "tf_lookups": "create_tf_lookup",
    "tf_broadcasters": "create_tf_broadcaster",
    "parameter_clients": "create_parameter_client",
    "robots": "create_robot",
}

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 18944


class ConfigError(Exception):
    """The configuration file cannot be used; says where and what was expected."""


@dataclass(frozen=True)
class StartupCommand:
    op: str
    arguments: dict[str, Any]
    where: str  # "config.yaml: subscribers[2]", for error messages


@dataclass(frozen=True)
class DaemonConfig:
    host: str = DEFAULT_HOST
    port: int = DEFAULT_PORT
    node_name: str = "slicer_bridge"
    namespace: str = ""
    log_level: str = "INFO"
    limits: SessionLimits = field(default_factory=SessionLimits)
    startup: tuple[StartupCommand, ...] = ()
    package_paths: tuple[tuple[str, str], ...] = ()


def load_startup_commands(path: Path) -> tuple[StartupCommand, ...]:
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as error:
        raise ConfigError(f"cannot read the config file {path}: {error.strerror}") from None
    try:
        document = yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise ConfigError(f"{path} is not valid YAML: {error}") from None
    if document is None:
        return ()
    if not isinstance(document, dict):
        raise ConfigError(f"{path}: expected a mapping of sections "
                          f"({', '.join(SECTIONS)}), got {type(document).__name__}")
    commands: list[StartupCommand] = []
    for section, entries in document.items():
        if section not in SECTIONS:
            raise ConfigError(f"{path}: unknown section {section!r}; expected one of "
                              f"{', '.join(SECTIONS)}")
        if not isinstance(entries, list):
            raise ConfigError(f"{path}: section {section!r} must be a list, got "
                              f"{type(entries).__name__}")
        for index, entry in enumerate(entries):
            where = f"{path.name}: {section}[{index}]"
            if not isinstance(entry, dict):
                raise ConfigError(f"{where}: expected a mapping of arguments, got "
                                  f"{type(entry).__name__}")
            commands.append(StartupCommand(SECTIONS[section], dict(entry), where))
    return tuple(commands)

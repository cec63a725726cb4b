"""`--ros-args`, as every rclpy node takes them, mapped onto the daemon's own options.

`ros2 run slicer_ros2_bridge bridge --port 19000 --ros-args -r __ns:=/lab -p host:=0.0.0.0`
works as a ROS user expects:

- remapping rules (`-r __node:=NAME`, `-r __ns:=/NS`, `-r /from:=/to`) and the rest of
  the ROS arguments go to the daemon's node, which rcl applies (`RosOptions.ros_args`);
- parameters (`-p name:=value`, `--param`, `--params-file FILE`) whose name is one of the
  daemon's options (`port`, `host`, `config`, `read_only`, `allow_topic`, ...: the option's
  long name with `_` for `-`) set that option. Values are YAML, as rcl reads them. Of a
  params file, only the sections rcl gives the daemon's node count: `/**`, its name, its
  namespace and name (flat `/ns/name:` or nested), `*` and `**` wildcards; another node's
  section (robot_state_publisher's `frame_prefix`) does not. The node is named by the
  command line (`--node-name`, `--namespace`, `-r __node:=`, `-r __ns:=`), not by a
  parameter. Later parameters win over earlier ones, as in rcl.

Precedence, highest first: an option given on the command line, then a ROS parameter, then
the `--config` file's `security:` section, then the default.
"""

from __future__ import annotations

import argparse
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

__all__ = ["RosArgsError", "RosArgs", "apply_parameters", "split_ros_args"]

ROS_ARGS_START = "--ros-args"
ROS_ARGS_END = "--"


class RosArgsError(Exception):
    """A ROS argument the daemon cannot use; the text says which and what was expected."""


@dataclass
class RosArgs:
    """What followed `--ros-args`: everything for rcl, and the parameters read from it."""

    argv: list[str] = field(default_factory=list)
    # (node name pattern, parameters) in command-line order; `-p` gives every node ("/**").
    sources: list[tuple[str, dict[str, Any]]] = field(default_factory=list)

    def parameters_for(self, node: str) -> dict[str, Any]:
        """The parameters rcl gives the node of fully qualified name `node`."""
        found: dict[str, Any] = {}
        for pattern, parameters in self.sources:
            if _node_pattern(pattern).fullmatch(node):
                found.update(parameters)
        return found

    def node_name(self, name: str, namespace: str) -> str:
        """The daemon node's fully qualified name: `name` and `namespace` (its options),
        unless a `__node`/`__name`/`__ns` remap of these arguments says otherwise."""
        for flag, rule in zip(self.argv, self.argv[1:]):
            if flag in ("-r", "--remap"):
                key, sep, value = rule.partition(":=")
                if sep and key in ("__node", "__name"):
                    name = value
                elif sep and key == "__ns":
                    namespace = value
        return "/" + "/".join(part for part in (*namespace.split("/"), name) if part)


def split_ros_args(argv: Sequence[str]) -> tuple[list[str], RosArgs]:
    """The daemon's own arguments, and the ROS ones (each `--ros-args ... [--]` section)."""
    ours: list[str] = []
    ros = RosArgs()
    inside = False
    items = list(argv)
    i = 0
    while i < len(items):
        item = items[i]
        if item == ROS_ARGS_START:
            inside = True
        elif inside and item == ROS_ARGS_END:
            inside = False
        elif inside:
            ros.argv.append(item)
            if item in ("-p", "--param", "--params-file"):
                if i + 1 >= len(items):
                    raise RosArgsError(f"{item}: expected a value after it, got nothing")
                value = items[i + 1]
                ros.argv.append(value)
                i += 1
                if item == "--params-file":
                    ros.sources.extend(_params_file(Path(value)))
                else:
                    name, value_text = _parameter(value)
                    ros.sources.append(("/**", {name: value_text}))
        else:
            ours.append(item)
        i += 1
    return ours, ros


def _parameter(text: str) -> tuple[str, Any]:
    name, sep, value = text.partition(":=")
    if not sep or not name:
        raise RosArgsError(f"-p: expected name:=value, got {text!r}")
    try:
        return name, yaml.safe_load(value)
    except yaml.YAMLError as error:
        raise RosArgsError(f"-p {name}: expected a YAML value, got {value!r} "
                           f"({' '.join(str(error).split())})") \
            from None


def _params_file(path: Path) -> list[tuple[str, dict[str, Any]]]:
    """The sections of a ROS params file: (node name pattern, its ``ros__parameters``), the
    pattern joined from nested keys (``/lab: {arm: {ros__parameters: ...}}`` is
    ``/lab/arm``) and absolute (``arm`` is ``/arm``, as rcl reads it)."""
    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as error:
        # One line: a YAML error's text spans several (the line, a caret).
        raise RosArgsError(f"--params-file: expected a readable YAML file, got {path} "
                           f"({' '.join(str(error).split())})") from None
    found: list[tuple[str, dict[str, Any]]] = []

    def walk(prefix: str, mapping: dict[Any, Any]) -> None:
        for key, value in mapping.items():
            if not isinstance(value, dict):
                continue
            if key == "ros__parameters":
                found.append((prefix or "/", value))
            else:
                walk(f"{prefix.rstrip('/')}/{str(key).strip('/')}", value)

    if isinstance(data, dict):
        walk("", data)
    return found


def _node_pattern(pattern: str) -> re.Pattern[str]:
    """rcl's node name wildcards as a regular expression: ``*`` one name part, ``**`` any
    number of them (``/**`` every node)."""
    parts = [part for part in pattern.split("/") if part]
    regex = "".join("(/[^/]+)*" if part == "**"
                    else "/" + re.escape(part).replace(r"\*", "[^/]+") for part in parts)
    return re.compile(regex or "/")


def apply_parameters(parser: argparse.ArgumentParser, args: argparse.Namespace,
                     our_argv: Sequence[str], parameters: dict[str, Any]) -> None:
    """Set the options that ROS parameters name, unless the command line gave them."""
    actions = {action.dest: action for action in parser._actions  # noqa: SLF001 - argparse
               if action.option_strings and action.dest != "help"}
    given = {action.dest for action in actions.values()
             if any(arg == opt or arg.startswith(opt + "=") for arg in our_argv
                    for opt in action.option_strings)}
    for name, value in parameters.items():
        action = actions.get(name)
        if action is None:
            continue  # a parameter for rcl (use_sim_time...), not an option of ours
        if name in given:
            continue  # the command line wins
        setattr(args, name, _convert(action, name, value))


def _convert(action: argparse.Action, name: str, value: Any) -> Any:
    if action.nargs == 0:  # a flag (store_true)
        if not isinstance(value, bool):
            raise RosArgsError(f"-p {name}: expected true or false, got {value!r}")
        return value
    values = value if isinstance(value, list) else [value]
    converted = []
    for item in values:
        try:
            converted.append(action.type(str(item)) if callable(action.type) else str(item))
        except (argparse.ArgumentTypeError, ValueError, TypeError) as error:
            raise RosArgsError(f"-p {name}: expected a value --{name.replace('_', '-')} "
                               f"takes, got {item!r} ({error})") from None
    if action.choices is not None and any(c not in action.choices for c in converted):
        raise RosArgsError(f"-p {name}: expected one of {', '.join(map(str, action.choices))},"
                           f" got {value!r}")
    if isinstance(action, argparse._AppendAction):  # noqa: SLF001 - repeatable options
        return converted
    if len(converted) != 1:
        raise RosArgsError(f"-p {name}: expected one value, got {value!r}")
    return converted[0]


def domain_id_from_environment() -> int:
    """The ROS domain this process's ROS joins, as rcl reads it (ROS_DOMAIN_ID, default 0;
    rcl refuses a bad value at init, so one here counts as 0)."""
    text = os.environ.get("ROS_DOMAIN_ID", "").strip()
    return int(text) if text.isdigit() else 0

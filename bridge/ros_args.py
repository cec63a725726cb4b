"""`--ros-args`, as every rclpy node takes them, mapped onto the daemon's own options.

`ros2 run slicer_ros2_bridge bridge --port 19000 --ros-args -r __ns:=/lab -p host:=0.0.0.0`
works as a ROS user expects:

- remapping rules (`-r __node:=NAME`, `-r __ns:=/NS`, `-r /from:=/to`) and the rest of
  the ROS arguments go to the daemon's node, which rcl applies (`RosOptions.ros_args`);
- parameters (`-p name:=value`, `--param`, `--params-file FILE`) whose name is one of the
  daemon's options (`port`, `host`, `config`, `read_only`, `allow_topic`, ...: the option's
  long name with `_` for `-`) set that option. Values are YAML, as rcl reads them.

Precedence, highest first: an option given on the command line, then a ROS parameter, then
the `--config` file's `security:` section, then the default.
"""

from __future__ import annotations

import argparse
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
    parameters: dict[str, Any] = field(default_factory=dict)


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
                    ros.parameters.update(_params_file(Path(value)))
                else:
                    name, value_text = _parameter(value)
                    ros.parameters[name] = value_text
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
        raise RosArgsError(f"-p {name}: expected a YAML value, got {value!r} ({error})") \
            from None


def _params_file(path: Path) -> dict[str, Any]:
    """The parameters a ROS params file gives every node (`/**`) or any node of ours: the
    daemon takes what names its options and leaves the rest to rcl."""
    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as error:
        raise RosArgsError(f"--params-file: expected a readable YAML file, got {path} "
                           f"({error})") from None
    found: dict[str, Any] = {}
    if isinstance(data, dict):
        for section in data.values():
            if isinstance(section, dict) and isinstance(section.get("ros__parameters"), dict):
                found.update(section["ros__parameters"])
    return found


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

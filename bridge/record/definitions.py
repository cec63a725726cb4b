"""A message type's full ``ros2msg`` definition, as rosbag2 stores it in a bag's schema.

The type's own ``.msg`` text, then each message type it uses (at any depth, once), each
after a line of 80 ``=`` and ``MSG: pkg/Type``: what `ros2 bag`, Foxglove and rosbags read
to decode a bag without the types installed. The texts are the ``.msg`` files the
interface packages install (``PREFIX/share/PKG/msg/TYPE.msg``), read as they are, comments
and constants included, as rosbag2 does.

No ROS import: the prefixes are ``AMENT_PREFIX_PATH``'s, then this environment's own (the
ROS 2 wheels install their ``share/`` into it), so the player side can use it too.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Optional

__all__ = ["DefinitionError", "MessageDefinitions", "SEPARATOR", "full_definition"]

SEPARATOR = "=" * 80
PRIMITIVES = frozenset({"bool", "byte", "char", "float32", "float64", "int8", "uint8",
                        "int16", "uint16", "int32", "uint32", "int64", "uint64", "string",
                        "wstring"})
MAX_DEPTH = 32  # a type nested deeper than this is a cycle (a .msg cannot hold itself)


class DefinitionError(Exception):
    """A type's definition cannot be found or read; the text says which and where."""


def _split_type(name: str) -> tuple[str, str]:
    """``pkg/msg/Type`` or ``pkg/Type`` -> (pkg, Type)."""
    parts = name.strip("/").split("/")
    if len(parts) == 3 and parts[1] == "msg":
        return parts[0], parts[2]
    if len(parts) == 2:
        return parts[0], parts[1]
    raise DefinitionError(f"expected a message type pkg/msg/Type, got {name!r}")


def _field_types(text: str, package: str) -> list[str]:
    """The message types (``pkg/Type``) a .msg text's fields use, in order."""
    used = []
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        words = line.split()
        if len(words) < 2 or "=" in words[1] or (len(words) > 2 and words[2].startswith("=")):
            continue  # a constant (TYPE NAME=VALUE), not a field
        base = words[0].split("[", 1)[0].split("<=", 1)[0]
        if base in PRIMITIVES:
            continue
        if "/" not in base:
            base = "std_msgs/Header" if base == "Header" else f"{package}/{base}"
        used.append(base)
    return used


def _default_prefixes() -> tuple[Path, ...]:
    listed = [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    return tuple(dict.fromkeys([*listed, Path(sys.prefix)]))


@dataclass
class MessageDefinitions:
    """Finds and concatenates definitions under ``prefixes`` (default: see the module)."""

    prefixes: tuple[Path, ...] = field(default_factory=_default_prefixes)

    def msg_file(self, package: str, name: str) -> Path:
        for prefix in self.prefixes:
            path = prefix / "share" / package / "msg" / f"{name}.msg"
            if path.is_file():
                return path
        raise DefinitionError(
            f"expected {package}/msg/{name}.msg under share/ of an interface prefix "
            f"(AMENT_PREFIX_PATH, or this environment: {sys.prefix}), got none in "
            f"{len(self.prefixes)} prefix(es)")

    def text(self, package: str, name: str) -> str:
        path = self.msg_file(package, name)
        try:
            return path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as error:
            raise DefinitionError(f"expected a readable UTF-8 file, got {path}: "
                                  f"{error}") from None

    def full(self, ros_type: str) -> str:
        """The concatenated definition of ``ros_type`` (``pkg/msg/Type``)."""
        package, name = _split_type(ros_type)
        top = self.text(package, name)
        sections: dict[str, str] = {}
        pending = [(used, 1) for used in _field_types(top, package)]
        while pending:
            used, depth = pending.pop(0)
            if used in sections:
                continue
            if depth > MAX_DEPTH:
                raise DefinitionError(f"expected message types nested at most {MAX_DEPTH} "
                                      f"deep, got {ros_type} nesting {used} deeper")
            sub_package, sub_name = _split_type(used)
            sections[used] = text = self.text(sub_package, sub_name)
            pending.extend((more, depth + 1) for more in _field_types(text, sub_package))
        parts = [top.rstrip("\n")]
        for used, text in sections.items():
            parts.append(f"{SEPARATOR}\nMSG: {used}\n{text.rstrip(chr(10))}")
        return "\n".join(parts) + "\n"


@lru_cache(maxsize=256)
def full_definition(ros_type: str, prefixes: Optional[tuple[Path, ...]] = None) -> str:
    """`MessageDefinitions.full` with the default prefixes (cached: files do not change
    while a process records)."""
    finder = MessageDefinitions(prefixes) if prefixes is not None else MessageDefinitions()
    return finder.full(ros_type)

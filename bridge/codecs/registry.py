"""ROS type names: resolve what a user typed to ``pkg/msg/Type`` and load the message class.

Accepted spellings: the protocol's grammar (`protocol.commands.types`: short names of the
reference, its node class names, ``pkg/msg/Type``, ``pkg/Type``, ``pkg.msg.Type``) and any
other bare message name (``"NavSatFix"``) found in exactly one installed package.

rclpy only: no ament index is needed (the PyPI wheels install none), installed interface
packages are found on ``sys.path`` by their ``msg/__init__.py``.
"""

from __future__ import annotations

import importlib
import os
import re
import sys
from functools import cache, lru_cache
from typing import Any

from bridge.codecs.errors import CodecError
from protocol.commands import REFERENCE_TYPE_NAMES, OutOfRangeError, resolve_message_type

__all__ = ["REFERENCE_SHORT_NAMES", "action_class", "installed_types", "message_class",
           "resolve_type",
           "ros_type_of",
           "service_class"]

# The reference's short names: one table, in the protocol (clients resolve them too).
REFERENCE_SHORT_NAMES = REFERENCE_TYPE_NAMES

_IDENT = r"[A-Za-z][A-Za-z0-9_]*"
_CANONICAL = re.compile(rf"^({_IDENT})/msg/({_IDENT})$")
_IMPORT_LINE = re.compile(rf"^from\s+({_IDENT})\.msg\.\w+\s+import\s+({_IDENT})", re.MULTILINE)


def _unknown(name: str, why: str) -> CodecError:
    return CodecError(field="type", expected=why, got=repr(name))


@cache
def message_class(ros_type: str) -> Any:
    """The rclpy message class of a canonical ``pkg/msg/Type``; `CodecError` if not installed."""
    m = _CANONICAL.match(ros_type)
    if m is None:
        raise _unknown(ros_type, "a message type 'pkg/msg/Type'")
    pkg, name = m.groups()
    try:
        module = importlib.import_module(f"{pkg}.msg")
    except ImportError:
        raise _unknown(ros_type, f"an installed interface package ({pkg!r} is not)") from None
    cls = getattr(module, name, None)
    if cls is None or not hasattr(cls, "get_fields_and_field_types"):
        raise _unknown(ros_type, f"a message of package {pkg!r} ({name!r} is not one)")
    return cls


_SERVICE = re.compile(rf"^({_IDENT})/srv/({_IDENT})$")


@cache
def service_class(ros_type: str) -> Any:
    """The rclpy service class of a canonical ``pkg/srv/Type``; `CodecError` if not installed."""
    m = _SERVICE.match(ros_type)
    if m is None:
        raise _unknown(ros_type, "a service type 'pkg/srv/Type'")
    pkg, name = m.groups()
    try:
        module = importlib.import_module(f"{pkg}.srv")
    except ImportError:
        raise _unknown(ros_type, f"an installed interface package ({pkg!r} is not)") from None
    cls = getattr(module, name, None)
    if cls is None or not hasattr(cls, "Request") or not hasattr(cls, "Response"):
        raise _unknown(ros_type, f"a service of package {pkg!r} ({name!r} is not one)")
    return cls


_ACTION = re.compile(rf"^({_IDENT})/action/({_IDENT})$")


@cache
def action_class(ros_type: str) -> Any:
    """The rclpy action class of a canonical ``pkg/action/Type``; `CodecError` if not
    installed."""
    m = _ACTION.match(ros_type)
    if m is None:
        raise _unknown(ros_type, "an action type 'pkg/action/Type'")
    pkg, name = m.groups()
    try:
        module = importlib.import_module(f"{pkg}.action")
    except ImportError:
        raise _unknown(ros_type, f"an installed interface package with actions ({pkg!r} "
                       f"has none here)") from None
    cls = getattr(module, name, None)
    if cls is None or not all(hasattr(cls, part) for part in ("Goal", "Result", "Feedback")):
        raise _unknown(ros_type, f"an action of package {pkg!r} ({name!r} is not one)")
    return cls


def ros_type_of(msg_or_class: Any) -> str:
    """``pkg/msg/Type`` of an rclpy message instance or class."""
    cls = msg_or_class if isinstance(msg_or_class, type) else type(msg_or_class)
    module = cls.__module__  # "sensor_msgs.msg._image"
    pkg = module.split(".", 1)[0]
    return f"{pkg}/msg/{cls.__name__}"


@lru_cache(maxsize=1)
def _installed_messages() -> dict[str, tuple[str, ...]]:
    """Bare message name -> packages defining it, read from every ``<pkg>/msg/__init__.py``
    on sys.path (the generated file lists one import per message, so no import is needed)."""
    found: dict[str, list[str]] = {}
    for entry in sys.path:
        if not entry or not os.path.isdir(entry):
            continue
        try:
            children = os.listdir(entry)
        except OSError:
            continue
        for pkg in children:
            init = os.path.join(entry, pkg, "msg", "__init__.py")
            if not os.path.isfile(init):
                continue
            try:
                with open(init, encoding="utf-8") as f:
                    text = f.read()
            except OSError:
                continue
            for imp_pkg, name in _IMPORT_LINE.findall(text):
                if imp_pkg == pkg and pkg not in found.setdefault(name, []):
                    found[name].append(pkg)
    return {name: tuple(sorted(pkgs)) for name, pkgs in found.items()}


def installed_types() -> tuple[str, ...]:
    """Every installed message type as ``pkg/msg/Type``, sorted (found without importing)."""
    return tuple(sorted(f"{pkg}/msg/{name}" for name, pkgs in _installed_messages().items()
                        for pkg in pkgs))


@lru_cache(maxsize=1024)
def resolve_type(name: str) -> str:
    """Any accepted spelling of a message type -> canonical ``pkg/msg/Type``.

    The grammar is the protocol's (`protocol.commands.resolve_message_type`, one for the
    whole project); here bare names are also looked up among the installed packages, and
    the type is checked to be installed. An unknown or ambiguous name raises `CodecError`
    with ``field="type"`` naming it.
    """
    if not isinstance(name, str):
        raise CodecError(field="type", expected="a message type name (str)",
                         got=type(name).__name__)
    try:
        ros_type = resolve_message_type(
            name, packages_of=lambda bare: _installed_messages().get(bare, ()))
    except OutOfRangeError as error:
        raise _unknown(name.strip(), error.expected) from None
    message_class(ros_type)
    return ros_type

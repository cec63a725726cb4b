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
from dataclasses import dataclass
from functools import cache, lru_cache
from typing import Any

from bridge.codecs.errors import CodecError
from protocol.commands import (REFERENCE_TYPE_NAMES, CommandFailedError, ErrorCode,
                               OutOfRangeError, resolve_message_type, resolve_service_type,
                               unknown_type)

__all__ = ["ACTION", "MESSAGE", "REFERENCE_SHORT_NAMES", "SERVICE", "InterfaceKind",
           "action_class", "installed_class", "installed_types", "interface_class",
           "message_class",
           "resolve_service", "resolve_type", "ros_type_of", "service_class"]

# The reference's short names: one table, in the protocol (clients resolve them too).
REFERENCE_SHORT_NAMES = REFERENCE_TYPE_NAMES

_IDENT = r"[A-Za-z][A-Za-z0-9_]*"
_IMPORT_LINES = {kind: re.compile(rf"^from\s+({_IDENT})\.{kind}\.\w+\s+import\s+({_IDENT})",
                                  re.MULTILINE) for kind in ("msg", "srv")}


def _unknown(name: str, why: str) -> CodecError:
    return CodecError(field="type", expected=why, got=repr(name))


@dataclass(frozen=True)
class InterfaceKind:
    """What a ROS interface kind is to the class lookup: its folder in a package (``msg``,
    ``srv``, ``action``), its name in errors, and the attributes its class has."""

    folder: str
    noun: str
    parts: tuple[str, ...]

    @property
    def one(self) -> str:
        """``a message``, ``an action``: the noun with its article, for errors."""
        return f"{'an' if self.noun[0] in 'aeiou' else 'a'} {self.noun}"


MESSAGE = InterfaceKind("msg", "message", ("get_fields_and_field_types",))
SERVICE = InterfaceKind("srv", "service", ("Request", "Response"))
ACTION = InterfaceKind("action", "action", ("Goal", "Result", "Feedback"))


@cache
def interface_class(kind: InterfaceKind, ros_type: str) -> Any:
    """The rclpy class of a canonical ``pkg/<folder>/Type`` of ``kind``; `CodecError` naming
    what was expected if it is not installed."""
    m = re.match(rf"^({_IDENT})/{kind.folder}/({_IDENT})$", ros_type)
    if m is None:
        raise _unknown(ros_type, f"{kind.one} type 'pkg/{kind.folder}/Type'")
    pkg, name = m.groups()
    try:
        module = importlib.import_module(f"{pkg}.{kind.folder}")
    except ImportError:
        raise _unknown(ros_type, f"an installed interface package with {kind.noun}s "
                       f"({pkg!r} has none here)") from None
    cls = getattr(module, name, None)
    if cls is None or not all(hasattr(cls, part) for part in kind.parts):
        raise _unknown(ros_type, f"{kind.one} of package {pkg!r} ({name!r} is not "
                       "one)")
    return cls


def message_class(ros_type: str) -> Any:
    """The rclpy message class of ``pkg/msg/Type`` (`interface_class`)."""
    return interface_class(MESSAGE, ros_type)


def service_class(ros_type: str) -> Any:
    """The rclpy service class of ``pkg/srv/Type`` (`interface_class`)."""
    return interface_class(SERVICE, ros_type)


def action_class(ros_type: str) -> Any:
    """The rclpy action class of ``pkg/action/Type`` (`interface_class`)."""
    return interface_class(ACTION, ros_type)


def ros_type_of(msg_or_class: Any) -> str:
    """``pkg/msg/Type`` of an rclpy message instance or class (``pkg/srv/Type_Request``
    for a service's part, ``pkg/action/Type_Goal`` for an action's)."""
    cls = msg_or_class if isinstance(msg_or_class, type) else type(msg_or_class)
    parts = cls.__module__.split(".")  # "sensor_msgs.msg._image"
    kind = parts[1] if len(parts) > 2 and parts[1] in ("srv", "action") else "msg"
    return f"{parts[0]}/{kind}/{cls.__name__}"


def _installed_messages() -> dict[str, tuple[str, ...]]:
    return _installed("msg")


@lru_cache(maxsize=2)
def _installed(kind: str) -> dict[str, tuple[str, ...]]:
    """Bare message (``kind`` msg) or service (srv) name -> packages defining it, read from
    every ``<pkg>/<kind>/__init__.py`` on sys.path (the generated file lists one import per
    interface, so no import is needed)."""
    import_line = _IMPORT_LINES[kind]
    found: dict[str, list[str]] = {}
    for entry in sys.path:
        if not entry or not os.path.isdir(entry):
            continue
        try:
            children = os.listdir(entry)
        except OSError:
            continue
        for pkg in children:
            init = os.path.join(entry, pkg, kind, "__init__.py")
            if not os.path.isfile(init):
                continue
            try:
                with open(init, encoding="utf-8") as f:
                    text = f.read()
            except OSError:
                continue
            for imp_pkg, name in import_line.findall(text):
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
            name, packages_of=lambda bare: _installed_messages().get(bare, ()),
            known=_installed_messages())
    except OutOfRangeError as error:
        raise CodecError(field="type", expected=error.expected, got=error.got) from None
    try:
        message_class(ros_type)
    except CodecError as error:  # a full name: say the closest installed one
        close = unknown_type("type", error.expected, ros_type, installed_types())
        raise CodecError(field="type", expected=error.expected, got=close.got) from None
    return ros_type


def resolve_service(name: str) -> str:
    """Any accepted spelling of a service type (``pkg/srv/Type``, a reference service client
    class name, a bare name defined by one installed package) -> ``pkg/srv/Type``, checked
    to be installed; `CodecError` naming it otherwise."""
    try:
        ros_type = resolve_service_type(name, packages_of=lambda bare: _installed("srv").get(
            bare, ()))
    except OutOfRangeError as error:
        raise _unknown(str(name).strip(), error.expected) from None
    service_class(ros_type)
    return ros_type


def installed_class(kind: InterfaceKind, type_name: str, ros_type: str) -> Any:
    """The rclpy class of ``ros_type`` for a request that named it ``type_name``;
    UNKNOWN_ROS_TYPE naming the field ``type`` if it is not installed."""
    try:
        return interface_class(kind, ros_type)
    except CodecError as error:
        raise CommandFailedError("type", f"{kind.one} type installed in the daemon's "
                                 "environment", f"{type_name!r} ({error})",
                                 code=ErrorCode.UNKNOWN_ROS_TYPE) from None

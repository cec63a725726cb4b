"""The `describe_type` op: what an installed message, service or action type is made of.

Clients build message objects from the answer at run time (slicer_client's reference
facade); the daemon reads it from rclpy's own introspection of the generated classes
(`bridge.codecs.generic.describe_message`). Answers are cached: an installed type does not
change while the daemon runs.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any, Mapping

from bridge.codecs import CodecError
from bridge.codecs.generic import describe_message
from bridge.codecs.registry import (action_class, message_class, resolve_service, resolve_type,
                                    service_class)
from bridge.core.content_guards import ContentGuard
from bridge.core.dispatch import Handler
from protocol.commands import (CommandFailedError, DescribeType, ErrorCode, MessageDescription,
                               Op, OutOfRangeError, TypeDescription, resolve_action_type)

__all__ = ["InterfaceTypes", "describe_type"]


class InterfaceTypes:
    """A capability without bridges: it only answers `describe_type`."""

    def handlers(self) -> Mapping[type[Op], Handler]:
        return {DescribeType: lambda request, _: describe_type(request.type, request.kind)}

    def describe(self) -> list[dict[str, Any]]:
        return []

    def state(self, guard: ContentGuard) -> dict[str, Any]:
        return {}

    def close(self) -> None:
        pass


@lru_cache(maxsize=512)
def describe_type(name: str, kind: str) -> TypeDescription:
    try:
        full, parts = _parts(name, kind)
    except (CodecError, OutOfRangeError) as error:
        expected = error.expected
        raise CommandFailedError("type", f"an installed {kind} type", f"{name!r} ({expected})",
                                 code=ErrorCode.UNKNOWN_ROS_TYPE) from None
    messages: dict[str, MessageDescription] = {}
    names = {part: describe_message(cls, messages) for part, cls in parts.items()}
    return TypeDescription(full, kind, names, messages)


def _parts(name: str, kind: str) -> tuple[str, dict[str, Any]]:
    if kind == "message":
        full = resolve_type(name)
        return full, {"message": message_class(full)}
    if kind == "service":
        full = resolve_service(name)
        cls = service_class(full)
        return full, {"request": cls.Request, "response": cls.Response}
    full = resolve_action_type(name)
    cls = action_class(full)
    return full, {"goal": cls.Goal, "result": cls.Result, "feedback": cls.Feedback}

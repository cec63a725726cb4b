"""What the two halves of the action bridges share: the action type lookup, and destroying
an rclpy action entity without stopping the executor."""

from __future__ import annotations

import logging
from typing import Any

from bridge.codecs import CodecError
from bridge.codecs.registry import action_class
from protocol.commands import CommandFailedError, ErrorCode

__all__ = ["action_class_of", "destroy_quietly"]

log = logging.getLogger("bridge.actions")


def action_class_of(type_name: str, ros_type: str) -> Any:
    """The rclpy action class; UNKNOWN_ROS_TYPE naming `type_name` if not installed."""
    try:
        return action_class(ros_type)
    except CodecError as error:
        raise CommandFailedError("type", "an action type installed in the daemon's environment",
                                 f"{type_name!r} ({error})",
                                 code=ErrorCode.UNKNOWN_ROS_TYPE) from None


def destroy_quietly(entity: Any, action: str) -> None:
    """Destroy an ActionClient or ActionServer (executor thread); log, never raise."""
    try:
        entity.destroy()
    except Exception:  # never let cleanup stop the executor
        log.exception("destroying the action entity of %s failed", action)

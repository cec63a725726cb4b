"""The security policy applied to messages whose content names resources: a tf2_msgs/
TFMessage names tf frames, an rcl_interfaces/ParameterEvent names parameters. A topic bridge
of such a type gets a `MessageGuard` that passes on only what the globs allow (ROS -> client)
and refuses what they deny (client -> ROS), transform by transform, parameter by parameter.

Duck-typed on the rclpy message classes, so this module needs no ROS import.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Optional, Protocol

from protocol.commands import ForbiddenError

__all__ = ["PARAMETER_EVENT_TYPE", "TF_MESSAGE_TYPE", "HeaderFrameGuard", "MessageGuard",
           "ParameterEventGuard", "TfMessageGuard"]

TF_MESSAGE_TYPE = "tf2_msgs/msg/TFMessage"
PARAMETER_EVENT_TYPE = "rcl_interfaces/msg/ParameterEvent"

Permits = Callable[[str], bool]
WhyNot = Callable[[str], str]


class MessageGuard(Protocol):
    def filter(self, msg: Any) -> Optional[Any]:
        """ROS -> client: the message with only what the policy allows; None if nothing."""
        ...

    def check(self, msg: Any) -> None:
        """Client -> ROS: raise `ForbiddenError` if the message writes a denied resource."""
        ...


def _frame(frame_id: str) -> str:
    return frame_id.lstrip("/")  # as the tf buffer holds it


@dataclass(frozen=True)
class TfMessageGuard:
    """A transform passes when both its frames are allowed (what a lookup of it needs)."""

    permits: Permits
    why_not: WhyNot

    def _allowed(self, transform: Any) -> bool:
        return (self.permits(_frame(transform.header.frame_id))
                and self.permits(_frame(transform.child_frame_id)))

    def filter(self, msg: Any) -> Optional[Any]:
        kept = [t for t in msg.transforms if self._allowed(t)]
        if len(kept) == len(msg.transforms):
            return msg
        return type(msg)(transforms=kept) if kept else None

    def check(self, msg: Any) -> None:
        for i, transform in enumerate(msg.transforms):
            for name, frame in (("header.frame_id", transform.header.frame_id),
                                ("child_frame_id", transform.child_frame_id)):
                if not self.permits(_frame(frame)):
                    raise ForbiddenError(f"value.transforms[{i}].{name}", "a tf frame this "
                                         "daemon exposes: " + self.why_not(_frame(frame)),
                                         _frame(frame))


@dataclass(frozen=True)
class ParameterEventGuard:
    """Parameters judged as ``<node>.<name>``, as every other parameter route."""

    permits: Permits
    why_not: WhyNot

    def filter(self, msg: Any) -> Optional[Any]:
        node = msg.node
        lists = {name: [p for p in getattr(msg, name) if self.permits(f"{node}.{p.name}")]
                 for name in ("new_parameters", "changed_parameters", "deleted_parameters")}
        if not any(lists.values()):
            return None
        return type(msg)(stamp=msg.stamp, node=node, **lists)

    def check(self, msg: Any) -> None:
        for name in ("new_parameters", "changed_parameters", "deleted_parameters"):
            for p in getattr(msg, name):
                full = f"{msg.node}.{p.name}"
                if not self.permits(full):
                    raise ForbiddenError(f"value.{name}", "a parameter this daemon exposes: "
                                         + self.why_not(full), full)


@dataclass(frozen=True)
class HeaderFrameGuard:
    """Client -> ROS on a publisher: the frame a message is stamped in (``header.frame_id``,
    and each pose's of a nav_msgs/Path) must be one the frame globs allow, whether it came
    from the publisher's ``frame``, a message's ``ros2.frame`` metadata or a JSON value.
    ROS -> client streams are not filtered by it (a publisher guard only)."""

    permits: Permits
    why_not: WhyNot

    def filter(self, msg: Any) -> Optional[Any]:
        return msg

    def check(self, msg: Any) -> None:
        header = getattr(msg, "header", None)
        frames: list[tuple[str, str]] = []
        if header is not None:
            frames.append(("header.frame_id", header.frame_id))
        for i, pose in enumerate(getattr(msg, "poses", ()) or ()):
            pose_header = getattr(pose, "header", None)
            if pose_header is not None:
                frames.append((f"poses[{i}].header.frame_id", pose_header.frame_id))
        for name, frame in frames:
            if frame and not self.permits(_frame(frame)):
                raise ForbiddenError(f"value.{name}", "a tf frame this daemon exposes: "
                                     + self.why_not(_frame(frame)), _frame(frame))

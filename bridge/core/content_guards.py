"""The security policy inside content: what a client sees or writes in a bridge's data or
an op's result, when that content names resources (tf frames, parameters).

An op declares the content it carries (`protocol.commands.Op.content`); the policy builds one
`ContentGuard` for exactly that (`SecurityPolicy.content_guard`), and the dispatcher hands it
to the op's handler, which keeps it with the bridge it makes. So the capabilities apply the
policy without knowing it, and a capability that reads content its op did not declare fails
in tests (TypeError), not silently open.

A topic's messages get a `MessageGuard` when their type names resources: a tf2_msgs/
TFMessage names tf frames, an rcl_interfaces/ParameterEvent names parameters. It passes on
only what the globs allow (ROS -> client) and refuses what they deny (client -> ROS),
transform by transform, parameter by parameter.

Duck-typed on the rclpy message classes, so this module needs no ROS import.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Optional, Protocol

from protocol.commands import ForbiddenError

__all__ = ["OPEN", "PARAMETER_EVENT_TYPE", "TF_MESSAGE_TYPE", "ContentGuard", "HeaderFrameGuard",
           "MessageGuard", "NameFilter", "ParameterEventGuard", "TfMessageGuard"]

TF_MESSAGE_TYPE = "tf2_msgs/msg/TFMessage"
PARAMETER_EVENT_TYPE = "rcl_interfaces/msg/ParameterEvent"

Permits = Callable[[str], bool]
WhyNot = Callable[[str], str]


class NameFilter(Protocol):
    """One kind's allow/deny globs (`bridge.core.security.NameRules`)."""

    def permits(self, name: str) -> bool: ...

    def why_not(self, name: str) -> str: ...

    @property
    def active(self) -> bool: ...


class _Open:
    """No globs: every name passes."""

    def permits(self, name: str) -> bool:
        return True

    def why_not(self, name: str) -> str:
        return "any name"

    @property
    def active(self) -> bool:
        return False


OPEN: NameFilter = _Open()


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


@dataclass(frozen=True)
class ContentGuard:
    """What one request's client may see or write inside its content, as its op declares
    it (``declared``, from `Op.content`). A part the op did not declare raises TypeError."""

    op: str
    declared: tuple[str, ...] = ()
    frames: NameFilter = OPEN
    parameters: NameFilter = OPEN
    # The messages of the op's topic: filtered to a client, checked from one (None: their
    # type names nothing the policy judges).
    messages: Optional[MessageGuard] = None
    # A call_service to this node's list_parameters: its reply lists parameter names.
    lists_parameters_of: Optional[str] = None
    # Folders the files its content names may be read from; None: anywhere (the operator's
    # own file).
    file_roots: Optional[tuple[str, ...]] = ()

    def _need(self, content: str) -> None:
        if content not in self.declared:
            raise TypeError(f"op {self.op!r} reads its content's {content} but does not declare "
                            f"them (Op content={self.declared!r})")

    # --- messages ------------------------------------------------------------------------
    def message_filter(self) -> Optional[Callable[[Any], Optional[Any]]]:
        """ROS -> client: keeps what the policy lets through (None if nothing is judged, so
        the hot path pays nothing)."""
        self._need("messages")
        return None if self.messages is None else self.messages.filter

    def message_check(self) -> Optional[Callable[[Any], None]]:
        """Client -> ROS: raises `ForbiddenError` for a message that writes a denied name."""
        self._need("messages")
        return None if self.messages is None else self.messages.check

    # --- tf frames -----------------------------------------------------------------------
    def frame_refusal(self, frame: str) -> Optional[str]:
        """Why `frame` (as the tf buffer holds it) is withheld, or None if it is shown."""
        self._need("frames")
        if self.frames.permits(frame):
            return None
        return f"frame {frame!r} refused by the frame policy: expected " \
               f"{self.frames.why_not(frame)}"

    def check_frame(self, field: str, frame: str) -> None:
        """Raise `ForbiddenError` naming `field` if `frame` is withheld."""
        self._need("frames")
        if not self.frames.permits(frame):
            raise ForbiddenError(field, "a tf frame this daemon exposes: "
                                 + self.frames.why_not(frame), frame)

    def visible_frames(self, frames: Iterable[str]) -> list[str]:
        self._need("frames")
        return [f for f in frames if self.frames.permits(f)]

    # --- files ---------------------------------------------------------------------------
    def readable_roots(self) -> Optional[tuple[Path, ...]]:
        """The folders a mesh its content names may be read from (None: anywhere)."""
        self._need("files")
        return None if self.file_roots is None else tuple(Path(r) for r in self.file_roots)

    # --- parameters ----------------------------------------------------------------------
    def visible_parameters(self, node: str, names: Iterable[str]) -> list[str]:
        """Of `node`'s parameter `names`, those a client may see (judged as node.name)."""
        self._need("parameters")
        return [n for n in names if self.parameters.permits(f"{node}.{n}")]

    def service_reply(self, response: dict[str, Any]) -> dict[str, Any]:
        """A call_service response as a client may see it: a node's parameter listing keeps
        only the names it may see, and no prefixes (a prefix can name a hidden one)."""
        self._need("parameters")
        node = self.lists_parameters_of
        if node is None or not self.parameters.active:
            return response
        result = dict(response.get("result") or {})
        result["names"] = self.visible_parameters(node, result.get("names") or ())
        result["prefixes"] = []
        return {**response, "result": result}

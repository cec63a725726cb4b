"""Typed errors of the daemon's tf buffer, worded like tf2 and carrying tf2's error codes.

The tree (``code`` is the value of ``tf2_msgs/msg/TF2Error`` a reply should carry)::

    TfError                       base; attributes code (TfErrorCode) and message
    +-- TfLookupError             LOOKUP_ERROR (1): a frame does not exist, or the tree loops
    +-- ConnectivityError         CONNECTIVITY_ERROR (2): the frames are in different trees
    +-- ExtrapolationError        EXTRAPOLATION_ERROR (3): no data at the requested time
    +-- InvalidArgumentError      INVALID_ARGUMENT_ERROR (4): field, expected, got
        +-- RejectedTransformsError   some transforms of a batch were refused (others stored)

``TfLookupError`` is not called ``LookupError`` so that it does not shadow Python's builtin.
Messages follow tf2's ``BufferCore`` wording, so users can search them as they know them.
"""

from __future__ import annotations

from enum import IntEnum
from typing import Literal, Optional, Sequence

__all__ = [
    "TfErrorCode",
    "TfError",
    "TfLookupError",
    "ConnectivityError",
    "ExtrapolationError",
    "InvalidArgumentError",
    "RejectedTransformsError",
    "display_time",
]


class TfErrorCode(IntEnum):
    """The constants of ``tf2_msgs/msg/TF2Error`` (same numbers on the wire)."""

    NO_ERROR = 0
    LOOKUP_ERROR = 1
    CONNECTIVITY_ERROR = 2
    EXTRAPOLATION_ERROR = 3
    INVALID_ARGUMENT_ERROR = 4
    TIMEOUT_ERROR = 5
    TRANSFORM_ERROR = 6


def display_time(stamp_ns: int) -> str:
    """A time as tf2 prints it in errors: seconds, a dot, nine digits of nanoseconds."""
    sec, ns = divmod(int(stamp_ns), 1_000_000_000)
    return f"{sec}.{ns:09d}"


class TfError(Exception):
    """Base of every tf buffer error. ``code`` is the `TfErrorCode` to report."""

    code: TfErrorCode = TfErrorCode.TRANSFORM_ERROR

    def __init__(self, message: str) -> None:
        self.message = message
        super().__init__(message)

    def identity(self) -> tuple[object, ...]:
        """What makes two errors 'the same' for change detection (see lookups.py)."""
        return (type(self), self.message)


class TfLookupError(TfError):
    """A frame is unknown (``frame`` names it), or the tree contains a loop (``frame`` None)."""

    code = TfErrorCode.LOOKUP_ERROR

    def __init__(self, message: str, frame: Optional[str] = None) -> None:
        self.frame = frame
        super().__init__(message)

    def __reduce__(self) -> tuple[object, ...]:
        return (type(self), (self.message, self.frame))

    @classmethod
    def unknown_frame(cls, frame: str, argument: str) -> TfLookupError:
        return cls(f'"{frame}" passed to {argument} does not exist.', frame=frame)


class ConnectivityError(TfError):
    """Both frames exist but no chain of transforms joins them."""

    code = TfErrorCode.CONNECTIVITY_ERROR

    def __init__(self, target_frame: str, source_frame: str) -> None:
        self.target_frame = target_frame
        self.source_frame = source_frame
        super().__init__(
            f"Could not find a connection between '{target_frame}' and '{source_frame}' because"
            " they are not part of the same tree.Tf has two or more unconnected trees."
        )

    def __reduce__(self) -> tuple[object, ...]:
        return (type(self), (self.target_frame, self.source_frame))


class ExtrapolationError(TfError):
    """A link of the chain has no data at ``requested_ns``.

    ``direction`` is ``"future"`` (requested after the newest sample ``available_ns``),
    ``"past"`` (before the oldest one) or ``"single"`` (only one sample, at another time).
    """

    code = TfErrorCode.EXTRAPOLATION_ERROR

    def __init__(
        self,
        direction: Literal["future", "past", "single"],
        requested_ns: int,
        available_ns: int,
        *,
        source_frame: str = "",
        target_frame: str = "",
    ) -> None:
        self.direction = direction
        self.requested_ns = requested_ns
        self.available_ns = available_ns
        self.source_frame = source_frame
        self.target_frame = target_frame
        req, got = display_time(requested_ns), display_time(available_ns)
        if direction == "future":
            text = (f"Lookup would require extrapolation into the future.  Requested time {req}"
                    f" but the latest data is at time {got}")
        elif direction == "past":
            text = (f"Lookup would require extrapolation into the past.  Requested time {req}"
                    f" but the earliest data is at time {got}")
        else:
            text = (f"Lookup would require extrapolation at time {req}, but only time {got}"
                    " is in the buffer")
        if source_frame or target_frame:
            text += (f", when looking up transform from frame [{source_frame}] to frame"
                     f" [{target_frame}]")
        super().__init__(text)

    def with_frames(self, source_frame: str, target_frame: str) -> ExtrapolationError:
        """The same error naming the lookup it happened in (tf2 appends this)."""
        return ExtrapolationError(self.direction, self.requested_ns, self.available_ns,
                                  source_frame=source_frame, target_frame=target_frame)

    def identity(self) -> tuple[object, ...]:
        # The times move with every sample; the kind of failure is what a client cares about.
        return (type(self), self.direction, self.source_frame, self.target_frame)

    def __reduce__(self) -> tuple[object, ...]:
        return (_rebuild_extrapolation, (self.direction, self.requested_ns, self.available_ns,
                                         self.source_frame, self.target_frame))


def _rebuild_extrapolation(direction: Literal["future", "past", "single"], requested_ns: int,
                           available_ns: int, source: str, target: str) -> ExtrapolationError:
    return ExtrapolationError(direction, requested_ns, available_ns,
                              source_frame=source, target_frame=target)


class InvalidArgumentError(TfError):
    """An argument or a transform is invalid: ``field`` was expected ``expected``, got ``got``."""

    code = TfErrorCode.INVALID_ARGUMENT_ERROR

    def __init__(self, field: str, expected: str, got: object) -> None:
        self.field = field
        self.expected = expected
        self.got = got
        super().__init__(f"Invalid argument {field}: expected {expected}, got {got!s}")

    def __reduce__(self) -> tuple[object, ...]:
        return (type(self), (self.field, self.expected, self.got))


class RejectedTransformsError(InvalidArgumentError):
    """Some transforms of one `TfBuffer.set_transforms` batch were refused.

    The valid ones of the batch were stored anyway (tf2 also judges each transform alone):
    ``changed`` holds the child frames that did change, ``rejected`` one error per refused
    transform (its ``field`` starts with ``transforms[i]``).
    """

    def __init__(self, rejected: Sequence[InvalidArgumentError], changed: set[str],
                 unworded: int = 0) -> None:
        self.rejected = list(rejected)
        self.changed = changed
        # Refused too, not worded one by one (a flood of them: the first few say enough).
        self.count = len(self.rejected) + unworded
        first = self.rejected[0]
        more = f" (and {self.count - 1} more)" if self.count > 1 else ""
        super().__init__(first.field, first.expected, f"{first.got!s}{more}")

    def __reduce__(self) -> tuple[object, ...]:
        return (type(self), (self.rejected, self.changed, self.count - len(self.rejected)))

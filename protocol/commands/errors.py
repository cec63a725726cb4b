"""Request errors: one `CommandError` subclass per way a request can be refused, and the
`ErrorCode` an error reply carries. Each error names the field, what was expected and what
came."""

from __future__ import annotations

from enum import IntEnum
from typing import ClassVar

from protocol.errors import ProtocolError

__all__ = ["BadJsonError", "CommandError", "CommandFailedError", "ErrorCode", "ForbiddenError",
           "LimitReachedError", "MissingFieldError", "OutOfRangeError", "TooLargeError",
           "UnknownFieldError", "UnknownOpError", "UnknownTypeError", "UnsupportedSchemaError",
           "WrongTypeError"]

class ErrorCode(IntEnum):
    """``error.code`` of a failed `Reply`. 1-19: the request is malformed (fix the client);
    20-39: the request is well-formed but cannot be done now; 99: daemon bug."""

    BAD_JSON = 1
    TOO_LARGE = 2
    UNKNOWN_OP = 3
    UNSUPPORTED_SCHEMA = 4
    MISSING_FIELD = 5
    UNKNOWN_FIELD = 6
    WRONG_TYPE = 7
    OUT_OF_RANGE = 8
    NOT_FOUND = 20
    ALREADY_EXISTS = 21
    UNKNOWN_ROS_TYPE = 22
    ROS_ERROR = 23
    TIMEOUT = 24
    UNAVAILABLE = 25
    TRANSFORM_UNAVAILABLE = 26
    NOT_SUPPORTED = 27
    FORBIDDEN = 28
    LIMIT_REACHED = 29
    REJECTED = 30  # an action server refused the goal
    INTERNAL = 99


class CommandError(ProtocolError):
    """Base of request errors; `error_code` is what the error reply carries."""

    code: ClassVar[ErrorCode] = ErrorCode.INTERNAL

    @property
    def error_code(self) -> ErrorCode:
        return self.code


class BadJsonError(CommandError):
    """The text is not a JSON object (syntax, encoding, NaN, duplicate keys, nesting)."""

    code = ErrorCode.BAD_JSON


class TooLargeError(CommandError):
    """The text or one of its values is larger than allowed."""

    code = ErrorCode.TOO_LARGE


class UnknownOpError(CommandError):
    """The COMMAND NAME is not an op of this schema."""

    code = ErrorCode.UNKNOWN_OP


class UnsupportedSchemaError(CommandError):
    """The request asks for a schema newer than this daemon's."""

    code = ErrorCode.UNSUPPORTED_SCHEMA


class MissingFieldError(CommandError):
    """A required field is absent."""

    code = ErrorCode.MISSING_FIELD


class UnknownFieldError(CommandError):
    """A field this op does not have (usually a typo)."""

    code = ErrorCode.UNKNOWN_FIELD


class WrongTypeError(CommandError):
    """A field has the wrong JSON type."""

    code = ErrorCode.WRONG_TYPE


class OutOfRangeError(CommandError):
    """A field has the right type but a value that is not allowed."""

    code = ErrorCode.OUT_OF_RANGE


class UnknownTypeError(OutOfRangeError):
    """An interface type name that names no type here (misspelt, or not installed): the
    code is the one of a type the daemon does not have, and the text says the closest
    known name ("did you mean PoseStamped?")."""

    code = ErrorCode.UNKNOWN_ROS_TYPE


class ForbiddenError(CommandError):
    """The daemon's security policy refuses the request (``--read-only``, or a topic,
    service or parameter glob); the field names what was refused."""

    code = ErrorCode.FORBIDDEN


class LimitReachedError(CommandError):
    """A per-client limit of the daemon is reached (``--max-bridges-per-client``)."""

    code = ErrorCode.LIMIT_REACHED


class CommandFailedError(CommandError):
    """A valid request the daemon could not carry out; the code is chosen per failure
    (NOT_FOUND, ALREADY_EXISTS, TIMEOUT...)."""

    def __init__(self, field: str, expected: str, got: object, *,
                 code: ErrorCode = ErrorCode.ROS_ERROR) -> None:
        self._code = code
        super().__init__(field, expected, got)

    @property
    def error_code(self) -> ErrorCode:
        return self._code


"""Typed errors of the OpenIGTLink protocol layer.

Every error names the offending ``field``, what was ``expected`` and what it ``got``, so a
log line or an error reply can say exactly what was wrong. The tree::

    ProtocolError                  base; attributes field, expected, got
    +-- FramingError               the byte stream cannot continue: close the connection
    |   +-- HeaderError            malformed 58-byte header (for example unknown header version)
    |   +-- BodyTooLargeError      BODY_SIZE over the decoder's limit (refused before allocation)
    |   +-- ReceiveBudgetError     BODY_SIZE over what the shared `ReceiveBudget` has left
    +-- MessageError               one message is bad, framing is intact: the stream goes on
    |   +-- CrcMismatchError       the body's CRC-64 differs from the header's
    |   +-- BodyError              malformed content; attribute type_name names the message type
    +-- EncodeError                the caller asked to encode invalid values

Other modules extend the tree from ``ProtocolError`` (for example the conversion and
command-schema errors); the base class stays generic for that reason.

Handling rule for a connection: on `MessageError` log it (or reply with an error) and keep
reading; on `FramingError` close the connection, since message boundaries are lost.
"""

from __future__ import annotations

__all__ = [
    "BodyError",
    "BodyTooLargeError",
    "CrcMismatchError",
    "EncodeError",
    "FramingError",
    "HeaderError",
    "MessageError",
    "ProtocolError",
    "ReceiveBudgetError",
]


def _show(value: object) -> str:
    # Strings are already human-readable descriptions ("shape (3,)"); show others as repr.
    if isinstance(value, str):
        return value
    text = repr(value)
    return text if len(text) <= 200 else text[:197] + "..."


class ProtocolError(Exception):
    """Base of every protocol error: ``field`` was expected to be ``expected`` but was ``got``."""

    def __init__(self, field: str, expected: str, got: object) -> None:
        self.field = field
        self.expected = expected
        self.got = got
        super().__init__(self._describe())

    def _describe(self) -> str:
        return f"{self.field}: expected {self.expected}, got {_show(self.got)}"

    def __reduce__(self) -> tuple[object, ...]:
        # Keeps subclasses with keyword-only extras picklable (multiprocessing, logging).
        return (_rebuild, (type(self), dict(self.__dict__)))


def _rebuild(cls: type[ProtocolError], state: dict[str, object]) -> ProtocolError:
    err = cls.__new__(cls)
    err.__dict__.update(state)
    Exception.__init__(err, err._describe())
    return err


class FramingError(ProtocolError):
    """The byte stream cannot continue (message boundaries are lost): close the connection."""


class HeaderError(FramingError):
    """The 58-byte message header is malformed (for example an unknown header version)."""


class BodyTooLargeError(FramingError):
    """BODY_SIZE exceeds the decoder's limit; refused before any allocation."""


class ReceiveBudgetError(FramingError):
    """A body does not fit in what the shared budget of partly received bodies has left;
    refused from the header, before any of it is stored."""


class MessageError(ProtocolError):
    """One message is bad but framing is intact: it was consumed and the stream goes on."""


class CrcMismatchError(MessageError):
    """The CRC-64 computed over the body differs from the header's CRC field."""


class BodyError(MessageError):
    """A message body (or its v2 extended header or metadata) is malformed.

    ``type_name`` is the message's type (``"POLYDATA"`` ...), empty if unknown.
    """

    def __init__(self, field: str, expected: str, got: object, *, type_name: str = "") -> None:
        self.type_name = type_name
        super().__init__(field, expected, got)

    def _describe(self) -> str:
        prefix = f"{self.type_name} " if self.type_name else ""
        return prefix + super()._describe()


class EncodeError(ProtocolError):
    """The values given cannot be encoded (name too long, wrong array shape, ...)."""

"""The one error type of the codecs: what was being converted, what was expected, what came."""

from __future__ import annotations

from protocol.errors import ProtocolError

__all__ = ["CodecError"]


class CodecError(ProtocolError):
    """A ROS message, an OpenIGTLink body or a client's JSON value cannot be converted.

    ``field`` is a dotted path into the value (``"pose.position.x"``, ``"data[3]"``,
    ``"pixels"``), ``expected`` says what would have been accepted and ``got`` what came.
    The daemon turns it into an error reply; it never escapes a ROS callback.
    """

"""Commands through 3D Slicer's OpenIGTLinkIF connector, without Slicer: building the
COMMAND (name, text) and reading the RTS_COMMAND reply, plus turning what a connector
node shows (node class, attributes, text or matrix) back into a `Message` for a `Client`.

Slicer's side (slicer_module/ROS2Bridge) passes the strings and values in and out.
"""

from __future__ import annotations

from typing import Any, Dict, Mapping, Optional, Tuple

import numpy as np

from protocol import commands as c
from protocol.messages import Message, String, Transform
from slicer_client.connection import CommandRefusedError, CommandTimeoutError
from slicer_client.scene_plan import metadata_from_attributes

__all__ = ["build_command", "message_from_node", "parse_reply"]


def build_command(op: str, arguments: Optional[Mapping[str, Any]] = None) -> Tuple[str, str]:
    """(NAME, text) for `SendCommand`. The request is validated against the schema here,
    and text over Slicer's 65535-byte limit is refused with the size (Slicer itself would
    fail silently)."""
    args = dict(arguments or {})
    args.setdefault("schema", c.SCHEMA_VERSION)
    text = c.dumps(args)
    request = c.parse_request(op, text)  # raises a CommandError naming the field
    name, text = c.encode_request(request)
    size = len(text.encode("utf-8"))
    if size > c.SLICER_MAX_COMMAND_TEXT_BYTES:
        raise c.TooLargeError("text", f"at most {c.SLICER_MAX_COMMAND_TEXT_BYTES} bytes "
                              "(3D Slicer's command limit)", f"{size} bytes")
    return name, text


def parse_reply(op: str, response_text: str, *, expired: bool = False,
                timeout: float = 0.0, error_message: str = "") -> Dict[str, Any]:
    """The result of a command's RTS_COMMAND reply, or the typed error. The JSON text
    decides (Slicer's `Status` metadata only says SUCCESS/FAIL)."""
    if expired:
        raise CommandTimeoutError(op, timeout)
    if not response_text.strip():
        info = c.ErrorInfo(c.ErrorCode.INTERNAL, error_message or "empty reply")
        raise CommandRefusedError(op, info)
    try:
        reply = c.Reply.from_json(response_text)
    except c.CommandError as error:
        raise CommandRefusedError(op, c.ErrorInfo(c.ErrorCode.INTERNAL,
                                                  f"unreadable reply: {error}")) from None
    if not reply.ok:
        assert reply.error is not None
        raise CommandRefusedError(op, reply.error)
    return reply.result


def message_from_node(device: str, attributes: Mapping[str, str], *,
                      text: Optional[str] = None,
                      matrix: Optional[Any] = None) -> Optional[Message]:
    """A connector node's content -> the Message it came from (text node: STRING,
    transform node: TRANSFORM); None for anything else."""
    metadata = metadata_from_attributes(attributes)
    if matrix is not None:
        return Message(device, Transform(np.array(matrix, dtype=np.float64)),
                       metadata=metadata)
    if text is not None:
        return Message(device, String(text), metadata=metadata)
    return None

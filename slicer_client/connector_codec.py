"""Commands through 3D Slicer's OpenIGTLinkIF connector, without Slicer: building the
COMMAND (name, text) and reading the RTS_COMMAND reply, plus turning what a connector
node shows (node class, attributes, text or matrix) back into a `Message` for a `Client`.

Slicer's side (slicer_module/ROS2Bridge) passes the strings and values in and out.

Facts about Slicer used here (checked in SlicerOpenIGTLink d090ca4 and OpenIGTLinkIO d7f6aef,
see slicer_client/README.md "Verified against"):
- `vtkSlicerOpenIGTLinkCommand.GetCommandStatus()` returns OpenIGTLinkIO's
  `igtlioCommandStatus` (Logic/igtlioCommand.h): `COMMAND_STATUS` below. A blocking send
  returns with RESPONSE_RECEIVED or EXPIRED; it returns at once, still UNKNOWN, when the
  connector has no socket (`igtlioConnector::SendCommand` loops over zero clients), and
  FAILED when writing to the socket failed.
- `PushNode` on a text node sends a STRING whose ENCODING field is the text node's VTK
  encoding id copied as is (vtkMRMLIGTLConnectorNode.cxx `AssignOutGoingNodeToDevice`),
  and it clears the device's metadata (only `MRMLNodeName` and `Status` are sent).
  VTK_ENCODING_UTF_8 is 3, which reads as MIBenum 3 (US-ASCII): so only ASCII text and
  no metadata can be streamed through the connector (`outgoing_content`).
"""

from __future__ import annotations

from typing import Any, Dict, Mapping, Optional, Sequence, Tuple

import numpy as np

from protocol import commands as c
from protocol.messages import (Message, PolyData, Status, String, TrackingData,
                               TrackingElement, Transform)
from slicer_client.connection import (CommandRefusedError, CommandTimeoutError,
                                      ConnectionClosedError)
from slicer_client.scene_plan import metadata_from_attributes

__all__ = ["COMMAND_STATUS", "SLICER_TEXT_ENCODING", "build_command", "message_from_node",
           "outgoing_content", "parse_reply"]

# igtlioCommandStatus values (OpenIGTLinkIO Logic/igtlioCommand.h), the same numbers as
# vtkSlicerOpenIGTLinkCommand.CommandUnknown ... CommandResponseSent.
COMMAND_STATUS: Dict[int, str] = {0: "unknown", 1: "waiting", 2: "expired", 3: "cancelled",
                                  4: "failed", 5: "response_received", 6: "response_sent"}
# What to give vtkMRMLTextNode.SetEncoding for an outgoing STRING: VTK_ENCODING_UTF_8 (3)
# is sent unchanged as the STRING's MIBenum, and 3 is US-ASCII there.
SLICER_TEXT_ENCODING = 3
_NOT_SENT = {
    "unknown": "was not sent: 3D Slicer's connector has no connection to the daemon "
               "(it keeps retrying; wait for 'Connected')",
    "failed": "could not be written to the daemon's socket by 3D Slicer's connector",
    "cancelled": "was cancelled in 3D Slicer's connector",
    "waiting": "is still waiting for its reply in 3D Slicer's connector",
    "response_sent": "is an incoming command, not a reply",
}


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
                timeout: float = 0.0, error_message: str = "",
                status: Optional[int] = None) -> Dict[str, Any]:
    """The result of a command's RTS_COMMAND reply, or the typed error. The JSON text
    decides (Slicer's `Status` metadata only says SUCCESS/FAIL). `status` is the
    command's `GetCommandStatus()` after a blocking send, when known."""
    state = COMMAND_STATUS.get(status, f"status {status}") if status is not None \
        else "response_received"
    if expired or state == "expired":
        raise CommandTimeoutError(op, timeout)
    if state != "response_received":
        raise ConnectionClosedError(f"{op} {_NOT_SENT.get(state, f'ended with {state}')}")
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
                      matrix: Optional[Any] = None,
                      status: Optional[Tuple[int, str, str]] = None,
                      model: Optional[Tuple[Any, Any]] = None,
                      poses: Optional[Tuple[Sequence[str], Any]] = None) -> Optional[Message]:
    """A connector node's content -> the Message it came from (text node: STRING,
    transform node: TRANSFORM, status node: STATUS from its code, error name and
    text, model node: POLYDATA from its points (N, 3) in mm and its polygons as
    ``[n, i0..i(n-1), ...]``, tracking-data bundle: TDATA from its transform nodes'
    names and matrices (N x 16 numbers or N 4x4, mm)); None for anything else."""
    metadata = metadata_from_attributes(attributes)
    if poses is not None:
        names, matrices = poses
        stacked = np.asarray(matrices, dtype=np.float64).reshape(len(names), 4, 4)
        return Message(device, TrackingData([TrackingElement(name, matrix)
                                             for name, matrix in zip(names, stacked)]),
                       metadata=metadata)
    if model is not None:
        points, polygons = model
        return Message(device, PolyData(points=np.asarray(points, dtype=np.float32),
                                        polygons=np.asarray(polygons, dtype=np.uint32)),
                       metadata=metadata)
    if status is not None:
        code, error_name, status_text = status
        return Message(device, Status(code=int(code), error_name=error_name,
                                      text=status_text), metadata=metadata)
    if matrix is not None:
        return Message(device, Transform(np.array(matrix, dtype=np.float64)),
                       metadata=metadata)
    if text is not None:
        return Message(device, String(text), metadata=metadata)
    return None


def outgoing_content(message: Message) -> Tuple[str, Any]:
    """What 3D Slicer's connector can stream for `message`: ("vtkMRMLLinearTransformNode",
    4x4 rows in mm) or ("vtkMRMLTextNode", ASCII text). Anything else raises, naming why
    (see the module doc: the connector drops metadata and labels text US-ASCII)."""
    if message.metadata:
        raise ValueError(f"{message.device_name}: 3D Slicer's connector sends no metadata "
                         f"(got {', '.join(sorted(message.metadata))}); use a command "
                         "(e.g. publish) or the socket client for that")
    body = message.body
    if isinstance(body, Transform):
        return "vtkMRMLLinearTransformNode", np.asarray(body.matrix, dtype=np.float64).tolist()
    if isinstance(body, String):
        if not body.text.isascii():
            raise ValueError(f"{message.device_name}: 3D Slicer's connector labels streamed "
                             "text US-ASCII, and this text is not ASCII; publish it with "
                             "a command (publisher.publish) instead")
        return "vtkMRMLTextNode", body.text
    raise TypeError(f"the connector transport streams TRANSFORM and STRING, not "
                    f"{message.type_name}")

"""The codec contract shared by every type pair, and small helpers used by all of them.

A `TypeCodec` converts one ROS message type both ways:

* ``encode(msg) -> Encoded`` (body + suggested metadata + the header stamp) and its short
  form ``to_igtl(msg) -> body``: called from ROS callbacks, so fast and never raising
  anything but `CodecError`;
* ``from_igtl(body, stamp=, frame_id=, metadata=)``: a message from 3D Slicer to publish;
  ``from_igtl_all`` when a body may become several (a POINT list as PointStamped each),
  ``from_igtl_raw`` the serialized message for codecs that build it with numpy (models);
* ``to_value(msg)`` / ``from_value(value, stamp=, frame_id=)``: the JSON "Slicer value" a
  client reads (``GetLastMessage``) and publishes (``Publish(value)``);
* ``to_yaml(msg)``: ``ros2 topic echo`` style text (``GetLastMessageYAML``).

Subclasses implement the ``_``-prefixed hooks; the public methods add the type check and
turn any stray ``ConversionError``/``ProtocolError`` of a lower layer into `CodecError`
naming the field.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, Union

from bridge.codecs.errors import CodecError
from bridge.codecs.generic import message_to_yaml
from bridge.codecs.registry import message_class
from protocol.conversions import igtl_stamp_or_now, igtl_timestamp_now
from protocol.errors import ProtocolError
from protocol.messages import Message, String
# The codecs' metadata keys live in the protocol, next to the other ros2.* keys.
from protocol.naming import KEY_ENCODING, KEY_FORMAT, KEY_FRAME, KEY_LABELS, KEY_SHAPE, KEY_TYPE

__all__ = [
    "KEY_ENCODING",
    "KEY_FORMAT",
    "KEY_LABELS",
    "KEY_SHAPE",
    "MAX_STRING_BYTES",
    "Body",
    "Encoded",
    "Stamp",
    "TypeCodec",
    "json_body",
    "make_header",
    "parse_json_text",
    "stamp_of",
    "stream_message",
    "string_text",
    "text_body",
]

Body = Any  # one of protocol.messages' body classes (Transform, String, Image, PolyData, Point)
# A ROS time: builtin_interfaces/Time, or (sec, nanosec).
Stamp = Union[Any, tuple[int, int], None]



@dataclass(frozen=True)
class Encoded:
    """One ROS message as OpenIGTLink content: the body, metadata to attach (strings), and
    the message's own time stamp ``(sec, nanosec)`` for the IGTL header (None if it has no
    header: the daemon uses its receive time)."""

    body: Body
    metadata: dict[str, str] = field(default_factory=dict)
    stamp: tuple[int, int] | None = None


def stream_message(device: str, metadata: Mapping[str, str], encoded: Encoded) -> Message:
    """A subscriber's message to clients: on ``device``, the bridge's ``metadata`` with the
    codec's over it, time-stamped with the message's own stamp (else now)."""
    stamp = igtl_stamp_or_now(*encoded.stamp) if encoded.stamp else igtl_timestamp_now()
    merged = dict(metadata)
    merged.update(encoded.metadata)
    return Message(device_name=device, body=encoded.body, timestamp=stamp, metadata=merged)


def stamp_of(msg: Any) -> tuple[int, int] | None:
    """``(sec, nanosec)`` of ``msg.header.stamp``, or None for a message without header."""
    header = getattr(msg, "header", None)
    stamp = getattr(header, "stamp", None)
    if stamp is None:
        return None
    return int(stamp.sec), int(stamp.nanosec)


def make_header(stamp: Stamp, frame_id: str) -> Any:
    """A std_msgs/Header from a caller's stamp (Time, (sec, nanosec) or None = zero)."""
    from builtin_interfaces.msg import Time  # local: keeps import order simple
    from std_msgs.msg import Header

    if not isinstance(frame_id, str):
        raise CodecError(field="frame_id", expected="a string", got=type(frame_id).__name__)
    if stamp is None:
        t = Time()
    elif isinstance(stamp, Time):
        t = stamp
    elif isinstance(stamp, tuple) and len(stamp) == 2:
        sec, nanosec = stamp
        if isinstance(sec, bool) or isinstance(nanosec, bool) or not (
                isinstance(sec, int) and isinstance(nanosec, int)):
            raise CodecError(field="stamp", expected="(sec, nanosec) integers", got=repr(stamp))
        if not (-(2**31) <= sec < 2**31 and 0 <= nanosec < 1_000_000_000):
            raise CodecError(field="stamp", expected="sec in int32, nanosec in [0, 1e9)",
                             got=repr(stamp))
        t = Time(sec=sec, nanosec=nanosec)
    else:
        raise CodecError(field="stamp", expected="builtin_interfaces/Time or (sec, nanosec)",
                         got=type(stamp).__name__)
    return Header(stamp=t, frame_id=frame_id)


def string_text(body: Body, ros_type: str) -> str:
    """The text of a STRING body, or `CodecError` if the body is another type."""
    if not isinstance(body, String):
        raise CodecError(field="body", expected=f"an OpenIGTLink STRING (for {ros_type})",
                         got=type(body).__name__)
    return str(body.text)


MAX_STRING_BYTES = 0xFFFF  # STRING's LENGTH is a u16


def text_body(text: str) -> String:
    """A UTF-8 STRING body; text over 65535 bytes is a `CodecError` here, at conversion,
    rather than an encode failure later on the connection."""
    size = len(text.encode("utf-8", "surrogatepass"))
    if size > MAX_STRING_BYTES:
        raise CodecError(field="text", expected=f"at most {MAX_STRING_BYTES} bytes of UTF-8 "
                         "(the OpenIGTLink STRING limit)", got=f"{size} bytes")
    return String(text=text)


def json_body(value: Any) -> String:
    """A STRING body holding compact JSON (UTF-8). NaN/inf are written as NaN/Infinity."""
    return text_body(json.dumps(value, separators=(",", ":"), ensure_ascii=False))


def parse_json_text(text: str, field_name: str = "text") -> Any:
    try:
        return json.loads(text)
    except ValueError as exc:
        raise CodecError(field=field_name, expected="JSON text",
                         got=f"invalid JSON ({exc})") from None


def _rename(exc: ProtocolError, prefix: str) -> CodecError:
    if isinstance(exc, CodecError):
        return exc
    name = f"{prefix}.{exc.field}" if prefix and exc.field else (prefix or exc.field)
    return CodecError(field=name, expected=exc.expected, got=exc.got)


@dataclass(frozen=True)
class TypeCodec:
    """Converts one ROS message type (``ros_type``) to and from one OpenIGTLink type."""

    ros_type: str  # "geometry_msgs/msg/PoseStamped"
    igtl_type: str  # "TRANSFORM", "STRING", "IMAGE", "POLYDATA"
    # A type for bulk data (images, point clouds): only the newest value matters, so its
    # subscriptions keep a history of one by default (`bridge.ros.qos.default_depth`). This is
    # about the type, before any message; whether one message is large is `hub.frame_for`.
    bulk: ClassVar[bool] = False
    # A POLYDATA from a client may take this codec up to about a second (a model of
    # hundreds of thousands of triangles): publisher bridges convert it off the loop.
    heavy_polydata: ClassVar[bool] = False

    @property
    def message_class(self) -> Any:
        return message_class(self.ros_type)

    # ---------------------------------------------------------------- public API

    def encode(self, msg: Any) -> Encoded:
        """ROS message -> body, metadata and stamp. Raises `CodecError` only."""
        self._check_message(msg)
        return self._encode_checked(msg)

    def encode_fields(self, msg: Any) -> Encoded:
        """As `encode`, for a message another library read (a bag's, decoded from its
        schema): any object with the type's field names, not only an rclpy message."""
        return self._encode_checked(msg)

    def encode_serialized(self, data: bytes) -> Encoded | None:
        """The message's serialized bytes -> as `encode`, without rclpy's deserialization,
        for a type with a reader of its bytes (bridge/codecs/cdr.py); None when this type
        has none or the bytes are not the plain CDR it reads (deserialize them then)."""
        return None

    def _encode_checked(self, msg: Any) -> Encoded:
        """`encode` of a message (or a reader's view with its fields) of this type."""
        try:
            body, meta = self._to_igtl(msg)
        except ProtocolError as exc:
            raise _rename(exc, "") from None
        except Exception as exc:  # a safety net: a ROS callback must only see CodecError
            raise self._unexpected("message", exc) from exc
        metadata = {KEY_TYPE: self.ros_type}
        frame = getattr(getattr(msg, "header", None), "frame_id", None)
        if frame:
            metadata[KEY_FRAME] = str(frame)
        metadata.update(meta)
        return Encoded(body=body, metadata=metadata, stamp=stamp_of(msg))

    def to_igtl(self, msg: Any) -> Body:
        """ROS message -> OpenIGTLink body. Raises `CodecError` only."""
        return self.encode(msg).body

    def from_igtl(self, body: Body, *, stamp: Stamp = None, frame_id: str = "",
                  metadata: Mapping[str, str] | None = None) -> Any:
        """OpenIGTLink body -> ROS message; ``stamp``/``frame_id`` fill its header (if it has
        one). ``metadata`` of the message may refine the conversion (image encoding, table
        shape). Raises `CodecError` (wrong body type, shape, NaN, size mismatch)."""
        msg = self._body_call(self._from_igtl, body, metadata)
        return self._stamp(msg, stamp, frame_id)

    def _body_call(self, hook: Any, body: Body, metadata: Mapping[str, str] | None) -> Any:
        """A ``_from_igtl*`` hook, its errors as `CodecError` naming ``body``."""
        try:
            return hook(body, dict(metadata or {}))
        except ProtocolError as exc:
            raise _rename(exc, "body") from None
        except Exception as exc:  # a safety net: a ROS callback must only see CodecError
            raise self._unexpected("body", exc) from exc

    def from_igtl_all(self, body: Body, *, stamp: Stamp = None, frame_id: str = "",
                      metadata: Mapping[str, str] | None = None) -> list[Any]:
        """Like `from_igtl`, for a body that may become several ROS messages (a POINT list
        published as one PointStamped per point); one message for every other pair."""
        msgs = self._body_call(self._from_igtl_all, body, metadata)
        if msgs is None:
            return [self.from_igtl(body, stamp=stamp, frame_id=frame_id, metadata=metadata)]
        return [self._stamp(msg, stamp, frame_id) for msg in msgs]

    def from_igtl_raw(self, body: Body, *, stamp: Stamp = None, frame_id: str = "",
                      metadata: Mapping[str, str] | None = None
                      ) -> tuple[bytes, Any] | None:
        """The serialized (CDR) message `from_igtl` would build, made with numpy without
        building its bulk as Python objects, and a probe: that message without its bulk
        (its header, for the security guards). None when this codec has no such path.
        The bytes equal rclpy's ``serialize_message`` of the `from_igtl` message."""
        made = self._body_call(self._from_igtl_raw, body, metadata)
        if made is None:
            return None
        probe, finish = made
        probe = self._stamp(probe, stamp, frame_id)
        return finish(probe), probe

    def to_value(self, msg: Any) -> Any:
        """ROS message -> JSON-able "Slicer value"."""
        self._check_message(msg)
        try:
            return self._to_value(msg)
        except ProtocolError as exc:
            raise _rename(exc, "") from None
        except Exception as exc:  # a safety net: a ROS callback must only see CodecError
            raise self._unexpected("message", exc) from exc

    def from_value(self, value: Any, *, stamp: Stamp = None, frame_id: str = "") -> Any:
        """JSON value from a client -> ROS message. Raises `CodecError` naming the bad part."""
        try:
            msg = self._from_value(value)
        except ProtocolError as exc:
            raise _rename(exc, "value") from None
        except Exception as exc:  # a safety net: a ROS callback must only see CodecError
            raise self._unexpected("value", exc) from exc
        return self._stamp(msg, stamp, frame_id)

    def to_yaml(self, msg: Any) -> str:
        """``ros2 topic echo`` style YAML of the whole message."""
        self._check_message(msg)
        return message_to_yaml(msg)

    # ---------------------------------------------------------------- hooks

    def _to_igtl(self, msg: Any) -> tuple[Body, dict[str, str]]:
        raise NotImplementedError

    def _from_igtl(self, body: Body, metadata: dict[str, str]) -> Any:
        raise NotImplementedError

    def _from_igtl_all(self, body: Body, metadata: dict[str, str]) -> list[Any] | None:
        return None  # one message per body: `_from_igtl`

    def _from_igtl_raw(self, body: Body, metadata: dict[str, str]
                       ) -> tuple[Any, Callable[[Any], bytes]] | None:
        return None  # (the message without its bulk, its serializer once stamped)

    def _to_value(self, msg: Any) -> Any:
        raise NotImplementedError

    def _from_value(self, value: Any) -> Any:
        raise NotImplementedError

    # ---------------------------------------------------------------- helpers

    def _unexpected(self, field_name: str, exc: Exception) -> CodecError:
        return CodecError(field=field_name, expected=f"data convertible as {self.ros_type}",
                          got=f"{type(exc).__name__}: {exc}")

    def _check_message(self, msg: Any) -> None:
        if not isinstance(msg, self.message_class):
            raise CodecError(field="message", expected=self.ros_type, got=type(msg).__name__)

    def _stamp(self, msg: Any, stamp: Stamp, frame_id: str) -> Any:
        # A caller's stamp / frame_id overrides what the value itself may have carried.
        header = make_header(stamp, frame_id)
        if hasattr(msg, "header"):
            if stamp is not None:
                msg.header.stamp = header.stamp
            if frame_id:
                msg.header.frame_id = frame_id
        return msg

"""OpenIGTLink message header (58 bytes), v2 extended header (12 bytes) and metadata.

Spec: OpenIGTLink protocol 3.0, "Header" and "Extended Header / Meta data"
(openigtlink.org/Documents/Protocol/index.md; igtl_header.h). All fields big-endian::

    Header     V u16 | TYPE char[12] | DEVICE_NAME char[20] | TIMESTAMP u64 | BODY_SIZE u64
               | CRC u64                                       (strings zero-padded)
    Body (V=2) EXT_HEADER_SIZE u16 | META_HEADER_SIZE u16 | META_SIZE u32 | MSG_ID u32
               | content | INDEX_COUNT u16 | INDEX_COUNT x (KEY_SIZE u16, VALUE_ENCODING u16,
               VALUE_SIZE u32) | keys and values, in index order

META_HEADER_SIZE counts INDEX_COUNT too (2 + 8 * count), as OpenIGTLink 3's
igtlMessageBase.cxx writes it, even with no metadata.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from functools import lru_cache
from typing import Union

from protocol.errors import BodyError, EncodeError, HeaderError

__all__ = [
    "DEVICE_NAME_SIZE",
    "ENCODING_US_ASCII",
    "ENCODING_UTF8",
    "EXT_HEADER_SIZE",
    "HEADER_SIZE",
    "SUPPORTED_HEADER_VERSIONS",
    "TYPE_NAME_SIZE",
    "ExtendedHeader",
    "Header",
    "decode_name",
    "decode_text",
    "encode_name",
    "encode_text",
    "foreign_protocol",
    "TDATA_NAME_MAX_BYTES",
    "pack_metadata",
    "unpack_metadata",
    "unpack_raw",
]

HEADER_SIZE = 58
EXT_HEADER_SIZE = 12
TYPE_NAME_SIZE = 12
DEVICE_NAME_SIZE = 20
# A TDATA element's name is char[20] too, but the C++ library 3D Slicer links reads one of
# 20 bytes as empty (igtlTrackingDataMessage.cxx, UnpackContent, puts '\n' where its NUL
# should be), and its connector then mixes up the elements: 19 bytes at most are sent.
TDATA_NAME_MAX_BYTES = DEVICE_NAME_SIZE - 1
SUPPORTED_HEADER_VERSIONS = (1, 2)

# IANA MIBenum values OpenIGTLink uses for text.
ENCODING_US_ASCII = 3
ENCODING_UTF8 = 106
_CODECS = {ENCODING_US_ASCII: "ascii", ENCODING_UTF8: "utf-8"}

_U64_MAX = (1 << 64) - 1
_HEADER = struct.Struct(">H12s20sQQQ")
_EXT_HEADER = struct.Struct(">HHII")
_META_ENTRY = struct.Struct(">HHI")
_U16 = struct.Struct(">H")

Buffer = Union[bytes, bytearray, memoryview]


def encode_name(value: str, field: str, size: int) -> bytes:
    """A fixed-size char[] field: UTF-8, at most ``size`` bytes, no NUL (zero-padded on pack)."""
    if not isinstance(value, str):
        raise EncodeError(field, f"a str of at most {size} bytes", type(value).__name__)
    raw = value.encode("utf-8", "surrogatepass")
    if len(raw) > size:
        raise EncodeError(field, f"at most {size} bytes in UTF-8", f"{len(raw)} bytes {value!r}")
    if b"\0" in raw:
        raise EncodeError(field, "no NUL character", repr(value))
    return raw


def decode_name(raw: bytes, field: str, type_name: str = "") -> str:
    """Decode a zero-padded char[] field (up to the first NUL) as UTF-8."""
    text = raw.split(b"\0", 1)[0]
    try:
        return text.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise BodyError(field, "UTF-8 text", f"{text!r} ({exc.reason})",
                        type_name=type_name) from None


def encode_text(text: str, encoding: int, field: str) -> bytes:
    """Text for STRING/COMMAND/metadata: 3 (US-ASCII) or 106 (UTF-8); EncodeError otherwise."""
    if not isinstance(text, str):
        raise EncodeError(field, "a str", type(text).__name__)
    codec = _CODECS.get(encoding)
    if codec is None:
        raise EncodeError(f"{field} encoding", "3 (US-ASCII) or 106 (UTF-8)", encoding)
    try:
        return text.encode(codec)
    except UnicodeEncodeError as exc:
        bad = text[exc.start:exc.end]
        raise EncodeError(field, f"text encodable as {codec} (encoding {encoding})",
                          f"{bad!r} at index {exc.start}") from None


def decode_text(raw: Buffer, encoding: int, field: str, type_name: str = "") -> str:
    """Inverse of `encode_text`; `BodyError` for an unknown encoding or undecodable bytes."""
    codec = _CODECS.get(encoding)
    if codec is None:
        raise BodyError(f"{field} encoding", "3 (US-ASCII) or 106 (UTF-8)", encoding,
                        type_name=type_name)
    try:
        return bytes(raw).decode(codec)
    except UnicodeDecodeError as exc:
        raise BodyError(field, f"{codec} text (encoding {encoding})",
                        f"byte {bytes(raw)[exc.start:exc.start + 1]!r} at offset {exc.start}",
                        type_name=type_name) from None


@dataclass(frozen=True)
class Header:
    """The 58-byte header. ``timestamp`` is the raw u64 (32.32 fixed point, 0 = unset)."""

    version: int
    type_name: str
    device_name: str
    timestamp: int
    body_size: int
    crc: int

    def pack(self) -> bytes:
        if self.version not in SUPPORTED_HEADER_VERSIONS:
            raise EncodeError("header version", "1 or 2", self.version)
        type_raw = encode_name(self.type_name, "type_name", TYPE_NAME_SIZE)
        if not type_raw:
            raise EncodeError("type_name", "a non-empty message type", "''")
        name_raw = encode_name(self.device_name, "device_name", DEVICE_NAME_SIZE)
        for field, value in (("timestamp", self.timestamp), ("body_size", self.body_size),
                             ("crc", self.crc)):
            if not isinstance(value, int) or not 0 <= value <= _U64_MAX:
                raise EncodeError(field, "an integer in [0, 2**64)", value)
        return _HEADER.pack(self.version, type_raw, name_raw, self.timestamp, self.body_size,
                            self.crc)

    @classmethod
    def unpack(cls, data: Buffer) -> Header:
        """Parse 58 bytes. `HeaderError` for a wrong length or header version; `BodyError`
        for a type or device name that is not UTF-8 (framing is still intact then)."""
        version, type_raw, name_raw, timestamp, body_size, crc = unpack_raw(data)
        type_name = decode_name(type_raw, "type_name")
        device_name = decode_name(name_raw, "device_name", type_name)
        return cls(version, type_name, device_name, timestamp, body_size, crc)


def unpack_raw(data: Buffer) -> tuple[int, bytes, bytes, int, int, int]:
    """Header fields with the names still raw; checks the length and header version only."""
    if len(data) != HEADER_SIZE:
        raise HeaderError("header", f"{HEADER_SIZE} bytes", f"{len(data)} bytes")
    fields: tuple[int, bytes, bytes, int, int, int] = _HEADER.unpack(data)
    if fields[0] not in SUPPORTED_HEADER_VERSIONS:
        other = foreign_protocol(bytes(data[:8]))
        raise HeaderError("header version", "1 or 2", fields[0] if other is None else
                          f"{fields[0]}: {other}, not OpenIGTLink (first bytes "
                          f"{bytes(data[:16])!r})")
    return fields


# What other protocols' first bytes say about the peer (the client reads a server's).
_FOREIGN_STARTS: tuple[tuple[tuple[bytes, ...], str], ...] = (
    ((b"GET ", b"POST ", b"HEAD ", b"PUT ", b"DELETE ", b"OPTIONS ", b"PATCH ", b"CONNECT ",
      b"TRACE ", b"PRI * HTTP"), "an HTTP client"),
    ((b"HTTP/", b"<!", b"<html", b"<HTML"), "an HTTP server"),
    ((b"SSH-",), "an SSH peer"),
    ((b"\x16\x03",), "a TLS peer"),
)


def foreign_protocol(first: bytes) -> str | None:
    """The kind of peer whose first bytes these are, if another protocol's ("an HTTP
    client"); None when they say nothing."""
    for starts, kind in _FOREIGN_STARTS:
        if first.startswith(starts):
            return kind
    return None


@dataclass(frozen=True)
class ExtendedHeader:
    """The v2 extended header that opens the body (12 bytes as written by protocol 3)."""

    ext_header_size: int
    meta_header_size: int
    meta_size: int
    message_id: int

    def pack(self) -> bytes:
        try:
            return _EXT_HEADER.pack(self.ext_header_size, self.meta_header_size, self.meta_size,
                                    self.message_id)
        except struct.error as exc:
            raise EncodeError("extended header", "u16, u16, u32, u32 values",
                              f"{self} ({exc})") from None

    @classmethod
    def unpack(cls, body: Buffer, type_name: str = "") -> ExtendedHeader:
        """Read and check against the body's size: `BodyError` names the inconsistent field."""
        if len(body) < EXT_HEADER_SIZE:
            raise BodyError("extended header", f"at least {EXT_HEADER_SIZE} body bytes",
                            f"{len(body)} bytes", type_name=type_name)
        ext, meta_header, meta, msg_id = _EXT_HEADER.unpack_from(body)
        if ext < EXT_HEADER_SIZE:
            raise BodyError("EXT_HEADER_SIZE", f">= {EXT_HEADER_SIZE}", ext, type_name=type_name)
        if meta_header == 0 and meta != 0:
            raise BodyError("META_HEADER_SIZE", "> 0 when META_SIZE > 0",
                            f"0 with META_SIZE {meta}", type_name=type_name)
        if meta_header != 0 and (meta_header - 2) % _META_ENTRY.size:
            raise BodyError("META_HEADER_SIZE", "2 + 8 * INDEX_COUNT", meta_header,
                            type_name=type_name)
        if ext + meta_header + meta > len(body):
            raise BodyError("META_SIZE", f"EXT_HEADER_SIZE + META_HEADER_SIZE + META_SIZE <= "
                            f"BODY_SIZE {len(body)}", f"{ext} + {meta_header} + {meta}",
                            type_name=type_name)
        return cls(ext, meta_header, meta, msg_id)


def pack_metadata(metadata: dict[str, str]) -> tuple[bytes, bytes]:
    """(metadata header incl. INDEX_COUNT, keys and values). Values go out as US-ASCII when
    they are ASCII (what 3D Slicer writes), else UTF-8."""
    if len(metadata) > 0xFFFF:
        raise EncodeError("metadata", "at most 65535 entries", len(metadata))
    entries = [_U16.pack(len(metadata))]
    payload = []
    for key, value in metadata.items():
        key_raw = encode_text(key, ENCODING_UTF8, "metadata key")
        if not key_raw or len(key_raw) > 0xFFFF:
            raise EncodeError("metadata key", "1 to 65535 bytes", f"{len(key_raw)} bytes")
        if not isinstance(value, str):
            raise EncodeError(f"metadata[{key!r}]", "a str", type(value).__name__)
        encoding = ENCODING_US_ASCII if value.isascii() else ENCODING_UTF8
        value_raw = encode_text(value, encoding, f"metadata[{key!r}]")
        if len(value_raw) > 0xFFFFFFFF:
            raise EncodeError(f"metadata[{key!r}]", "at most 2**32-1 bytes", len(value_raw))
        entries.append(_META_ENTRY.pack(len(key_raw), encoding, len(value_raw)))
        payload.append(key_raw)
        payload.append(value_raw)
    return b"".join(entries), b"".join(payload)


# A stream sends the same metadata with every value: small metadata read once is reused.
_CACHED_METADATA_BYTES = 1024


def unpack_metadata(meta_header: Buffer, meta: Buffer, type_name: str = "") -> dict[str, str]:
    """Parse metadata header + key/value bytes; `BodyError` names the inconsistent field."""
    if len(meta_header) + len(meta) <= _CACHED_METADATA_BYTES:
        return dict(_cached_metadata(bytes(meta_header), bytes(meta), type_name))
    return dict(_metadata_items(meta_header, meta, type_name))


def _metadata_items(meta_header: Buffer, meta: Buffer,
                    type_name: str) -> tuple[tuple[str, str], ...]:
    if len(meta_header) == 0:
        return ()  # some writers omit even INDEX_COUNT when there is no metadata
    if len(meta_header) < 2:
        raise BodyError("META_HEADER_SIZE", ">= 2 (INDEX_COUNT)", len(meta_header),
                        type_name=type_name)
    (count,) = _U16.unpack_from(meta_header)
    expected_header = 2 + count * _META_ENTRY.size
    if len(meta_header) != expected_header:
        raise BodyError("META_HEADER_SIZE", f"2 + 8 * INDEX_COUNT ({count}) = {expected_header}",
                        len(meta_header), type_name=type_name)
    entries = [_META_ENTRY.unpack_from(meta_header, 2 + i * _META_ENTRY.size)
               for i in range(count)]
    total = sum(k + v for k, _, v in entries)
    if total != len(meta):
        raise BodyError("META_SIZE", f"sum of KEY_SIZE + VALUE_SIZE = {total}", len(meta),
                        type_name=type_name)
    view = memoryview(meta)
    pos = 0
    result: dict[str, str] = {}  # a repeated key: the last value, as a dict reads them
    for index, (key_size, encoding, value_size) in enumerate(entries):
        key = decode_text(view[pos:pos + key_size], ENCODING_UTF8, f"metadata key #{index}",
                          type_name)
        pos += key_size
        result[key] = decode_text(view[pos:pos + value_size], encoding, f"metadata[{key!r}]",
                                  type_name)
        pos += value_size
    return tuple(result.items())


# Bounded (a peer sending new metadata each time only evicts); errors are not kept.
_cached_metadata = lru_cache(maxsize=256)(_metadata_items)

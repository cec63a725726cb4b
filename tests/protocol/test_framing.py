"""Framing: encode/Decoder with golden headers, any chunking, and every malformed stream."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.crc64 import crc64
from protocol.errors import (
    BodyError,
    BodyTooLargeError,
    CrcMismatchError,
    EncodeError,
    FramingError,
    HeaderError,
    MessageError,
    ProtocolError,
    ReceiveBudgetError,
)
from protocol.framing import DEFAULT_MAX_BODY_SIZE, Decoder, ReceiveBudget, encode
from protocol.header import HEADER_SIZE, Header, foreign_protocol
from protocol.messages import (
    Message,
    RawBody,
    Status,
    String,
    Transform,
)
from tests.protocol import igtl_strategies as strat

TS = 0x6553F10080000000  # 2023-11-14 22:13:20.5 UTC


def tf_message(tx: float = 1.0, name: str = "Tool") -> Message:
    matrix = np.eye(4)
    matrix[:3, 3] = (tx, 2, 3)
    return Message(name, Transform(matrix), TS)


def decode_all(data: bytes, chunk_sizes: list[int] | None = None, **kw: object) -> list[Message]:
    decoder = Decoder(**kw)  # type: ignore[arg-type]
    out: list[Message] = []
    pos = 0
    sizes = iter(chunk_sizes or [len(data) or 1])
    while pos < len(data):
        size = next(sizes, 1)
        decoder.feed(data[pos:pos + size])
        pos += size
        out.extend(decoder.messages())
    assert decoder.buffered == 0
    return out


# ------------------------------------------------------------------ golden, hand-written


def test_transform_golden_bytes() -> None:
    expected = bytes.fromhex(
        "0001"
        + b"TRANSFORM".ljust(12, b"\0").hex()
        + b"Tool".ljust(20, b"\0").hex()
        + "6553f10080000000"  # timestamp
        + "0000000000000030"  # BODY_SIZE 48
        + "acf68624880f705e"  # CRC-64/ECMA-182 of the body (computed with crcmod, by hand)
        + "3f800000 00000000 00000000"  # R11 R21 R31
        + "00000000 3f800000 00000000"  # R12 R22 R32
        + "00000000 00000000 3f800000"  # R13 R23 R33
        + "3f800000 40000000 40400000"  # TX TY TZ = 1, 2, 3 mm
    )
    assert encode(tf_message()) == expected
    (decoded,) = decode_all(expected)
    assert decoded == tf_message()


def test_string_golden_bytes() -> None:
    expected = bytes.fromhex(
        "0001" + b"STRING".ljust(12, b"\0").hex() + b"msg".ljust(20, b"\0").hex()
        + "0000000000000000" + "0000000000000006" + "346f0c6d32b831cf"
        + "006a 0002 6869"
    )
    assert encode(Message("msg", String("hi"))) == expected
    assert decode_all(expected) == [Message("msg", String("hi"))]


def test_status_golden_bytes() -> None:
    expected = bytes.fromhex(
        "0001" + b"STATUS".ljust(12, b"\0").hex() + b"st".ljust(20, b"\0").hex()
        + "0000000000000000" + "0000000000000021" + "0abb6cd71046ad32"
        + "0001" + "0000000000000000" + "00" * 20 + "6f6b00"
    )
    assert encode(Message("st", Status(text="ok"))) == expected
    assert decode_all(expected) == [Message("st", Status(text="ok"))]


def test_v2_golden_bytes_with_one_metadata_pair() -> None:
    message = Message("msg", String("hi"), 0, {"k": "v"}, message_id=7, header_version=2)
    expected = bytes.fromhex(
        "0002" + b"STRING".ljust(12, b"\0").hex() + b"msg".ljust(20, b"\0").hex()
        + "0000000000000000" + "000000000000001e" + "de19c41dc6395b7e"
        + "000c 000a 00000002 00000007"  # EXT_HEADER_SIZE, META_HEADER_SIZE, META_SIZE, MSG_ID
        + "006a 0002 6869"  # content
        + "0001"  # INDEX_COUNT
        + "0001 0003 00000001"  # KEY_SIZE 1, VALUE_ENCODING 3 (ASCII), VALUE_SIZE 1
        + "6b 76"  # "k" "v"
    )
    assert encode(message, header_version=2) == expected
    assert decode_all(expected) == [message]


def test_v1_drops_metadata_and_message_id() -> None:
    message = Message("d", String("x"), 5, {"a": "b"}, 9, 2)
    (decoded,) = decode_all(encode(message, header_version=1))
    assert decoded == Message("d", String("x"), 5, {}, 0, 1)


def test_v2_with_empty_metadata_writes_index_count() -> None:
    data = encode(Message("d", String("x")), header_version=2)
    body = data[HEADER_SIZE:]
    assert body[:12] == bytes.fromhex("000c 0002 00000000 00000000")
    assert body[-2:] == b"\0\0"


def test_non_ascii_metadata_is_utf8() -> None:
    message = Message("d", String("x"), metadata={"clé": "é"}, header_version=2)
    data = encode(message, header_version=2)
    assert struct.pack(">HHI", 4, 106, 2) in data
    assert decode_all(data) == [message]


# ------------------------------------------------------------------ round trips and chunking


@settings(max_examples=80, deadline=None)
@given(strat.messages())
def test_message_roundtrip(message: Message) -> None:
    data = encode(message, header_version=message.header_version)
    (decoded,) = decode_all(data)
    assert decoded == message
    assert encode(decoded, header_version=decoded.header_version) == data


@settings(max_examples=40, deadline=None)
@given(st.lists(strat.messages(), min_size=1, max_size=5),
       st.lists(st.integers(1, 200), max_size=300))
def test_random_chunking(messages: list[Message], chunks: list[int]) -> None:
    stream = b"".join(encode(m, header_version=m.header_version) for m in messages)
    assert decode_all(stream, chunks) == messages


def test_one_byte_feeds_and_many_messages_in_one_chunk() -> None:
    messages = [tf_message(float(i), f"T{i}") for i in range(50)]
    stream = b"".join(encode(m) for m in messages)
    assert decode_all(stream, [1] * len(stream)) == messages
    assert decode_all(stream) == messages


def test_partial_header_is_kept() -> None:
    data = encode(tf_message())
    decoder = Decoder()
    decoder.feed(data[:57])
    assert decoder.next_message() is None and decoder.buffered == 57
    decoder.feed(data[57:100])
    assert decoder.next_message() is None and decoder.buffered == 100
    decoder.feed(data[100:])
    assert decoder.next_message() == tf_message()
    assert decoder.next_message() is None and decoder.buffered == 0


def test_large_body_in_small_chunks_is_linear() -> None:
    # 8 MiB fed in 1 KiB chunks: a quadratic buffer would copy ~32 GiB here.
    message = Message("big", RawBody("BLOB", bytes(8 << 20)))
    data = encode(message)
    decoder = Decoder()
    view = memoryview(data)
    for pos in range(0, len(data), 1024):
        decoder.feed(view[pos:pos + 1024])
    assert decoder.next_message() == message


def test_verify_crc_false_skips_the_check() -> None:
    data = bytearray(encode(tf_message()))
    data[50] ^= 0xFF
    (decoded,) = decode_all(bytes(data), verify_crc=False)
    assert decoded == tf_message()


# ------------------------------------------------------------------ malformed streams


def test_wrong_crc_is_a_message_error_and_the_stream_continues() -> None:
    first = bytearray(encode(tf_message(1.0)))
    first[HEADER_SIZE + 3] ^= 0x01
    decoder = Decoder()
    decoder.feed(bytes(first) + encode(tf_message(2.0)))
    with pytest.raises(CrcMismatchError) as info:
        decoder.next_message()
    assert info.value.field == "CRC"
    assert decoder.next_message() == tf_message(2.0)
    assert decoder.buffered == 0


def test_truncated_body_waits_then_completes() -> None:
    data = encode(tf_message())
    decoder = Decoder()
    decoder.feed(data[:-1])
    assert decoder.next_message() is None  # not an error: the rest may come
    assert decoder.buffered == len(data) - 1
    decoder.feed(data[-1:])
    assert decoder.next_message() == tf_message()


def test_truncated_content_with_consistent_size_is_a_body_error() -> None:
    content = Transform(np.eye(4)).pack()[:-4]
    header = Header(1, "TRANSFORM", "T", 0, len(content), crc64(content)).pack()
    decoder = Decoder()
    decoder.feed(header + content + encode(tf_message()))
    with pytest.raises(BodyError) as info:
        decoder.next_message()
    assert info.value.type_name == "TRANSFORM"
    assert decoder.next_message() == tf_message()


def raw_header(version: int = 1, type_name: bytes = b"TRANSFORM", name: bytes = b"T",
               body_size: int = 0, crc: int = 0) -> bytes:
    return struct.pack(">H12s20sQQQ", version, type_name, name, 0, body_size, crc)


def test_huge_body_size_is_refused_before_allocation() -> None:
    decoder = Decoder()
    decoder.feed(raw_header(body_size=2**63))
    with pytest.raises(BodyTooLargeError) as info:
        decoder.next_message()
    assert info.value.got == 2**63 and info.value.field == "BODY_SIZE"
    assert isinstance(info.value, FramingError)
    # Broken for good: every later call raises the same error.
    with pytest.raises(BodyTooLargeError) as again:
        decoder.next_message()
    assert again.value is info.value
    with pytest.raises(BodyTooLargeError):
        decoder.feed(b"more")


def test_custom_max_body_size() -> None:
    data = encode(tf_message())
    with pytest.raises(BodyTooLargeError):
        decode_all(data, max_body_size=47)
    assert decode_all(data, max_body_size=48) == [tf_message()]
    assert DEFAULT_MAX_BODY_SIZE == 64 * 1024 * 1024


@pytest.mark.parametrize("version", [0, 3, 0x0100, 0xFFFF])
def test_bad_header_version_breaks_the_stream(version: int) -> None:
    decoder = Decoder()
    decoder.feed(raw_header(version=version))
    with pytest.raises(HeaderError) as info:
        decoder.next_message()
    assert info.value.field == "header version" and info.value.got == version
    with pytest.raises(HeaderError):
        list(decoder.messages())
    assert decoder.broken is info.value


def v2_body(ext_size: int, meta_header_size: int, meta_size: int, tail: bytes) -> bytes:
    return struct.pack(">HHII", ext_size, meta_header_size, meta_size, 0) + tail


@pytest.mark.parametrize("body, field", [
    (b"\0" * 11, "extended header"),
    (v2_body(11, 2, 0, b"\0\0"), "EXT_HEADER_SIZE"),
    (v2_body(12, 0, 4, b"abcd"), "META_HEADER_SIZE"),
    (v2_body(12, 5, 0, b"\0" * 5), "META_HEADER_SIZE"),
    (v2_body(12, 2, 100, b"\0\0"), "META_SIZE"),
    (v2_body(12, 10, 2, b"\0\2" + struct.pack(">HHI", 1, 3, 1) + b"kv"), "META_HEADER_SIZE"),
    (v2_body(12, 10, 3, b"\0\1" + struct.pack(">HHI", 1, 3, 1) + b"kvv"), "META_SIZE"),
    (v2_body(12, 10, 2, b"\0\1" + struct.pack(">HHI", 1, 3, 1) + b"k\xff"), "metadata['k']"),
    (v2_body(12, 10, 2, b"\0\1" + struct.pack(">HHI", 1, 77, 1) + b"kv"),
     "metadata['k'] encoding"),
])
def test_inconsistent_v2_sizes_are_body_errors(body: bytes, field: str) -> None:
    decoder = Decoder()
    decoder.feed(raw_header(2, b"STRING", b"S", len(body), crc64(body)) + body
                 + encode(tf_message()))
    with pytest.raises(BodyError) as info:
        decoder.next_message()
    assert info.value.field == field, str(info.value)
    assert info.value.type_name == "STRING"
    assert decoder.next_message() == tf_message()  # framing intact


def test_unknown_type_passes_through() -> None:
    body = b"\x00\x01\x02"
    data = raw_header(1, b"NDARRAY", b"arr", len(body), crc64(body)) + body
    (message,) = decode_all(data)
    assert message.type_name == "NDARRAY" and message.body == RawBody("NDARRAY", body)
    assert encode(message) == data


def test_query_without_body_passes_through() -> None:
    data = raw_header(1, b"GET_POLYDATA", b"", 0, 0)
    (message,) = decode_all(data)
    assert message.body == RawBody("GET_POLYDATA", b"") and message.device_name == ""
    assert encode(message) == data


@pytest.mark.parametrize("name, field", [(b"\xff\xfe", "device_name"),
                                         (b"T", "type_name")])
def test_invalid_utf8_names_are_message_errors(name: bytes, field: str) -> None:
    type_name = b"TRANS\xc3" if field == "type_name" else b"TRANSFORM"
    content = Transform(np.eye(4)).pack()
    bad = raw_header(1, type_name, name, len(content), crc64(content)) + content
    decoder = Decoder()
    decoder.feed(bad + encode(tf_message()))
    with pytest.raises(BodyError) as info:
        decoder.next_message()
    assert info.value.field == field
    assert decoder.next_message() == tf_message()


def test_invalid_utf8_string_body() -> None:
    content = bytes.fromhex("006a 0002 c328")
    decoder = Decoder()
    decoder.feed(raw_header(1, b"STRING", b"s", len(content), crc64(content)))
    decoder.feed(content)
    with pytest.raises(BodyError, match="utf-8"):
        decoder.next_message()


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=400), st.sampled_from([1, 2]),
       st.sampled_from(["TRANSFORM", "STRING", "STATUS", "POLYDATA", "POINT", "IMAGE",
                        "COMMAND", "RTS_COMMAND"]))
def test_garbage_bodies_only_raise_typed_errors(body: bytes, version: int, type_name: str) -> None:
    decoder = Decoder()
    decoder.feed(raw_header(version, type_name.encode(), b"g", len(body), crc64(body)))
    decoder.feed(body)
    try:
        decoder.next_message()
    except MessageError:
        pass
    assert decoder.buffered == 0


@settings(max_examples=200, deadline=None)
@given(st.binary(min_size=58, max_size=300))
def test_garbage_streams_only_raise_typed_errors(stream: bytes) -> None:
    decoder = Decoder(max_body_size=1 << 16)
    decoder.feed(stream)
    for _ in range(10):
        try:
            if decoder.next_message() is None:
                break
        except FramingError:
            break
        except ProtocolError:
            continue


# ------------------------------------------------------------------ encode errors


@pytest.mark.parametrize("message, version, field", [
    (Message("x" * 21, String("a")), 1, "device_name"),
    (Message("é" * 11, String("a")), 1, "device_name"),
    (Message("d", String("a"), timestamp=-1), 1, "timestamp"),
    (Message("d", String("a"), timestamp=2**64), 1, "timestamp"),
    (Message("d", String("a")), 3, "header_version"),
    (Message("d", String("a"), message_id=2**32), 2, "message_id"),
    (Message("d", String("a"), metadata={"": "x"}), 2, "metadata key"),
    (Message("d", RawBody("THIS_IS_TOO_LONG", b"")), 1, "type_name"),
])
def test_encode_errors(message: Message, version: int, field: str) -> None:
    with pytest.raises(EncodeError) as info:
        encode(message, header_version=version)
    assert info.value.field == field


def test_header_unpack_standalone() -> None:
    data = encode(tf_message())
    header = Header.unpack(data[:HEADER_SIZE])
    assert header == Header(1, "TRANSFORM", "Tool", TS, 48, 0xACF68624880F705E)
    assert header.pack() == data[:HEADER_SIZE]
    with pytest.raises(HeaderError):
        Header.unpack(data[:57])


# ------------------------------------------------------------------ what a decoder holds


def blob(size: int, name: str = "big") -> bytes:
    return encode(Message(name, RawBody("BLOB", bytes(size))))


def test_frame_in_progress_and_frames_count_track_the_stream() -> None:
    decoder = Decoder()
    data = encode(tf_message())
    assert not decoder.frame_in_progress and decoder.pending_body_size is None
    decoder.feed(data[:7])  # a slowloris' 7 bytes
    assert decoder.next_message() is None
    assert decoder.frame_in_progress and decoder.pending_body_size is None
    decoder.feed(data[7:HEADER_SIZE + 1])
    assert decoder.next_message() is None
    assert decoder.pending_body_size == len(data) - HEADER_SIZE and decoder.frames == 0
    decoder.feed(data[HEADER_SIZE + 1:] + data[:3])  # the end of one, the start of the next
    assert decoder.next_message() == tf_message() and decoder.next_message() is None
    assert decoder.frames == 1 and decoder.frame_in_progress and decoder.buffered == 3


def test_a_bad_message_counts_as_a_finished_frame() -> None:
    bad = bytearray(encode(tf_message()))
    bad[HEADER_SIZE] ^= 0xFF
    decoder = Decoder()
    decoder.feed(bytes(bad))
    with pytest.raises(CrcMismatchError):
        decoder.next_message()
    assert decoder.frames == 1 and not decoder.frame_in_progress


def test_a_consumed_large_buffer_is_dropped_at_once() -> None:
    decoder = Decoder()
    decoder.feed(blob(4 << 20))
    assert decoder.next_message() is not None
    assert decoder.buffered == 0 and len(decoder._buffer) == 0  # not kept to the next feed


def test_budget_is_claimed_from_the_header_and_released_with_the_body() -> None:
    budget = ReceiveBudget(3 << 20, uncounted_body_bytes=1 << 20)
    first, second = Decoder(budget=budget), Decoder(budget=budget)
    data = blob(3 << 20)
    first.feed(data[:HEADER_SIZE])
    assert first.next_message() is None
    assert budget.in_use == 2 << 20  # the declared body less the uncounted part, no body yet
    assert budget.cost(100) == 0
    second.feed(data[:HEADER_SIZE + 10])
    with pytest.raises(ReceiveBudgetError) as info:
        second.next_message()
    assert isinstance(info.value, FramingError) and info.value.got == 3 << 20
    assert "1048576 bytes left" in str(info.value) and "3145728 bytes" in str(info.value)
    assert budget.in_use == 2 << 20  # the refused one claimed nothing
    # A small message still gets through while the budget is taken.
    small = Decoder(budget=budget)
    small.feed(encode(tf_message()))
    assert small.next_message() == tf_message()
    first.feed(data[HEADER_SIZE:])
    assert first.next_message() is not None
    assert budget.in_use == 0


def test_close_gives_back_buffer_and_budget_and_refuses_more() -> None:
    budget = ReceiveBudget(8 << 20)
    decoder = Decoder(budget=budget)
    data = blob(5 << 20)
    decoder.feed(data[:len(data) // 2])
    assert decoder.next_message() is None and budget.in_use > 0
    decoder.close()
    decoder.close()  # idempotent
    assert budget.in_use == 0 and decoder.buffered == 0 and not decoder.frame_in_progress
    with pytest.raises(FramingError, match="closed"):
        decoder.feed(b"x")


def test_budget_arguments_are_checked() -> None:
    with pytest.raises(ValueError, match="total_bytes > 0"):
        ReceiveBudget(0)


@pytest.mark.parametrize(("first", "kind"), [
    (b"GET / HTTP/1.1\r\nHost: localhost:18944\r\n", "an HTTP client"),
    (b"POST /x HTTP/1.1\r\n", "an HTTP client"),
    (b"HTTP/1.1 400 Bad Request\r\n", "an HTTP server"),
    (b"SSH-2.0-OpenSSH_9.2\r\n", "an SSH peer"),
    (b"\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03", "a TLS peer"),
])
def test_another_protocol_s_bytes_are_named_in_the_header_error(first: bytes,
                                                                 kind: str) -> None:
    decoder = Decoder()
    decoder.feed(first.ljust(HEADER_SIZE, b"\0"))
    with pytest.raises(HeaderError) as info:
        decoder.next_message()
    version = int.from_bytes(first[:2], "big")
    assert str(info.value).startswith(f"header version: expected 1 or 2, got {version}: "
                                      f"{kind}, not OpenIGTLink (first bytes ")
    assert foreign_protocol(first) == kind
    assert foreign_protocol(raw_header(version=7)) is None


def test_a_large_body_is_received_apart_and_the_stream_goes_on() -> None:
    """A body of LARGE_BODY_BYTES or more goes into a buffer of its own as it arrives
    (none copied again when it is complete); any chunking, with the next message in the
    same chunk as its last bytes, gives the same messages."""
    from protocol.framing import LARGE_BODY_BYTES
    from protocol.messages import RawBody

    big = Message("big", RawBody("BLOB", bytes(range(256)) * (LARGE_BODY_BYTES // 256 + 3)))
    small = Message("small", String("after"))
    wire = encode(big, header_version=2) + encode(small, header_version=2)
    for chunk in (997, 4093, 65536, 1 << 20, len(wire)):
        decoder = Decoder(max_body_size=2 * LARGE_BODY_BYTES)
        got = []
        for start in range(0, len(wire), chunk):
            decoder.feed(wire[start:start + chunk])
            assert decoder.frame_in_progress or not decoder.buffered
            got.extend(decoder.messages())
        assert [m.device_name for m in got] == ["big", "small"], chunk
        assert bytes(got[0].body.data) == bytes(big.body.data)
        assert got[1].body.text == "after" and decoder.buffered == 0


def test_metadata_read_again_is_a_dict_of_its_own_and_errors_are_never_kept() -> None:
    """A stream repeats its metadata with each value: what was read once is reused."""
    from protocol.errors import BodyError
    from protocol.header import unpack_metadata

    head = struct.pack(">HHHI", 1, 1, 3, 2)  # one entry: key 1 byte, UTF-8, value 2 bytes
    first = unpack_metadata(head, b"kvv")
    first["k"] = "changed by its reader"
    assert unpack_metadata(head, b"kvv") == {"k": "vv"}
    for _ in range(2):  # bad bytes are refused every time, not only the first
        with pytest.raises(BodyError, match="META_SIZE"):
            unpack_metadata(head, b"kv")
    assert unpack_metadata(b"", b"") == {}

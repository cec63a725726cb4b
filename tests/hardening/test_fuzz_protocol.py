"""Fuzzing the decoder and the command schema in-process (bounded: a few seconds).

Whatever the bytes, the decoder yields a message, raises `MessageError` (skip it and go
on) or `FramingError` (close); the schema yields a request or raises `CommandError`.
Nothing else may escape. The longer campaign is bench/fuzz_decoder.py (atheris).
"""

from __future__ import annotations

import json
import struct

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hardening_tools import framing_breakers, malformed_inputs, raw_message, valid_messages
from protocol import commands as c
from protocol.crc64 import crc64
from protocol.errors import FramingError, MessageError
from protocol.framing import Decoder

FAST = settings(max_examples=300, deadline=None,
                suppress_health_check=[HealthCheck.too_slow])
TYPES = ["TRANSFORM", "STRING", "STATUS", "IMAGE", "POLYDATA", "POINT", "COMMAND",
         "RTS_COMMAND", "NDARRAY", "TDATA", "POSITION", "GET_IMAGE", "QTDATA", "NOPE"]


def drain(data: bytes, chunks: list[int] | None = None, **options: object) -> list[str]:
    """Feed `data` (in the given chunk sizes); the outcome of each message, by name."""
    decoder = Decoder(max_body_size=1 << 20, **options)  # type: ignore[arg-type]
    outcomes: list[str] = []
    pieces = [data]
    if chunks:
        pieces, rest = [], data
        for size in chunks:
            pieces.append(rest[:size])
            rest = rest[size:]
        pieces.append(rest)
    for piece in pieces:
        try:
            decoder.feed(piece)
        except FramingError:
            return outcomes + ["closed"]
        while True:
            try:
                message = decoder.next_message()
            except MessageError as error:
                outcomes.append(type(error).__name__)
                continue
            except FramingError:
                return outcomes + ["closed"]
            if message is None:
                break
            outcomes.append(message.type_name)
    return outcomes


def test_every_catalogued_bad_input_is_a_typed_error_or_a_message() -> None:
    for name, data in {**malformed_inputs(), **framing_breakers()}.items():
        outcomes = drain(data)
        assert outcomes, name  # a complete message was judged one way or another
    assert drain(framing_breakers()["BODY_SIZE 2^63"]) == ["closed"]
    assert drain(malformed_inputs()["wrong CRC"]) == ["CrcMismatchError"]


def test_the_stream_goes_on_after_every_bad_message() -> None:
    good = valid_messages()[1]
    for name, data in malformed_inputs().items():
        assert drain(data + good)[-1] == "STRING", name


@FAST
@given(st.binary(max_size=600), st.lists(st.integers(1, 64), max_size=8))
def test_random_bytes(data: bytes, chunks: list[int]) -> None:
    drain(data, chunks)


@FAST
@given(st.sampled_from(TYPES), st.binary(max_size=400), st.integers(1, 2))
def test_random_bodies_with_a_valid_crc(type_name: str, body: bytes, version: int) -> None:
    # A correct CRC sends the nonsense through to the body parsers.
    drain(raw_message(type_name, body, version=version))


@FAST
@given(st.sampled_from(range(7)), st.data())
def test_mutated_valid_messages(index: int, data: st.DataObject) -> None:
    message = bytearray(valid_messages()[index])
    for _ in range(data.draw(st.integers(1, 6))):
        position = data.draw(st.integers(0, len(message) - 1))
        message[position] = data.draw(st.integers(0, 255))
    cut = data.draw(st.integers(0, len(message)))
    drain(bytes(message[:cut]), data.draw(st.lists(st.integers(1, 32), max_size=4)))
    # Recompute the CRC so the body parser meets the mutation.
    if len(message) >= 58:
        body = bytes(message[58:])
        struct.pack_into(">QQ", message, 42, len(body), crc64(body))
        drain(bytes(message))


json_leaf = st.one_of(st.none(), st.booleans(), st.integers(), st.floats(allow_nan=False),
                      st.text(max_size=20))
json_values = st.recursive(json_leaf, lambda inner: st.lists(inner, max_size=4)
                           | st.dictionaries(st.text(max_size=8), inner, max_size=4),
                           max_leaves=20)


@FAST
@given(st.sampled_from(sorted(c.REQUEST_TYPES) + ["nope", ""]),
       st.one_of(st.binary(max_size=200), st.text(max_size=200)))
def test_command_text_garbage(op: str, text: bytes | str) -> None:
    try:
        c.parse_request(op, text)
    except c.CommandError:
        pass


@FAST
@given(st.sampled_from(sorted(c.REQUEST_TYPES)),
       st.dictionaries(st.sampled_from(["topic", "type", "value", "node", "names", "values",
                                        "parent", "child", "matrix", "name", "service",
                                        "request", "timeout", "rate_hz", "qos", "source",
                                        "static", "stamp", "time", "schema"]),
                       json_values, max_size=6))
def test_command_fields_of_any_shape(op: str, args: dict) -> None:
    try:
        request = c.parse_request(op, json.dumps(args))
    except c.CommandError:
        return
    # Anything accepted can be encoded again and parses to the same request.
    assert c.parse_request(op, request.to_json()) == request


def test_deeply_nested_and_huge_json_are_refused_by_name() -> None:
    for text in ("[" * 100_000 + "]" * 100_000, '{"a":' * 5000 + "1" + "}" * 5000,
                 '{"topic": "/x", "value": "' + "x" * (2 << 20) + '"}',
                 '{"value": 1' + "0" * 5000 + "}"):
        try:
            c.parse_request("publish", text)
        except (c.BadJsonError, c.TooLargeError):
            continue
        raise AssertionError(f"accepted {text[:40]}...")

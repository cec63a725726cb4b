"""Header-version negotiation per connection."""

from __future__ import annotations

import pytest

from protocol.framing import Decoder, encode
from protocol.messages import Message, Status, String
from protocol.negotiation import HeaderVersionNegotiator


def test_starts_with_v1() -> None:
    negotiator = HeaderVersionNegotiator()
    assert negotiator.outgoing_version == 1 and not negotiator.peer_speaks_v2


def test_v1_messages_keep_v1() -> None:
    negotiator = HeaderVersionNegotiator()
    assert negotiator.observe(Message("a", String("x"), header_version=1)) == 1
    assert negotiator.outgoing_version == 1


def test_slicer_announcement_switches_to_v2_for_good() -> None:
    # What 3D Slicer sends on connect: a STATUS with metadata, header v2, decoded from bytes.
    hello = encode(Message("", Status(), metadata={"a": "b"}, header_version=2), header_version=2)
    decoder = Decoder()
    decoder.feed(hello)
    announcement = decoder.next_message()
    assert announcement is not None
    negotiator = HeaderVersionNegotiator()
    assert negotiator.observe(announcement) == 2
    assert negotiator.observe(Message("a", String("x"), header_version=1)) == 2  # stays
    assert negotiator.peer_speaks_v2


def test_max_version_caps() -> None:
    negotiator = HeaderVersionNegotiator(max_version=1)
    negotiator.observe(Message("a", String("x"), header_version=2))
    assert negotiator.outgoing_version == 1 and negotiator.peer_speaks_v2


def test_reset() -> None:
    negotiator = HeaderVersionNegotiator()
    negotiator.observe(Message("a", String("x"), header_version=2))
    negotiator.reset()
    assert negotiator.outgoing_version == 1


def test_invalid_max_version() -> None:
    with pytest.raises(ValueError, match="max_version"):
        HeaderVersionNegotiator(max_version=3)

"""A frame written from its parts (an image's header, its pixels where they lie, metadata)
through a client's slot, compiled and pure Python alike: the peer reads their concatenation,
whole or with the rest kept for the loop, on real sockets."""

from __future__ import annotations

import socket
from typing import Any

import numpy as np
import pytest

from bridge.core import native_stream
from bridge.core.native_stream import BROKEN, REFUSED, SENT, STASHED, PySlot

SLOTS = [pytest.param(PySlot, id="python"),
         pytest.param(lambda: native_stream.new_slot(None), id="compiled",
                      marks=pytest.mark.skipif(not native_stream.available(),
                                               reason="the native lane is not built here"))]


def parts(pixels: int) -> tuple[bytes, memoryview, bytes]:
    image = np.arange(pixels, dtype=np.uint32).astype(np.uint8)
    return b"head" * 15, memoryview(image).toreadonly(), b"metadata"


def connected(new_slot: Any, send_buffer: int | None = None) -> tuple[Any, socket.socket,
                                                                       socket.socket]:
    ours, theirs = socket.socketpair()
    ours.setblocking(False)
    if send_buffer is not None:
        ours.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, send_buffer)
    slot = new_slot()
    with slot:
        slot.connect(ours)
        slot.open = True
    return slot, ours, theirs


def read_exactly(sock: socket.socket, n: int) -> bytes:
    sock.settimeout(5)
    out = bytearray()
    while len(out) < n:
        chunk = sock.recv(n - len(out))
        assert chunk, f"expected {n} bytes, the peer closed after {len(out)}"
        out += chunk
    return bytes(out)


@pytest.mark.parametrize("new_slot", SLOTS)
def test_parts_taken_whole_reach_the_peer_as_one_frame(new_slot: Any) -> None:
    slot, ours, theirs = connected(new_slot)
    frame = parts(3000)
    with slot:
        assert slot.send(frame) == SENT
        assert slot.open and not slot.has_stash and slot.sent == 1
    assert read_exactly(theirs, sum(len(bytes(p)) for p in frame)) == b"".join(frame)
    ours.close()
    theirs.close()


@pytest.mark.parametrize("new_slot", SLOTS)
def test_parts_taken_in_part_keep_the_rest_and_refuse_more_until_it_is_taken(
        new_slot: Any) -> None:
    slot, ours, theirs = connected(new_slot, send_buffer=4096)
    frame = parts(900_000)  # far beyond what the kernel takes at once
    whole = b"".join(frame)
    with slot:
        assert slot.send(frame) == STASHED
        assert not slot.open and slot.has_stash and slot.sent == 1
        assert slot.send(b"next") == REFUSED  # nothing may pass the rest
        rest = slot.take_stash()
    assert rest is not None and 0 < len(rest) < len(whole)
    taken = read_exactly(theirs, len(whole) - len(rest))
    assert taken + rest == whole
    ours.close()
    theirs.close()


@pytest.mark.parametrize("new_slot", SLOTS)
def test_a_strided_part_is_sent_as_its_bytes(new_slot: Any) -> None:
    slot, ours, theirs = connected(new_slot)
    strided = memoryview(np.arange(200, dtype=np.uint8))[::2]  # every other byte
    with slot:
        assert slot.send((b"head", strided, b"tail")) == SENT
    assert read_exactly(theirs, 4 + 100 + 4) == b"head" + bytes(range(0, 200, 2)) + b"tail"
    ours.close()
    theirs.close()


@pytest.mark.parametrize("new_slot", SLOTS)
def test_parts_to_a_peer_that_has_gone_say_broken(new_slot: Any) -> None:
    slot, ours, theirs = connected(new_slot)
    theirs.close()
    with slot:
        assert slot.send(parts(10)) == BROKEN
        assert not slot.open
    ours.close()


@pytest.mark.skipif(not native_stream.available(), reason="the native lane is not built here")
def test_the_compiled_slot_says_how_many_parts_it_takes() -> None:
    slot, ours, theirs = connected(lambda: native_stream.new_slot(None))
    with slot, pytest.raises(ValueError, match="expected 1 to 8 parts, got 9"):
        slot.send((b"x",) * 9)
    ours.close()
    theirs.close()

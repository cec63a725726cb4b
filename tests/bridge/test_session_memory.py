"""A closed client's memory comes back at close, without the cyclic garbage collector.

In-process: the real `BridgeServer` on an ephemeral port and real TCP clients, in one
asyncio loop, so that the session objects themselves can be watched (weak references)
and the receive buffers traced (tracemalloc) with the GC disabled.
"""

from __future__ import annotations

import asyncio
import dataclasses
import gc
import tracemalloc
import weakref
from typing import Awaitable, Callable, Iterator

import pytest

from bridge.core.hub import Hub
from bridge.core.server import BridgeServer
from bridge.core.session import ClientSession, SessionLimits
from protocol.framing import Decoder, encode
from protocol.header import HEADER_SIZE
from protocol.messages import Image, Message, RawBody, StatusCode
from support import scaled

MIB = 1 << 20


@pytest.fixture
def no_gc() -> Iterator[None]:
    gc.collect()
    gc.disable()
    try:
        yield
    finally:
        gc.enable()


async def until(predicate: Callable[[], bool], what: str, timeout: float = 10.0) -> None:
    deadline = asyncio.get_running_loop().time() + scaled(timeout)
    while not predicate():
        if asyncio.get_running_loop().time() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        await asyncio.sleep(0.005)


def run_with_server(scenario: Callable[[BridgeServer], Awaitable[None]], *,
                    limits: SessionLimits | None = None) -> None:
    async def main() -> None:
        server = BridgeServer(Hub(asyncio.get_running_loop()), lambda message, session: None,
                              host="127.0.0.1", port=0, limits=limits or SessionLimits())
        await server.start()
        try:
            await scenario(server)
        finally:
            await server.close()
    asyncio.run(main())


def body_frame(size: int) -> bytes:
    return encode(Message("big", RawBody("BLOB", bytes(size))))


def receiving(server: BridgeServer, at_least: int) -> list[ClientSession]:
    return [s for s in server.sessions if s._decoder.buffered >= at_least]


def test_six_clients_holding_40_mib_then_gone_give_it_all_back(no_gc: None) -> None:
    """The issue's case: 6 clients each hold 40 MiB of an unfinished body, then leave."""
    async def scenario(server: BridgeServer) -> None:
        frame = body_frame(40 * MIB)
        tracemalloc.start()
        try:
            baseline = tracemalloc.get_traced_memory()[0]
            writers = []
            for _ in range(6):
                _, writer = await asyncio.open_connection("127.0.0.1", server.port)
                writer.write(frame[:-1000])  # all but the end: the body stays unfinished
                writers.append(writer)
            await until(lambda: len(receiving(server, 40 * MIB - 1000)) == 6,
                        "6 sessions holding 40 MiB each")
            held = tracemalloc.get_traced_memory()[0] - baseline
            sessions = [weakref.ref(s) for s in server.sessions]
            decoders = [weakref.ref(s._decoder) for s in server.sessions]
            for writer in writers:
                writer.close()
            await until(lambda: not server.sessions, "every session closed")
            freed = tracemalloc.get_traced_memory()[0] - baseline
        finally:
            tracemalloc.stop()
        print(f"\n6 x 40 MiB unfinished bodies: {held / MIB:.0f} MiB traced while held, "
              f"{freed / MIB:.2f} MiB after the clients left (GC disabled)")
        assert held > 6 * 40 * MIB
        assert freed < 2 * MIB
        assert all(ref() is None for ref in sessions + decoders)  # gone by refcount alone
        assert server.budget.in_use == 0
    # Budget and deadline out of the way: this is about what a closed session keeps.
    run_with_server(scenario, limits=SessionLimits(receive_budget_bytes=512 * MIB,
                                                   frame_deadline_s=600.0))


@pytest.mark.parametrize("ending", ["framing error", "frame deadline", "daemon closes"])
def test_a_session_the_daemon_closes_is_freed_at_once(no_gc: None, ending: str) -> None:
    limits = dataclasses.replace(SessionLimits(), frame_deadline_s=0.2 if ending ==
                                 "frame deadline" else 60.0)

    async def scenario(server: BridgeServer) -> None:
        reader, writer = await asyncio.open_connection("127.0.0.1", server.port)
        frame = body_frame(8 * MIB)
        writer.write(frame[:-10])
        await until(lambda: len(receiving(server, 8 * MIB - 10)) == 1, "the body held")
        (session,) = server.sessions
        ref = weakref.ref(session)
        if ending == "framing error":
            writer.write(frame[-10:] + b"\x00\x07" + bytes(HEADER_SIZE))  # header version 7
        elif ending == "daemon closes":
            session.close()
        del session
        await until(lambda: not server.sessions, "the session closed")
        decoder = Decoder()
        decoder.feed(await asyncio.wait_for(reader.read(), scaled(10)))
        replies = list(decoder.messages())
        writer.close()
        assert ref() is None
        if ending == "framing error":
            assert replies[-1].body.code == StatusCode.UNKNOWN_ERROR
            assert "header version" in replies[-1].body.text
        elif ending == "frame deadline":
            assert replies[-1].body.code == StatusCode.TIME_OUT
            assert "frame deadline" in replies[-1].body.text
        assert server.budget.in_use == 0
    run_with_server(scenario, limits=limits)


# ---------------------------------------------------------------------------- bulk frames


def _cloud() -> Message:
    import numpy as np

    from protocol.messages import PolyData

    rng = np.random.default_rng(7)
    points = rng.uniform(-500, 500, (200_000, 3)).astype(np.float32)
    vertices = np.array([1, 0, 1, 1, 1, 2], dtype=np.uint32)
    return Message(device_name="cloud", body=PolyData(points=points, vertices=vertices),
                   timestamp=123 << 32, metadata={"ros2.type": "sensor_msgs/msg/PointCloud2"})


def _image() -> Message:
    import numpy as np

    pixels = np.random.default_rng(3).integers(0, 255, (1, 480, 640, 3), dtype=np.uint8)
    return Message(device_name="camera", body=Image(pixels=pixels), timestamp=123 << 32,
                   metadata={"ros2.type": "sensor_msgs/msg/Image"})


@pytest.mark.parametrize("make", [_cloud, _image], ids=["cloud", "image"])
@pytest.mark.parametrize("first", [1, 2])
def test_a_bulk_frame_keeps_one_encoding_and_gives_the_same_bytes(
        first: int, make: Callable[[], Message]) -> None:
    """The hub's newest value of an image or a cloud is held once (its v2 wire parts, not
    joined), not as body arrays and bytes; other versions and the message come back from
    those bytes."""
    from bridge.core.outbox import BulkFrame, Frame

    message = make()
    bulk, plain = BulkFrame(message), Frame(message)
    other = 3 - first
    assert bulk.encoded(first) == plain.encoded(first)
    assert bulk._message is None and bulk._parts is not None  # v2 keeps the metadata
    assert not bulk._encoded  # nothing joined is kept
    assert b"".join(bulk.encoded_parts(2)) == plain.encoded(2)
    assert bulk.encoded(other) == plain.encoded(other)
    assert not bulk._encoded  # v1 bytes are made again when asked for, not kept
    again = bulk.message
    assert encode(again, header_version=2) == plain.encoded(2)
    assert again.device_name == message.device_name
    assert again.timestamp == message.timestamp

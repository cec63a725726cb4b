"""Images posted from a ROS thread to real TCP clients, written from that thread as their
parts: a client that reads gets every one whole; one that stops reading gets whole frames
and then the newest, never a queue of stale images.

In-process: the real `BridgeServer` on an ephemeral port, real sockets, the posts from
another thread as the ROS executor's are."""

from __future__ import annotations

import asyncio
import socket
import sys
import threading

import numpy as np

from bridge.core.hub import Hub, frame_for
from bridge.core.outbox import BulkFrame, Frame
from bridge.core.server import BridgeServer
from bridge.core.session import LARGE_KERNEL_UNSENT_BYTES, SessionLimits
from protocol.framing import Decoder
from protocol.messages import Image, Message
from support import scaled

SHAPE = (1, 480, 640, 3)  # a VGA rgb8 frame: 921,600 bytes of pixels


def image(index: int) -> Message:
    return Message(device_name="camera", body=Image(pixels=np.full(SHAPE, index, np.uint8)),
                   timestamp=(1 << 32) + index)


async def until(predicate, what: str, timeout: float = 20.0) -> None:  # noqa: ANN001
    deadline = asyncio.get_running_loop().time() + scaled(timeout)
    while not predicate():
        if asyncio.get_running_loop().time() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        await asyncio.sleep(0.005)


def received_images(data: bytes) -> list[int]:
    decoder = Decoder(max_body_size=len(data))
    decoder.feed(data)
    out = []
    for message in decoder.messages():
        pixels = message.body.pixels
        assert pixels.shape == SHAPE and (pixels == pixels.flat[0]).all(), "a frame is whole"
        out.append(int(pixels.flat[0]))
    return out


def run(scenario) -> None:  # noqa: ANN001
    async def main() -> None:
        hub = Hub(asyncio.get_running_loop())
        server = BridgeServer(hub, lambda message, session: None, host="127.0.0.1", port=0,
                              limits=SessionLimits(negotiation_grace_s=0.01))
        await server.start()
        try:
            await scenario(hub, server)
        finally:
            await server.close()
    asyncio.run(main())


def post_from_a_thread(hub: Hub, first: int, count: int) -> None:
    channel = hub.open_channel("camera")
    poster = threading.Thread(target=lambda: [hub.post_frame(channel, frame_for(image(n)))
                                              for n in range(first, first + count)])
    poster.start()
    poster.join()


def test_a_reading_client_gets_every_image_whole_and_in_order() -> None:
    async def scenario(hub: Hub, server: BridgeServer) -> None:
        reader, writer = await asyncio.open_connection("127.0.0.1", server.port)
        await until(lambda: len(hub.clients) == 1, "the client attached")
        got = bytearray()
        size = None
        for n in range(10):  # one at a time, read before the next: each goes directly
            post_from_a_thread(hub, n, 1)
            while size is None or len(got) < size * (n + 1):
                got += await asyncio.wait_for(reader.read(1 << 20), scaled(10))
                if size is None and len(got) >= 58:
                    size = 58 + int.from_bytes(got[42:50], "big")
        assert received_images(bytes(got)) == list(range(10))
        assert hub.direct == 10
        writer.close()
    run(scenario)


def test_a_frame_larger_than_the_kernel_takes_at_once_goes_through_the_loop_whole() -> None:
    """A VGA point cloud's POLYDATA is 9 MB: more than `LARGE_KERNEL_UNSENT_BYTES`. Written
    from the ROS thread its rest would be copied into the slot's stash and again into
    asyncio's buffer; the loop writes it instead, from its own parts."""
    shape = (1, 1536, 2048, 3)  # 9.4 MB of pixels
    assert np.prod(shape) > LARGE_KERNEL_UNSENT_BYTES

    async def scenario(hub: Hub, server: BridgeServer) -> None:
        reader, writer = await asyncio.open_connection("127.0.0.1", server.port)
        await until(lambda: len(hub.clients) == 1, "the client attached")
        (session,) = server.sessions
        channel = hub.open_channel("cloud")
        decoder = Decoder(max_body_size=1 << 26)
        firsts: list[int] = []
        for n in range(3):  # one at a time, read before the next
            big = Message(device_name="cloud", body=Image(pixels=np.full(shape, n, np.uint8)),
                          timestamp=(1 << 32) + n)
            poster = threading.Thread(target=hub.post_frame, args=(channel, frame_for(big)))
            poster.start()
            poster.join()
            while len(firsts) < n + 1:
                decoder.feed(await asyncio.wait_for(reader.read(1 << 20), scaled(10)))
                for message in decoder.messages():
                    pixels = message.body.pixels
                    assert (pixels == pixels.flat[0]).all(), "a frame is whole"
                    firsts.append(int(pixels.flat[0]))
        assert firsts == [0, 1, 2]  # each whole, in order
        assert int(session.slot.sent) == 0  # none written (or stashed) by the posting thread
        writer.close()
    run(scenario)


def test_a_client_that_stops_reading_gets_whole_frames_then_the_newest() -> None:
    async def scenario(hub: Hub, server: BridgeServer) -> None:
        sock = socket.create_connection(("127.0.0.1", server.port))
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 64 * 1024)
        await until(lambda: len(hub.clients) == 1, "the client attached")
        (session,) = server.sessions
        post_from_a_thread(hub, 0, 40)  # 37 MB to a client that reads nothing meanwhile
        await until(lambda: hub.pending == 0 and not session._handed, "the posts settled")
        sock.setblocking(False)
        got = bytearray()
        deadline = asyncio.get_running_loop().time() + scaled(20)
        while True:  # read it all now: the newest must come last
            assert asyncio.get_running_loop().time() < deadline, "the newest never came"
            await asyncio.sleep(0.01)
            try:
                while chunk := sock.recv(1 << 20):
                    got += chunk
            except BlockingIOError:
                pass
            images = received_images(bytes(got)) if got else []
            if images and images[-1] == 39:
                break
        assert images == sorted(images) and len(set(images)) == len(images)
        # What the kernel held when it stopped, then the newest: not the 40 in a queue.
        assert len(images) < 12, images
        sock.close()
    run(scenario)


def test_a_frame_encoded_by_two_threads_at_once_gives_both_the_same_bytes() -> None:
    """The taking thread writes a new image while the loop sends it to a client that has
    just connected: whichever encodes first, both get the same parts, and the message can
    still be read back."""
    vga = Message(device_name="camera", body=Image(pixels=np.full(SHAPE, 7, np.uint8)))
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # threads take turns often: the window is hit, not missed
    try:
        for _ in range(100):
            encode_twice(frame_for(vga))
    finally:
        sys.setswitchinterval(interval)


def encode_twice(frame: Frame) -> None:
    assert isinstance(frame, BulkFrame)
    frame.clock = 5
    results: list[bytes] = []
    start = threading.Barrier(2)
    threads = [threading.Thread(target=_encode_after, args=(start, frame, results))
               for _ in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert len(results) == 2 and results[0] == results[1]
    assert int(frame.message.body.pixels.flat[0]) == 7


def _encode_after(start: threading.Barrier, frame: Frame, results: list[bytes]) -> None:
    start.wait()
    results.append(b"".join(frame.encoded_parts(2)))

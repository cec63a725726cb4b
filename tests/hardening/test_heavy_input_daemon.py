"""Heavy input (issue 22, item 7): a large data message is judged by its header before a
byte of its body is decoded, and decoded off the event loop. A real daemon, raw TCP
clients; what they are told shows where the daemon looked."""

from __future__ import annotations

import struct

import numpy as np

from hardening_tools import RawClient, ask, command_bytes, raw_message
from protocol.messages import StatusCode
from support import Processes, start_daemon, wait_until


def _polydata(body_bytes: int) -> bytes:
    """A POLYDATA body whose vertex cells alternate 1 and 2 indices (decoded one Python
    step per cell), about ``body_bytes`` long."""
    pairs = body_bytes // 20
    cells = np.empty((pairs, 5), dtype=">u4")
    cells[:, 0], cells[:, 1], cells[:, 2], cells[:, 3], cells[:, 4] = 1, 0, 2, 0, 1
    head = struct.pack(">10I", 2, 2 * pairs, cells.nbytes, 0, 0, 0, 0, 0, 0, 0)
    return head + np.zeros(6, dtype=">f4").tobytes() + cells.tobytes()


def _corrupt(body: bytes, device: str) -> bytes:
    """The message with a CRC that does not match: decoding it would say CHECKSUM_ERROR."""
    return raw_message("POLYDATA", body, device=device, crc=1)


def test_a_large_body_to_a_device_nobody_receives_is_refused_before_decoding(
        processes: Processes) -> None:
    daemon = start_daemon(processes)
    client = RawClient(daemon.port)
    try:
        client.send(_corrupt(_polydata(2_000_000), "nowhere"))
        told = client.read_until(lambda m: m.type_name == "STATUS", timeout=20)
        # Judged by its device: never read far enough to find its CRC wrong.
        assert told.body.code == StatusCode.NOT_FOUND, told.body.text
        assert told.device_name == "nowhere"
    finally:
        client.close()


def test_a_read_only_daemon_refuses_a_large_body_before_decoding(processes: Processes) -> None:
    daemon = start_daemon(processes, "--read-only")
    client = RawClient(daemon.port)
    try:
        client.send(_corrupt(_polydata(2_000_000), "pub:anything"))
        told = client.read_until(lambda m: m.type_name == "STATUS", timeout=20)
        assert told.body.code == StatusCode.ACCESS_DENIED, told.body.text
    finally:
        client.close()


def test_a_large_body_is_decoded_while_the_daemon_answers_others(processes: Processes) -> None:
    """While a client's 40 MB POLYDATA of mixed-size cells is decoded, another client's
    list_bridges is answered and shows it being decoded: the loop is not the one doing
    it."""
    daemon = start_daemon(processes)
    sender, other = RawClient(daemon.port), RawClient(daemon.port)
    try:
        device = ask(sender, "create_publisher", {"topic": "/heavy_mesh",
                                                  "type": "shape_msgs/msg/Mesh"},
                     1)["result"]["device"]
        sender.send(raw_message("POLYDATA", _polydata(40_000_000), device=device)
                    + command_bytes("hello", b"{}", 2))
        seen: list[bool] = []

        def decoding() -> bool:
            clients = ask(other, "list_bridges", {}, 10 + len(seen))["result"]["clients"]
            seen.append(any(c["decoding"] for c in clients))
            return seen[-1]
        wait_until(decoding, timeout=30, what="the other client seeing the body decoded")
        # The mesh has no polygons: refused once decoded (and converted, in its own
        # worker); the hello sent after it is answered once the body was decoded.
        came = [sender.read_until(lambda m: m.type_name in ("STATUS", "RTS_COMMAND"),
                                  timeout=60) for _ in range(2)]
        (told,) = [m for m in came if m.type_name == "STATUS"]
        assert told.body.code == StatusCode.CONFIG_ERROR and "polygons" in told.body.text
        assert [m.body.command_id for m in came if m.type_name == "RTS_COMMAND"] == [2]
    finally:
        sender.close()
        other.close()

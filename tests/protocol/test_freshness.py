"""The client's judge of late stream values (protocol/freshness.py), with two clocks that
share nothing but the messages between them."""

from __future__ import annotations

import pytest

from protocol.freshness import Freshness, daemon_clock_ms

OFFSET = 123_456_789  # the client's clock minus the daemon's: unknown to the judge


def test_ages_are_measured_against_the_fastest_transit_seen() -> None:
    judge = Freshness(0.5)
    judge.reset(daemon_ms=1_000, now_ms=1_000 + OFFSET + 2)  # hello: 2 ms transit
    assert judge.age_ms(1_010, 1_010 + OFFSET + 2) == 0.0
    assert judge.age_ms(1_020, 1_020 + OFFSET + 300) == 298.0
    assert not judge.is_late(1_030, 1_030 + OFFSET + 400)
    assert judge.is_late(1_040, 1_040 + OFFSET + 700)  # sat 0.7 s in a stalled link
    # A faster message than any before lowers the baseline.
    assert judge.age_ms(1_050, 1_050 + OFFSET + 1) == 0.0
    assert judge.age_ms(1_060, 1_060 + OFFSET + 2) == 1.0
    assert judge.age_ms(0, 5) is None  # unstamped: not judged


def test_the_baseline_follows_heartbeats_across_the_32_bit_wrap_and_clock_drift() -> None:
    judge = Freshness(0.5)
    start = (1 << 32) - 5_000
    judge.reset(daemon_ms=start, now_ms=10)
    for k in range(1, 40):  # a heartbeat a second, across the wrap of the daemon's clock
        daemon = (start + k * 1_000) % (1 << 32)
        judge.heartbeat(daemon, 10 + k * 1_000 + k)  # the client's clock runs 1 ms/s fast
    daemon = (start + 40_000) % (1 << 32)
    assert judge.age_ms(daemon, 10 + 40_000 + 40) == pytest.approx(30.0, abs=1)
    assert judge.is_late(daemon, 10 + 40_000 + 40 + 600)


def test_a_judge_needs_a_positive_bound_and_stamps_are_never_zero() -> None:
    with pytest.raises(ValueError, match="positive"):
        Freshness(0)
    assert Freshness(1.0).age_ms(5, 5) is None  # no hello yet
    assert all(daemon_clock_ms() > 0 for _ in range(100))


def test_read_link_reads_the_kernel_s_tcp_info() -> None:
    import struct
    import sys

    from protocol.liveness import TCP_INFO_BYTES, LinkState, read_link

    def info(unacked: int, last_ack_recv_ms: int, retransmits: int = 0) -> bytes:
        u32s = [0] * 13
        u32s[4], u32s[12] = unacked, last_ack_recv_ms
        order = "<" if sys.byteorder == "little" else ">"
        return bytes([1, 0, retransmits]) + bytes(5) + struct.pack(f"{order}13I", *u32s) \
            + bytes(40)

    assert len(info(0, 0)) >= TCP_INFO_BYTES
    # data waits, nothing acknowledged for 6.5 s
    assert read_link(info(3, 6_500)) == LinkState(silent_s=6.5, retransmitting=False)
    assert read_link(info(3, 450, retransmits=2)) == LinkState(0.45, retransmitting=True)
    assert read_link(info(0, 60_000)) is None  # nothing waits: an idle link is keepalive's
    assert read_link(b"\0" * 10) is None


def test_a_plain_remote_client_is_cut_under_the_freshness_bound_others_after_5_s() -> None:
    from protocol.freshness import DEFAULT_FRESHNESS_S
    from protocol.liveness import (PEER_SILENT_AFTER_S, PLAIN_SILENT_AFTER_S, LinkState,
                                   link_is_dead)

    assert PLAIN_SILENT_AFTER_S < DEFAULT_FRESHNESS_S < PEER_SILENT_AFTER_S
    lost = LinkState(silent_s=0.45, retransmitting=True)
    assert link_is_dead(lost, reads_stamps=False, loopback=False)
    # It drops late values itself; a loopback link cannot be pulled; a window probe or a
    # packet still in its first flight is no sign of a dead link.
    assert not link_is_dead(lost, reads_stamps=True, loopback=False)
    assert not link_is_dead(lost, reads_stamps=False, loopback=True)
    assert not link_is_dead(LinkState(0.45, retransmitting=False), reads_stamps=False,
                            loopback=False)
    assert not link_is_dead(LinkState(0.3, retransmitting=True), reads_stamps=False,
                            loopback=False)
    assert not link_is_dead(None, reads_stamps=False, loopback=False)
    for reads_stamps in (True, False):
        for loopback in (True, False):
            assert link_is_dead(LinkState(5.0, retransmitting=False),
                                reads_stamps=reads_stamps, loopback=loopback)

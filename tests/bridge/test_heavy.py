"""HeavyWork, the lanes heavy work runs in off the loop (issue 22): one job of a client at
a time, in order, clients taking turns, a lane resting after each job, and what a client
that left had waiting cancelled. Real threads, gated by events (no sleeps)."""

from __future__ import annotations

import asyncio
import threading
import time
from typing import Callable

import pytest

from bridge.core.heavy import HeavyWork, LaneFullError
from support import scaled


def _gate() -> tuple[threading.Event, Callable[[str], Callable[[], str]], list[str]]:
    """A gate jobs wait behind, and a maker of jobs that note when they run."""
    gate = threading.Event()
    ran: list[str] = []

    def job(name: str) -> Callable[[], str]:
        def work() -> str:
            ran.append(f"start {name}")
            assert gate.wait(scaled(10))
            ran.append(f"end {name}")
            return name
        return work
    return gate, job, ran


def test_one_job_of_a_client_at_a_time_in_order_and_clients_take_turns() -> None:
    async def scenario() -> None:
        heavy = HeavyWork(threads=2, duty=1.0)
        gate, job, ran = _gate()
        a1, a2 = heavy.run("a", job("a1")), heavy.run("a", job("a2"))
        b1 = heavy.run("b", job("b1"))
        while len(ran) < 2:  # two threads: a1 and b1 start, a2 waits for a1
            await asyncio.sleep(0.001)
        assert sorted(ran) == ["start a1", "start b1"]
        gate.set()
        assert await asyncio.gather(a1, a2, b1) == ["a1", "a2", "b1"]
        assert ran.index("end a1") < ran.index("start a2")
        heavy.close()

    asyncio.run(scenario())


def test_a_lane_rests_after_a_job_and_a_full_lane_is_refused() -> None:
    async def scenario() -> None:
        heavy = HeavyWork(threads=1, max_waiting=2, duty=0.5)
        loop = asyncio.get_running_loop()

        def busy() -> float:  # a job that costs CPU time: its rest follows from it
            began = time.thread_time()
            total = 0.0
            for i in range(300_000):
                total += i * 0.5
            return time.thread_time() - began

        spent = await heavy.run("a", busy)
        done = loop.time()
        second = heavy.run("a", lambda: loop.time())  # waits: the lane rests
        third = heavy.run("a", busy)
        with pytest.raises(LaneFullError, match="at most 2 heavy requests"):
            heavy.run("a", busy)
        started = await second
        # It waited for the lane's rest (as long as the job took, at half duty).
        assert started - done >= 0.9 * spent > 0
        await third
        heavy.close()

    asyncio.run(scenario())


def test_a_client_that_leaves_has_its_waiting_jobs_cancelled() -> None:
    async def scenario() -> None:
        heavy = HeavyWork(threads=1, duty=1.0)
        gate, job, ran = _gate()
        running = heavy.run("a", job("a1"))
        waiting = heavy.run("a", job("a2"))
        while not ran:
            await asyncio.sleep(0.001)
        heavy.forget("a")
        gate.set()
        assert await running == "a1"
        with pytest.raises(asyncio.CancelledError):
            await waiting
        assert "start a2" not in ran
        heavy.close()

    asyncio.run(scenario())

"""Heavy work off the event loop, one lane per client.

Decoding a 60 MB POLYDATA, building a ROS message from a megabyte of JSON or encoding a
listing of thousands of bridges takes from tens of milliseconds to seconds. On the loop it
would hold every other client's replies and streams for that long. So such work runs on a
small pool of threads (`HeavyWork`), and each client has a lane: at most one of its jobs
runs at a time, the next waits for it, in order, and clients take turns (a client's next
job joins the pool's queue behind the others' only once its previous one is done). One
client's load then costs others at most one job of its at a time, and a lane rests after
each job (`LANE_DUTY`: a client's lane works at most half the time), so one client cannot
keep a core busy for itself. Python's GIL is handed over every switch interval, so the loop
and the ROS threads keep running meanwhile.

A handler asks for this by returning `OffLoop` (its work, which must not touch what only
the loop may touch), or a `LargeResult` (computed on the loop, its reply encoded in the
lane).
"""

from __future__ import annotations

import asyncio
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any, Callable, Generic, TypeVar

from protocol.commands import LimitReachedError

__all__ = ["HEAVY_THREADS", "MAX_WAITING_PER_LANE", "HeavyWork", "LaneFullError",
           "LargeResult", "OffLoop"]

T = TypeVar("T")
T_co = TypeVar("T_co", covariant=True)

HEAVY_THREADS = 2  # the machine this is built for has two cores
MAX_WAITING_PER_LANE = 16  # a client's jobs queued behind its running one
# A client's lane works at most this share of the time: after a job that took T seconds of
# CPU, its next one starts T * (1 / LANE_DUTY - 1) later (a client's own work waits, not
# anybody else's).
LANE_DUTY = 0.5


class LaneFullError(LimitReachedError):
    """A client has `MAX_WAITING_PER_LANE` jobs waiting already."""

    def __init__(self, limit: int) -> None:
        super().__init__("op", f"at most {limit} heavy requests (large publishes, decodes, "
                         f"listings) waiting per client", "one more")


@dataclass(frozen=True)
class OffLoop(Generic[T_co]):
    """What a handler returns for work to run in its client's lane: ``work()`` in a pool
    thread, its result (or exception) the handler's."""

    work: Callable[[], T_co]


class LargeResult(dict[str, Any]):
    """A handler's result whose reply is encoded in the client's lane (a listing)."""


@dataclass
class _Lane:
    running: bool = False
    waiting: deque[tuple[Callable[[], Any], asyncio.Future[Any]]] = field(
        default_factory=deque)
    rest_until: float = 0.0  # loop time its next job may start (LANE_DUTY)


def _timed(work: Callable[[], T]) -> tuple[T, float]:
    """``work()`` and the CPU time the thread spent on it (pool thread)."""
    began = time.thread_time()
    return work(), time.thread_time() - began


class HeavyWork:
    """The pool and the lanes (loop thread). `run(owner, work)` -> an awaitable of
    ``work()``'s result; `forget(owner)` when it leaves: its waiting jobs are cancelled."""

    def __init__(self, threads: int = HEAVY_THREADS,
                 max_waiting: int = MAX_WAITING_PER_LANE, duty: float = LANE_DUTY) -> None:
        self._pool = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="heavy")
        self._lanes: dict[object, _Lane] = {}
        self._max_waiting = max_waiting
        self._duty = duty

    def run(self, owner: object, work: Callable[[], T]) -> asyncio.Future[T]:
        loop = asyncio.get_running_loop()
        outcome: asyncio.Future[T] = loop.create_future()
        lane = self._lanes.setdefault(owner, _Lane())
        resting = loop.time() < lane.rest_until
        if lane.running or lane.waiting or resting:
            if len(lane.waiting) >= self._max_waiting:
                raise LaneFullError(self._max_waiting)
            lane.waiting.append((work, outcome))
            if resting and not lane.running and len(lane.waiting) == 1:
                loop.call_at(lane.rest_until, self._next, owner)
        else:
            self._start(owner, lane, work, outcome)
        return outcome

    def _start(self, owner: object, lane: _Lane, work: Callable[[], Any],
               outcome: asyncio.Future[Any]) -> None:
        lane.running = True
        done = asyncio.get_running_loop().run_in_executor(self._pool, _timed, work)
        done.add_done_callback(lambda finished: self._finished(owner, finished, outcome))

    def _finished(self, owner: object, finished: asyncio.Future[Any],
                  outcome: asyncio.Future[Any]) -> None:
        spent = 0.0
        if not outcome.done():
            if finished.cancelled():
                outcome.cancel()
            elif finished.exception() is not None:
                outcome.set_exception(finished.exception())  # type: ignore[arg-type]
            else:
                result, spent = finished.result()
                outcome.set_result(result)
        lane = self._lanes.get(owner)
        if lane is None:
            return
        lane.running = False
        loop = asyncio.get_running_loop()
        lane.rest_until = loop.time() + spent * (1.0 / self._duty - 1.0)
        if lane.waiting:
            loop.call_at(lane.rest_until, self._next, owner)

    def _next(self, owner: object) -> None:
        """The lane's rest is over: its next job that still has an awaiter starts."""
        lane = self._lanes.get(owner)
        if lane is None or lane.running:
            return
        while lane.waiting:
            work, queued = lane.waiting.popleft()
            if not queued.done():  # a job whose awaiter went is skipped
                self._start(owner, lane, work, queued)
                return

    def forget(self, owner: object) -> None:
        """``owner`` left: its waiting jobs are cancelled (a running one finishes)."""
        lane = self._lanes.pop(owner, None)
        if lane is None:
            return
        for _, queued in lane.waiting:
            queued.cancel()
        lane.waiting.clear()

    def close(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)

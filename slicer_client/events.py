"""Where a user's callbacks run: never on the socket's receive thread.

The receive thread only decodes messages, updates what the client holds (a subscription's
last message, a lookup's matrix) and queues the callbacks those changes call for. The
queued callbacks run

* in `EventDispatcher.spin`, on the thread that calls it: 3D Slicer's main thread (a Qt
  timer), or a script that calls the reference's ``logic.Spin()``;
* on the dispatcher's own thread when nobody spins (mode ``"auto"``, the default): a
  callback waits at most ``spin_grace`` for a spinner before that thread runs it.

Either way callbacks run one at a time, in the order their events came, and never where a
reply is awaited: a callback may call anything, blocking commands included. A stream's
callbacks are queued by `post_newest`: while one waits to run, a newer value replaces its
own, so a callback that falls behind (a GUI spinning every 20 ms, a 1 kHz topic) runs
once with the newest value, not once for every value it no longer needs. Mode
``"spin"`` leaves every callback to `spin` (a GUI that must run them on its own thread).

A spin also runs the tick hooks (`add_tick`): the reference's tf lookups notify their
observers on every spin, as its logic looks every lookup up on each tick.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from typing import Any, Callable, Deque, Dict, Hashable, List, Optional, Tuple

__all__ = ["DISPATCH_MODES", "EventDispatcher"]

log = logging.getLogger("slicer_client")

DISPATCH_MODES = ("auto", "spin")
# Callbacks waiting to run; past this the oldest are dropped (and counted): a callback that
# never returns must not make the client hold every message forever.
MAX_QUEUED = 10_000

class _Event:
    """A queued callback; `post_newest` may replace its callback and args while queued."""

    __slots__ = ("callback", "args", "queued_at", "key")

    def __init__(self, callback: Callable[..., Any], args: Tuple[Any, ...],
                 key: Optional[Hashable] = None) -> None:
        self.callback = callback
        self.args = args
        self.queued_at = time.monotonic()
        self.key = key


class EventDispatcher:
    def __init__(self, mode: str = "auto", *, spin_grace: float = 0.2,
                 max_queued: int = MAX_QUEUED) -> None:
        if mode not in DISPATCH_MODES:
            raise ValueError(f"callbacks: expected one of {', '.join(DISPATCH_MODES)}, got "
                             f"{mode!r}")
        self.mode = mode
        self._grace = spin_grace
        self._queue: Deque[_Event] = deque()
        self._newest: Dict[Hashable, _Event] = {}  # `post_newest`'s events still queued
        self._max = max_queued
        self._lock = threading.Lock()
        self._wake = threading.Condition(self._lock)
        # One deliverer at a time, so callbacks never overlap (re-entrant: see `spin`).
        self._delivering = threading.RLock()
        self._delivery_thread: Optional[int] = None
        self._spinner: Optional[int] = None  # the thread inside spin(), if any
        self._last_spin = float("-inf")
        self._ticks: List[Callable[[], None]] = []
        self._closed = False
        self.dropped = 0
        self.replaced = 0  # values a newer one replaced before their callback ran
        self.ran = 0
        self._thread: Optional[threading.Thread] = None
        if mode == "auto":
            self._thread = threading.Thread(target=self._run, name="slicer-client-callbacks",
                                            daemon=True)
            self._thread.start()

    # --- from any thread ------------------------------------------------------------------
    def post(self, callback: Callable[..., Any], *args: Any) -> None:
        """Queue `callback(*args)` (the receive thread calls this; it never runs it)."""
        with self._wake:
            if not self._closed:
                self._append(_Event(callback, args))

    def post_newest(self, key: Hashable, callback: Callable[..., Any], *args: Any) -> None:
        """`post`, but if the event queued under `key` has not run yet, it runs with
        these arguments instead, in its place: a stream's newest value."""
        with self._wake:
            if self._closed:
                return
            queued = self._newest.get(key)
            if queued is not None:
                queued.callback, queued.args = callback, args
                self.replaced += 1
                return
            event = _Event(callback, args, key)
            self._newest[key] = event
            self._append(event)

    def _append(self, event: _Event) -> None:
        # Under the lock.
        if len(self._queue) >= self._max:
            dropped = self._queue.popleft()
            if dropped.key is not None:
                del self._newest[dropped.key]
            self.dropped += 1
            if self.dropped == 1 or self.dropped % 1000 == 0:
                log.warning("%d callbacks dropped: nothing ran them for a while (a "
                            "callback that does not return, or nobody spinning in "
                            "'spin' mode)", self.dropped)
        self._queue.append(event)
        self._wake.notify()

    def add_tick(self, hook: Callable[[], None]) -> None:
        """`hook()` runs on every `spin` (after the queued callbacks)."""
        self._ticks.append(hook)

    def remove_tick(self, hook: Callable[[], None]) -> None:
        if hook in self._ticks:
            self._ticks.remove(hook)

    @property
    def pending(self) -> int:
        return len(self._queue)

    # --- the spinner's thread ---------------------------------------------------------------
    def spin(self, timeout: float = 0.0, max_events: Optional[int] = None) -> int:
        """Run, on this thread, every callback queued so far (waiting up to `timeout` s for
        the first), then the tick hooks; returns how many callbacks ran. Called from inside
        a callback it returns 0 at once: a callback never runs inside another."""
        if self._delivery_thread == threading.get_ident():
            return 0
        self._spinner = threading.get_ident()
        try:
            return self._spin(timeout, max_events)
        finally:
            self._spinner = None

    def spinning_here(self) -> bool:
        """Is the calling thread inside `spin` (its callbacks or tick hooks)?"""
        return self._spinner == threading.get_ident()

    def _spin(self, timeout: float, max_events: Optional[int]) -> int:
        with self._wake:
            self._last_spin = time.monotonic()
            if timeout > 0 and not self._queue:
                self._wake.wait(timeout)
            queued = len(self._queue)  # what came during this spin waits for the next
        ran = self._deliver(queued if max_events is None else min(queued, max_events))
        for hook in list(self._ticks):
            self._call(hook, ())
        with self._lock:
            self._last_spin = time.monotonic()
        return ran

    def _deliver(self, max_events: Optional[int]) -> int:
        ran = 0
        with self._delivering:
            self._delivery_thread = threading.get_ident()
            try:
                while max_events is None or ran < max_events:
                    with self._lock:
                        if not self._queue:
                            break
                        event = self._queue.popleft()
                        if event.key is not None:
                            del self._newest[event.key]
                    self._call(event.callback, event.args)
                    ran += 1
            finally:
                self._delivery_thread = None
        return ran

    def _call(self, callback: Callable[..., Any], args: Tuple[Any, ...]) -> None:
        try:
            callback(*args)
        except Exception:  # noqa: BLE001 - a user's callback must not stop the others
            log.exception("callback %r raised", callback)
        self.ran += 1

    # --- the dispatcher thread (mode "auto") ----------------------------------------------
    def _run(self) -> None:
        while True:
            with self._wake:
                while not self._closed and not self._ready():
                    self._wake.wait(self._wait_time())
                if self._closed:
                    return
            self._deliver(None)

    def _ready(self) -> bool:
        """Is there a callback for this thread: one nobody spun for within the grace?"""
        if not self._queue:
            return False
        now = time.monotonic()
        oldest = self._queue[0].queued_at
        return now - self._last_spin > self._grace or now - oldest > self._grace

    def _wait_time(self) -> Optional[float]:
        if not self._queue:
            return None
        return max(0.001, self._queue[0].queued_at + self._grace - time.monotonic())

    def close(self) -> None:
        with self._wake:
            self._closed = True
            self._queue.clear()
            self._newest.clear()
            self._wake.notify_all()
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=2.0)

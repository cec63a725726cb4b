"""A recording the daemon writes on its machine: ``ros.record(path)`` -> `Recording`.

    rec = ros.record("/data/session.mcap")       # what the daemon bridges
    ...
    print(rec.elapsed, rec.messages, rec.dropped)
    final = rec.stop()                            # the bag is finished and closed

The counts come from the daemon (``recording_status``, one round trip each); after `stop`
they are the final ones, kept.
"""

from __future__ import annotations

import time
from typing import Any, Callable, Dict, Optional, Sequence

from protocol import commands as c

__all__ = ["Recording"]

Request = Callable[..., Dict[str, Any]]


class Recording:
    """One bag being recorded by the daemon (see the module)."""

    def __init__(self, request: Request, path: str, started: Dict[str, Any]) -> None:
        self._request = request
        self.path = path
        self._started = time.monotonic() - float(started.get("elapsed_s", 0.0))
        self._final: Optional[Dict[str, Any]] = None
        self.topics_at_start = [t["topic"] for t in started.get("topics", [])]

    @classmethod
    def start(cls, request: Request, path: str, topics: Optional[Sequence[str]] = None, *,
              overwrite: bool = False, compression: str = "none",
              timeout: float = 10.0) -> Recording:
        reply = request(c.StartRecording(path=path, topics=tuple(topics or ()),
                                         overwrite=overwrite, compression=compression),
                        timeout=timeout)
        return cls(request, str(reply.get("path", path)), reply)

    def status(self, timeout: float = 10.0) -> Dict[str, Any]:
        """The daemon's counts: ``messages``, ``dropped``, ``bytes``, ``elapsed_s``,
        ``topics`` (each with its own counts), ``pending`` (wanted, not recorded yet, and
        why), ``error`` if it stopped on its own (a full disk)."""
        if self._final is not None:
            return self._final
        return self._request(c.RecordingStatus(path=self.path), timeout=timeout)

    def stop(self, timeout: float = 30.0) -> Dict[str, Any]:
        """Finish the bag; returns its final status (the same on a second call)."""
        if self._final is None:
            self._final = self._request(c.StopRecording(path=self.path), timeout=timeout)
        return self._final

    @property
    def running(self) -> bool:
        return self._final is None

    @property
    def elapsed(self) -> float:
        """Seconds since it started (final once stopped); no round trip."""
        if self._final is not None:
            return float(self._final["elapsed_s"])
        return time.monotonic() - self._started

    @property
    def messages(self) -> int:
        """Messages recorded so far, all topics together (a round trip until stopped)."""
        return int(self.status()["messages"])

    @property
    def dropped(self) -> int:
        """Messages the daemon could not keep (its queue was full), counted, never silent."""
        return int(self.status()["dropped"])

    @property
    def counts(self) -> Dict[str, int]:
        """Messages recorded per topic (a round trip until stopped)."""
        return {t["topic"]: int(t["messages"]) for t in self.status()["topics"]}

    def __enter__(self) -> Recording:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def __repr__(self) -> str:
        state = "running" if self.running else "stopped"
        return f"Recording({self.path!r}, {state}, {self.elapsed:.1f} s)"

"""Every background thread of the daemon is started by bridge/core/threads.py (issue 43):
a failing one is said in one line and runs again, or stops the daemon, as it declares."""

from __future__ import annotations

import errno
import logging
import threading
from pathlib import Path

import pytest

from bridge.core import threads
from bridge.core.threads import OnFailure, fatal_failure, start_thread

BRIDGE = Path(threads.__file__).resolve().parents[1]


@pytest.fixture(autouse=True)
def quick(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(threads, "RESTART_PAUSE_S", 0.01)
    monkeypatch.setattr(threads, "_fatal", [])  # this test's own record
    monkeypatch.setattr(threads, "_failures", threads.RateLimitedLog(threads.log))


def out_of_descriptors() -> None:
    raise OSError(errno.EMFILE, "Too many open files")


FAILS_AT = out_of_descriptors.__code__.co_firstlineno + 1


def test_a_restarting_thread_says_its_failure_once_and_runs_again(
        caplog: pytest.LogCaptureFixture) -> None:
    runs: list[int] = []

    def run() -> None:
        runs.append(1)
        if len(runs) <= 3:
            out_of_descriptors()

    stopped: list[bool] = []
    with caplog.at_level(logging.WARNING, logger="bridge.core.threads"):
        start_thread("watch", run, OnFailure.RESTART,
                     stop_process=lambda: stopped.append(True)).join(10)
    assert len(runs) == 4 and not stopped and fatal_failure() is None
    # Three failures within the interval: one line, no traceback, naming where it failed.
    (record,) = caplog.records
    assert record.levelname == "WARNING" and record.exc_info is None
    assert record.getMessage() == (
        "thread watch failed (OSError: [Errno 24] Too many open files at "
        f"tests/bridge/test_threads.py:{FAILS_AT} in out_of_descriptors); it runs again "
        "in 0.01 s")


def test_a_thread_the_daemon_needs_stops_it_loudly(caplog: pytest.LogCaptureFixture) -> None:
    stopped = threading.Event()

    def run() -> None:
        raise RuntimeError("the wait set failed")

    with caplog.at_level(logging.WARNING, logger="bridge.core.threads"):
        start_thread("reader", run, OnFailure.STOP, stop_process=stopped.set).join(10)
    assert stopped.is_set()
    why = fatal_failure()
    assert why is not None and why.startswith("thread reader failed (RuntimeError: the wait "
                                              "set failed at tests/bridge/"
                                              "test_threads.py:")
    (record,) = caplog.records
    assert record.levelname == "CRITICAL" and "stopping" in record.getMessage()


def test_a_restarting_thread_that_never_recovers_stops_the_daemon(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(threads, "GIVE_UP_AFTER", 3)
    stopped = threading.Event()
    runs: list[int] = []

    def run() -> None:
        runs.append(1)
        out_of_descriptors()

    start_thread("watch", run, OnFailure.RESTART, stop_process=stopped.set).join(10)
    assert stopped.is_set() and len(runs) == 3
    assert "3 times in a row" in (fatal_failure() or "")


def test_every_daemon_thread_is_started_by_the_helper() -> None:
    """No thread of bridge/ is started any other way (one owner of the rule)."""
    starts = [f"{path.relative_to(BRIDGE.parent)}:{n}"
              for path in BRIDGE.rglob("*.py") if path.name != "threads.py"
              for n, line in enumerate(path.read_text().splitlines(), 1)
              if "threading.Thread(" in line]
    assert starts == []

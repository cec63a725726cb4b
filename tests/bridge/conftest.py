"""Fixtures for daemon tests: one real daemon process per test module, real TCP clients."""

from __future__ import annotations

from typing import Iterator

import pytest

import slicer_client
from slicer_client.client import Client
from slicer_client.connection import Connection
from support import Processes, RunningDaemon, assert_clean_exit, start_daemon


@pytest.fixture(scope="module")
def daemon(module_processes: Processes) -> Iterator[RunningDaemon]:
    running = start_daemon(module_processes)
    yield running
    assert_clean_exit(running)


@pytest.fixture
def client(daemon: RunningDaemon) -> Iterator[Connection]:
    connection = daemon.connect()
    yield connection
    connection.close()


@pytest.fixture
def ros(daemon: RunningDaemon) -> Iterator[Client]:
    """The Pythonic client on the module's daemon (no reconnect: a test ends with it)."""
    client = slicer_client.connect("127.0.0.1", daemon.port, reconnect=False)
    yield client
    client.close()


@pytest.fixture(params=["compiled", "pure Python"])
def tf_store(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    """Runs a tf test once on each store `TfBuffer` can use (`TfBuffer()` then takes it):
    the compiled one (skipped where it was not built) and the pure Python fallback."""
    from bridge.tf import buffer

    if request.param == "compiled" and buffer.CompiledFrameStore is None:
        pytest.skip("the compiled tf store was not built (no C compiler or Cython at install)")
    monkeypatch.setattr(buffer, "COMPILED", request.param == "compiled")
    return str(request.param)

"""Fixtures for daemon tests: one real daemon process per test module, real TCP clients."""

from __future__ import annotations

from typing import Iterator

import pytest

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

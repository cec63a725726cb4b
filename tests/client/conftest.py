"""Fixtures for client tests: a real daemon process per module, `slicer_client.connect`."""

from __future__ import annotations

from typing import Any, Iterator

import pytest

import slicer_client
from support import Processes, RunningDaemon, assert_clean_exit, start_daemon


@pytest.fixture(scope="module")
def daemon(module_processes: Processes) -> Iterator[RunningDaemon]:
    running = start_daemon(module_processes)
    yield running
    assert_clean_exit(running)


@pytest.fixture
def ros(daemon: RunningDaemon) -> Iterator[slicer_client.Client]:
    """A Pythonic client; its facade is `ros.GetDefaultROS2Node()`."""
    client = slicer_client.connect("127.0.0.1", daemon.port)
    yield client
    client.close()


@pytest.fixture
def rosLogic(ros: slicer_client.Client) -> Any:  # noqa: N802 - the reference's name
    """The reference's logic over a Pythonic client (`ros.logic`)."""
    return ros.logic

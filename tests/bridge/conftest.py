"""Fixtures for daemon tests: one real daemon process per test module, real TCP clients."""

from __future__ import annotations

from typing import TYPE_CHECKING, Iterator

import pytest

import slicer_client
from slicer_client.client import Client
from slicer_client.connection import Connection
from play_support import NO_ROS_SITECUSTOMIZE
from support import Processes, RunningDaemon, assert_clean_exit, start_daemon

if TYPE_CHECKING:  # rosbags (the test extra): imported by the player's tests only
    from bags import RobotBag


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


# --- the player's tests (test_play*.py): no ROS, the demo robot's bag by rosbags ---------

@pytest.fixture(scope="module")
def no_ros(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """The environment of a process where `import rclpy` (and every ROS import) fails."""
    folder = tmp_path_factory.mktemp("no-ros")
    (folder / "sitecustomize.py").write_text(NO_ROS_SITECUSTOMIZE)
    return {"PYTHONPATH": str(folder)}


@pytest.fixture(scope="module")
def demo() -> tuple[str, str]:
    """The demo robot's URDF text and its package folder (meshes by --package-path)."""
    from bridge.robots.demo import demo_urdf_path
    from bridge.robots.demo.urdf import DEMO_PACKAGE

    urdf, packages = demo_urdf_path()
    return urdf.read_text(), f"{DEMO_PACKAGE}={packages[DEMO_PACKAGE]}"


@pytest.fixture(scope="module")
def robot_bag(tmp_path_factory: pytest.TempPathFactory, demo: tuple[str, str]) -> "RobotBag":
    from bags import write_robot_bag

    return write_robot_bag(tmp_path_factory.mktemp("bags") / "robot", demo[0])

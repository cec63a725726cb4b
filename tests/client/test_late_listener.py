"""Nothing a client receives is lost before its listener is attached.

The daemon sends its whole state (a robot's meshes, once per connection) as soon as a
client announces header v2, which `Connection` does at once. A `Client` attached to its
transport only later, as a busy program or 3D Slicer's main thread may do, must still get
every mesh.
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterator

import pytest

from bridge.robots.demo import DEMO_PACKAGE, demo_urdf_path
from protocol.messages import Message, PolyData
from slicer_client.client import Client
from slicer_client.transport import open_transport
from support import Processes, RunningDaemon, assert_clean_exit, start_daemon, wait_until

pytestmark = pytest.mark.ros

RUNS = 20
DEMO_VISUALS = 14


@pytest.fixture(scope="module")
def demo_daemon(module_processes: Processes, tmp_path_factory: pytest.TempPathFactory) \
        -> Iterator[tuple[RunningDaemon, Path]]:
    folder = tmp_path_factory.mktemp("late")
    urdf, packages = demo_urdf_path(folder / "demo")
    config = folder / "bridge.yaml"
    config.write_text(f"robots:\n  - {{name: arm, source: {{kind: file, path: '{urdf}'}}}}\n")
    running = start_daemon(module_processes, "--config", str(config), "--package-path",
                           f"{DEMO_PACKAGE}={packages[DEMO_PACKAGE]}")
    yield running, urdf
    assert_clean_exit(running)


def _meshes_arrived(transport: object) -> int:
    connection = transport.connection  # type: ignore[attr-defined]
    return sum(1 for device in connection.devices()
               if isinstance(connection.latest(device).body, PolyData))


def test_a_listener_attached_after_the_state_arrived_gets_every_mesh(
        demo_daemon: tuple[RunningDaemon, Path]) -> None:
    daemon, urdf = demo_daemon
    for run in range(RUNS):
        transport = open_transport("127.0.0.1", daemon.port, reconnect=False)
        try:
            # The whole state is in before anyone listens: the case that lost meshes.
            wait_until(lambda t=transport: _meshes_arrived(t) == DEMO_VISUALS, timeout=60,
                       what=f"the {DEMO_VISUALS} meshes at the connection (run {run})")
            client = Client(transport)
            robot = client.robot("arm", source={"kind": "file", "path": str(urdf)})
            # No tf runs here, so only the meshes and the root link's pose come: every mesh
            # must be there at once, from what arrived before the listener.
            assert robot.mesh_count() == DEMO_VISUALS, f"run {run}: {robot.mesh_count()}"
            assert len(robot.links) == 11
        finally:
            transport.close()


def test_the_late_listener_gets_every_device_that_came_before_it(
        demo_daemon: tuple[RunningDaemon, Path]) -> None:
    daemon, _ = demo_daemon
    transport = open_transport("127.0.0.1", daemon.port, reconnect=False)
    try:
        wait_until(lambda: _meshes_arrived(transport) == DEMO_VISUALS, timeout=60,
                   what="the meshes at the connection")
        before = set(transport.connection.devices())
        seen: list[str] = []

        class Recorder:
            def on_message(self, message: Message) -> None:
                seen.append(message.device_name)

            def on_connected(self, command: object, first: bool) -> None:
                pass

            def on_disconnected(self, reason: str) -> None:
                pass

        transport.set_listener(Recorder())
        assert before <= set(seen)
        assert sum(1 for name in set(seen) if name.startswith("arm:") and
                   name.count(":") == 2) == DEMO_VISUALS
    finally:
        transport.close()

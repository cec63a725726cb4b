"""A client that announces header v2 late (a busy 3D Slicer main thread) still gets every
mesh and static transform with its metadata: the state is sent again once it announces."""

from __future__ import annotations

from pathlib import Path

import pytest

from bridge.robots.demo import DEMO_PACKAGE, demo_urdf_path
from hardening_tools import RawClient
from protocol.framing import encode
from protocol.messages import Message, PolyData, Status
from support import Processes, assert_clean_exit, start_daemon

pytestmark = pytest.mark.ros

DEMO_VISUALS = 14


def test_a_late_v2_announcement_gets_the_meshes_again_with_metadata(
        processes: Processes, tmp_path: Path) -> None:
    urdf, packages = demo_urdf_path(tmp_path / "demo")
    config = tmp_path / "bridge.yaml"
    config.write_text(f"robots:\n  - {{name: arm, source: {{kind: file, path: '{urdf}'}}}}\n")
    daemon = start_daemon(processes, "--config", str(config), "--package-path",
                          f"{DEMO_PACKAGE}={packages[DEMO_PACKAGE]}")
    client = RawClient(daemon.port)
    try:
        # Silent past the grace time: the meshes come as header v1, without metadata.
        first: dict[str, Message] = {}
        while len(first) < DEMO_VISUALS:
            mesh = client.read_until(lambda m: isinstance(m.body, PolyData), timeout=30)
            first[mesh.device_name] = mesh
        assert all(m.header_version == 1 and not m.metadata for m in first.values())
        # The announcement, as 3D Slicer makes it (a STATUS with metadata, header v2).
        client.send(encode(Message(device_name="", body=Status(), metadata={"dummy": "dummy"}),
                           header_version=2))
        again: dict[str, Message] = {}
        while len(again) < DEMO_VISUALS:
            mesh = client.read_until(lambda m: isinstance(m.body, PolyData), timeout=30)
            again[mesh.device_name] = mesh
        assert set(again) == set(first)
        for device, mesh in again.items():
            assert mesh.header_version == 2
            assert mesh.metadata["ros2.robot"] == "arm", device
            assert mesh.metadata["ros2.parent_device"].startswith("arm:"), device
    finally:
        client.close()
    assert_clean_exit(daemon)

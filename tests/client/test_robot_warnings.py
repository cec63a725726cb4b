"""A robot that loads with problems says so to the user: in the reply, through the client's
logging and callbacks, and in the module's robot lines (not only in the daemon's log)."""

from __future__ import annotations

import json
import logging
import threading
from pathlib import Path

import pytest

import slicer_client
from slicer_client.scene_plan import robot_status_lines
from support import Processes, assert_clean_exit, start_daemon

pytestmark = pytest.mark.ros

URDF = """<robot name="warned">
  <link name="base"><visual><geometry><box size="0.1 0.1 0.1"/></geometry></visual></link>
  <link name="arm"><visual><geometry><mesh filename="meshes/missing.stl"/></geometry></visual>
  </link>
  <joint name="j" type="fixed"><parent link="base"/><child link="arm"/></joint>
</robot>"""


def test_a_missing_mesh_reaches_the_user(processes: Processes, tmp_path: Path,
                                         caplog: pytest.LogCaptureFixture) -> None:
    urdf = tmp_path / "warned.urdf"
    urdf.write_text(URDF)
    daemon = start_daemon(processes, "--robot-dir", str(tmp_path))
    seen: list[tuple[str, str, object]] = []
    warned = threading.Event()

    def on_change(kind: str, link: str, value: object) -> None:
        seen.append((kind, link, value))
        if kind == "warning":
            warned.set()

    with caplog.at_level(logging.WARNING, logger="slicer_client"), \
            slicer_client.connect("127.0.0.1", daemon.port) as ros:
        robot = ros.robot("warned", source={"kind": "file", "path": str(urdf)},
                          callback=on_change)
        assert robot.info["warnings"] == robot.warnings
        (warning,) = robot.warnings
        assert "meshes/missing.stl" in warning and "arm" in warning
        # Callbacks run on the client's callback thread, not in the call that loaded.
        assert warned.wait(30), "no warning callback within 30 s"
        assert [entry for entry in seen if entry[0] == "warning"] == [("warning", "", warning)]
        assert [r.getMessage() for r in caplog.records
                if r.name == "slicer_client"] == [f"robot warned: {warning}"]
        robot._wait(lambda: robot.mesh_count() == 1, 30, "the box's mesh")
        assert robot_status_lines([robot]) == ["warned: 1 of 1 meshes received",
                                               f"  warning: {warning}"]
        # A client that only listens (the module, a robot loaded later) reads them from the
        # robot's description device.
        with daemon.connect() as listener:
            status = listener.wait_for("urdf:warned", timeout=30)
            assert json.loads(status.metadata["ros2.warnings"]) == [warning]
    assert_clean_exit(daemon)


def test_a_robot_that_cannot_load_says_why_in_the_exception(
        ros: slicer_client.Client) -> None:
    """Issue 25, item 8: the daemon's reason is in the exception, not only in `info`."""
    robot = ros.robot("absent", namespace="nowhere_ns")
    reason = ("parameter robot_description of /nowhere_ns/robot_state_publisher: node not "
              "available yet")
    assert (robot.state, robot.reason) == ("waiting", reason)
    with pytest.raises(slicer_client.RobotNotLoadedError) as error:
        robot.wait_until_loaded(timeout=1.0)
    assert str(error.value) == (f"robot 'absent' not loaded within 1.0 s (0 meshes "
                                f"received); the daemon says waiting: {reason}")
    assert isinstance(error.value, TimeoutError)
    assert (error.value.state, error.value.reason) == ("waiting", reason)
    robot.remove()

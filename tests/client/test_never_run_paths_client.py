"""Client paths no other test runs: `Robot.wait_until_loaded` returning once a robot has
arrived (from a file, and from a node that appears after the robot was asked for), and
`Service.call_async` (its answer, its error, where its callback runs). Real daemon, real
rclpy peers in other processes, real TCP.
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any, Iterator, Optional

import numpy as np
import pytest

import slicer_client
from protocol.commands import ErrorCode
from protocol.messages import PolyData
from support import Child, Processes, RunningDaemon, assert_clean_exit, scaled, start_daemon

pytestmark = pytest.mark.ros

# Three links, fixed joints only (their transforms need no joint states): a box on the
# root, a sphere 0.3 m up, a link without visual 0.1 m along x from it.
URDF = """<?xml version="1.0"?>
<robot name="waiter">
  <link name="root"><visual><geometry><box size="0.1 0.1 0.1"/></geometry></visual></link>
  <link name="ball"><visual><geometry><sphere radius="0.02"/></geometry></visual></link>
  <link name="frame_only"/>
  <joint name="a" type="fixed"><parent link="root"/><child link="ball"/>
    <origin xyz="0 0 0.3"/></joint>
  <joint name="b" type="fixed"><parent link="ball"/><child link="frame_only"/>
    <origin xyz="0.1 0 0"/></joint>
</robot>
"""
EXPECTED_MM = {"root": (0, 0, 0), "ball": (0, 0, 300), "frame_only": (100, 0, 300)}


@pytest.fixture(scope="module")
def robot_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("robots")
    (folder / "waiter.urdf").write_text(URDF)
    return folder


@pytest.fixture(scope="module")
def daemon(module_processes: Processes, robot_dir: Path) -> Iterator[RunningDaemon]:
    running = start_daemon(module_processes, "--robot-dir", str(robot_dir))
    yield running
    assert_clean_exit(running)


@pytest.fixture
def ros(daemon: RunningDaemon) -> Iterator[slicer_client.Client]:
    client = slicer_client.connect("127.0.0.1", daemon.port, reconnect=False)
    yield client
    client.close()


def check_poses(robot: Any) -> None:
    assert sorted(robot.transforms) == sorted(EXPECTED_MM)
    for link, xyz in EXPECTED_MM.items():
        expected = np.eye(4)
        expected[:3, 3] = xyz
        np.testing.assert_allclose(robot.transforms[link], expected, atol=1e-6, err_msg=link)


# ---------------------------------------------------------------------------- robots


def test_wait_until_loaded_returns_once_every_link_and_mesh_arrived(
        ros: slicer_client.Client, processes: Processes, robot_dir: Path) -> None:
    """A robot from a file: its meshes come at once, its link transforms from tf. Until a
    state publisher gives those, wait_until_loaded times out; then it returns."""
    robot = ros.robot("waiter", source={"kind": "file", "path": str(robot_dir / "waiter.urdf")},
                      tf_prefix="waiter/")
    try:
        assert robot.state == "loaded"
        robot._wait(lambda: robot.mesh_count() == 2, scaled(30), "the two meshes")
        with pytest.raises(slicer_client.RobotNotLoadedError) as error:
            robot.wait_until_loaded(timeout=0.5)
        assert "(2 of 2 meshes received)" in str(error.value)
        assert sorted(robot.transforms) == ["root"]  # the fixed frame: no tf needed
        processes.bridge("state-publisher", str(robot_dir / "waiter.urdf"), "--namespace",
                         "waiter_ns", "--frame-prefix", "waiter/").wait_for_output("ready",
                                                                                  timeout=30)
        robot.wait_until_loaded(timeout=scaled(30))
        # Everything the create reply named is there: 3 transforms, 2 meshes.
        check_poses(robot)
        assert robot.mesh_count() == 2 and robot.progress() == (2, 2)
        box, ball = robot.links["root"].meshes[0], robot.links["ball"].meshes[0]
        assert isinstance(box, PolyData) and isinstance(ball, PolyData)
        np.testing.assert_allclose(np.ptp(box.points, axis=0), (100, 100, 100), atol=1e-3)
        np.testing.assert_allclose(np.linalg.norm(ball.points, axis=1), 20, atol=1e-3)
        assert robot.links["frame_only"].meshes == {}
        # Waiting again returns at once: nothing more is expected.
        robot.wait_until_loaded(timeout=0.0)
    finally:
        robot.remove()


def test_wait_until_loaded_on_a_robot_whose_node_appears_later(
        ros: slicer_client.Client, processes: Processes, robot_dir: Path) -> None:
    """Asked for before its robot_state_publisher exists, the robot is "waiting" with no
    link known; wait_until_loaded returns once the node appeared and the daemon's "loaded"
    STATUS (its link and visual counts) and every link and mesh have arrived."""
    robot = ros.robot("later", namespace="later_ns", tf_prefix="later_ns/", wait=True)
    try:
        assert (robot.state, robot.progress()) == ("waiting", (0, None))
        publisher = processes.bridge("state-publisher", str(robot_dir / "waiter.urdf"),
                                     "--namespace", "later_ns", "--frame-prefix", "later_ns/")
        publisher.wait_for_output("ready", timeout=30)
        robot.wait_until_loaded(timeout=scaled(40))
        assert (robot.state, robot.reason) == ("loaded", "")
        check_poses(robot)
        assert robot.mesh_count() == 2 and robot.progress() == (2, 2)
    finally:
        robot.remove()


# ---------------------------------------------------------------------------- services


@pytest.fixture(scope="module")
def services(module_processes: Processes) -> Child:
    server = module_processes.python("services", "service_server.py", "--namespace",
                                     "/async_srv")
    server.wait_for_output("READY", timeout=30)
    return server


def test_call_async_hands_the_response_to_the_callback_thread(
        ros: slicer_client.Client, daemon: RunningDaemon, services: Child) -> None:
    done = threading.Event()
    got: list[tuple[Optional[dict[str, Any]], Optional[Exception], str]] = []

    def on_answer(response: Optional[dict[str, Any]], error: Optional[Exception]) -> None:
        got.append((response, error, threading.current_thread().name))
        done.set()

    service = ros.service("/async_srv/set_enabled", "std_srvs/srv/SetBool")
    worker = service.call_async({"data": True}, on_answer, timeout=scaled(10))
    assert worker.name == "service /async_srv/set_enabled"
    # Seen once (fresh-clone run ci62): no answer in 30 s. Whether the server got the request, and
    # whether rclpy could send its response ("failed to send response"), is in its output.
    assert done.wait(scaled(30)), (f"no answer; the server printed:\n{services.output()[-2000:]}"
                                   f"\nthe daemon:\n{daemon.child.output()[-3000:]}")
    worker.join(scaled(10))
    assert not worker.is_alive()
    ((response, error, thread),) = got
    assert error is None
    assert response == {"success": True, "message": "/async_srv enabled=True"}
    # Not the worker that made the call: the client's callback thread (mode "auto").
    assert thread == "slicer-client-callbacks"


def test_call_async_hands_a_refusal_to_the_callback(ros: slicer_client.Client) -> None:
    done = threading.Event()
    got: list[tuple[Optional[dict[str, Any]], Optional[Exception]]] = []

    def on_answer(response: Optional[dict[str, Any]], error: Optional[Exception]) -> None:
        got.append((response, error))
        done.set()

    ros.service("/async_srv/nobody_here", "std_srvs/srv/Trigger").call_async(
        None, on_answer, timeout=0.5)
    assert done.wait(scaled(30))
    ((response, error),) = got
    assert response is None
    assert isinstance(error, slicer_client.CommandRefusedError)
    assert error.code in (ErrorCode.UNAVAILABLE, ErrorCode.TIMEOUT)
    assert "/async_srv/nobody_here" in str(error)


def test_call_async_callbacks_wait_for_the_spinning_thread(daemon: RunningDaemon,
                                                           services: Child) -> None:
    """With callbacks="spin" (3D Slicer's main thread), the answer is queued until the
    application spins, and the callback runs on the spinning thread."""
    with slicer_client.connect("127.0.0.1", daemon.port, reconnect=False,
                               callbacks="spin") as ros:
        got: list[tuple[Optional[dict[str, Any]], Optional[Exception], int]] = []

        def on_answer(response: Optional[dict[str, Any]], error: Optional[Exception]) -> None:
            got.append((response, error, threading.get_ident()))

        worker = ros.service("/async_srv/trigger", "std_srvs/srv/Trigger").call_async(
            {}, on_answer, timeout=scaled(10))
        worker.join(scaled(30))
        assert not worker.is_alive() and got == []  # answered, not yet delivered
        assert ros.process_events(timeout=scaled(10)) >= 1
        ((response, error, thread),) = got
        assert error is None and thread == threading.get_ident()
        assert response is not None and response["success"] is True
        assert response["message"].startswith("triggered ")

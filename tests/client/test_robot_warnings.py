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
from support import Processes, assert_clean_exit, scaled, start_daemon

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
        # robot's description device: a kept robot goes to every client.
        robot.keep()
        with daemon.connect() as listener:
            status = listener.wait_for("urdf:warned", timeout=30)
            assert json.loads(status.metadata["ros2.warnings"]) == [warning]
    # Issue 43, item 12: the daemon's log said each warning twice (as the loader met it,
    # then all of them in the "loaded" line): once now, the "loaded" line counts them.
    log = daemon.child.output()
    assert len([line for line in log.splitlines() if "meshes/missing.stl" in line]) == 1, log
    assert "robot warned loaded 'warned': 2 links, 1 visuals, fixed frame base; 1 " \
        "warning(s) (above)" in log
    assert_clean_exit(daemon)


def test_a_robot_that_cannot_load_says_why_in_the_exception(
        ros: slicer_client.Client) -> None:
    """Issue 25, item 8: the daemon's reason is in the exception, not only in `info`."""
    robot = ros.robot("absent", namespace="nowhere_ns", wait=True)
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


def test_a_robot_whose_node_does_not_exist_is_refused_by_both_routes(
        ros: slicer_client.Client) -> None:
    """Issue 43, item 9: a robot whose parameter node does not exist loaded "successfully"
    with 0 links, through `ros.robot()` and `CreateAndAddRobotNode`. Both now raise a
    NOT_FOUND refusal naming the node and the parameter, and leave no robot behind."""
    expected = (
        "the daemon refused create_robot (field 'source.node'): NOT_FOUND: source.node: "
        "expected a node on the ROS graph holding parameter robot_description (or "
        "\"wait\": true to wait for it), got /ghost_ns/robot_state_publisher: no such node "
        "(its parameter services not found in 10 s)")
    with pytest.raises(slicer_client.CommandRefusedError) as refused:
        ros.robot("ghost", namespace="ghost_ns")
    assert (refused.value.code.name, str(refused.value)) == ("NOT_FOUND", expected)
    with pytest.raises(slicer_client.CommandRefusedError) as refused:
        ros.GetDefaultROS2Node().CreateAndAddRobotNode("ghost",
                                                       "/ghost_ns/robot_state_publisher")
    assert (refused.value.code.name, str(refused.value)) == ("NOT_FOUND", expected)
    assert "ghost" not in [r["name"] for r in ros.command("list_robots")["robots"]]
    assert ros.GetDefaultROS2Node().GetRobotNodeByName("ghost") is None


ELBOW_URDF = """<robot name="elbowed">
  <link name="base"><visual><geometry><box size="0.1 0.1 0.1"/></geometry></visual></link>
  <link name="plate"/>
  <link name="forearm"><visual><geometry><box size="0.2 0.05 0.05"/></geometry></visual>
  </link>
  <joint name="bolt" type="fixed"><parent link="base"/><child link="plate"/></joint>
  <joint name="elbow" type="revolute"><parent link="plate"/><child link="forearm"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>"""


def test_a_robot_without_joint_states_says_so_when_its_wait_times_out(
        ros: slicer_client.Client, processes: Processes, tmp_path: Path) -> None:
    """Issue 43, item 9: wait_until_loaded said "(2 of 2 meshes received); the daemon says
    loaded" when nothing published joint states, so the link after the moving joint had
    no tf. It now names the links without a transform and that cause."""
    urdf = tmp_path / "elbowed.urdf"
    urdf.write_text(ELBOW_URDF)
    processes.bridge("state-publisher", str(urdf), "--namespace", "elbow_ns",
                     "--frame-prefix", "elbow_ns/").wait_for_output("ready", timeout=30)
    robot = ros.robot("elbowed", namespace="elbow_ns", tf_prefix="elbow_ns/", wait=True)
    try:
        def placed() -> bool:
            plate = robot.links.get("plate")
            return robot.mesh_count() == 2 and plate is not None and \
                plate.matrix is not None and robot.state == "loaded"
        robot._wait(placed, scaled(30), "the meshes and the fixed links' transforms")
        with pytest.raises(slicer_client.RobotNotLoadedError) as error:
            robot.wait_until_loaded(timeout=1.0)
        assert str(error.value) == (
            "robot 'elbowed' not loaded within 1.0 s (2 of 2 meshes received); the daemon "
            "says loaded, but 1 link(s) have no transform (forearm): the links after moving "
            "joint(s) elbow get tf from a state publisher only once it has those joints' "
            "states, and nothing publishes joint states on /elbow_ns/joint_states")
        assert error.value.unposed == ("forearm",)
    finally:
        robot.remove()

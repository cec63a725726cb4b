"""The ROS2Bridge module's logic, widget and self-test driven as a 3D Slicer user would,
against a real daemon: tests/slicer_standin.py's scene (MRML nodes, subject hierarchy, the
event loop of `slicer.app.processEvents`) and its socket-backed connector node, with real
VTK. What ends up in the scene's nodes, the parameter node, the GUI and ROS is asserted."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np
import pytest

from slicer_standin import MODULE, load_module
from support import Processes, RunningDaemon, wait_until

SELFTEST = MODULE.parents[1] / "selftest.py"

# Two links with box and cylinder visuals (the daemon meshes them), one revolute joint.
ARM_URDF = """<robot name="arm">
  <link name="base_link"><visual><geometry><box size="0.1 0.1 0.02"/></geometry>
    <material name="red"><color rgba="1 0 0 1"/></material></visual></link>
  <link name="upper"><visual><origin xyz="0 0 0.05"/>
    <geometry><cylinder radius="0.01" length="0.1"/></geometry></visual></link>
  <joint name="shoulder" type="revolute"><parent link="base_link"/><child link="upper"/>
    <origin xyz="0 0 0.01"/><axis xyz="0 0 1"/>
    <limit lower="-1.5" upper="1.5" effort="1" velocity="1"/></joint>
</robot>"""


@pytest.fixture
def module(monkeypatch: pytest.MonkeyPatch) -> Iterator[Any]:
    """ROS2Bridge.py over the stand-ins with real VTK; sys.path as the test found it."""
    monkeypatch.setattr(sys, "path", list(sys.path))
    monkeypatch.delitem(sys.modules, "ROS2Bridge", raising=False)
    loaded = load_module(lambda name, mod: monkeypatch.setitem(sys.modules, name, mod),
                         real_vtk=True)
    yield loaded
    import slicer
    slicer.mrmlScene.Clear(0)  # stops every connector the test's scene still runs


def pump_until(predicate: Callable[[], bool], timeout: float = 20.0, what: str = "") -> None:
    """Slicer's event loop until `predicate` holds."""
    import slicer

    def step() -> bool:
        slicer.app.processEvents()
        return predicate()
    wait_until(step, timeout=timeout, what=what or "the scene")


@pytest.fixture
def widget(module: Any) -> Iterator[Any]:
    made = module.ROS2BridgeWidget()
    made.setup()
    yield made
    made.cleanup()


def connect(widget: Any, port: int) -> None:
    """What the user does: the port in the GUI, then Connect."""
    ui = widget.ui
    ui.portSpin.value = port
    ui.portSpin.emit("valueChanged(int)", port)
    ui.connectButton.checked = True
    ui.connectButton.emit("toggled(bool)", True)
    pump_until(lambda: widget.logic.client is not None, what="the module's client")


def scene_nodes(cls: str) -> list:
    import slicer
    return slicer.util.getNodesByClass(cls)


# --- the self-test ------------------------------------------------------------------------
def _run_selftest(monkeypatch: pytest.MonkeyPatch, port: str) -> int:
    monkeypatch.setenv("ROS2BRIDGE_TEST_PORT", port)
    spec = importlib.util.spec_from_file_location("ros2bridge_selftest", SELFTEST)
    assert spec is not None and spec.loader is not None
    selftest = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(selftest)
    return int(selftest.main())


def test_the_self_test_passes_against_a_daemon(module: Any, daemon: RunningDaemon,
                                               monkeypatch: pytest.MonkeyPatch,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    """selftest.py, the script users run inside Slicer, with ROS2BRIDGE_TEST_PORT set."""
    code = _run_selftest(monkeypatch, str(daemon.port))
    assert "ROS2Bridge self-test passed" in capsys.readouterr().out
    assert code == 0


def test_the_self_test_without_a_daemon_port_checks_the_scene_only(
        module: Any, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    import slicer
    monkeypatch.delenv("ROS2BRIDGE_TEST_PORT", raising=False)
    spec = importlib.util.spec_from_file_location("ros2bridge_selftest", SELFTEST)
    assert spec is not None and spec.loader is not None
    selftest = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(selftest)
    assert selftest.main() == 0
    assert capsys.readouterr().out.strip().endswith("ROS2Bridge self-test passed")
    shown = slicer.ScriptedLoadableModule.ScriptedLoadableModuleTest.displayed
    assert shown[-2:] == ["Scene placement passed",
                          "ROS2BRIDGE_TEST_PORT not set: daemon round trip skipped"]


def test_the_self_test_script_exits_with_its_code(module: Any,
                                                  monkeypatch: pytest.MonkeyPatch,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """Run as Slicer runs it (`--python-script`: as __main__), it ends Slicer with its
    exit code through slicer.util.exit; a daemon port nobody listens on is a failure."""
    import runpy
    import socket
    with socket.socket() as unused:
        unused.bind(("127.0.0.1", 0))
        port = unused.getsockname()[1]
    monkeypatch.setenv("ROS2BRIDGE_TEST_PORT", str(port))
    with pytest.raises(SystemExit) as exited:
        runpy.run_path(str(SELFTEST), run_name="__main__")
    assert exited.value.code == 1
    captured = capsys.readouterr()
    assert "ROS2Bridge self-test FAILED" in captured.out
    assert f"no daemon at 127.0.0.1:{port}" in captured.err


# --- the widget and logic, as a user drives them -------------------------------------------
def test_a_robot_is_loaded_placed_moved_and_removed(widget: Any, daemon: RunningDaemon,
                                                    processes: Processes) -> None:
    import slicer
    peer = processes.python("rsp", "param_node.py", "module_arm_rsp", "--description",
                            ARM_URDF)
    peer.wait_for_output("READY")
    logic, ui = widget.logic, widget.ui
    connect(widget, daemon.port)
    widget.updateStatus()
    assert ui.statusLabel.text.startswith("Connected to ")
    assert ui.statusLabel.text.endswith(f"(127.0.0.1:{daemon.port})")
    for edit, value in ((ui.robotNameEdit, "arm"), (ui.robotNodeEdit, "/module_arm_rsp")):
        edit.text = value
        edit.emit("textChanged(QString)", value)
    ui.loadRobotButton.emit("clicked(bool)", False)
    assert ui.robotCombo.items == ["arm"] and "robot: arm" in ui.bridgeList.items
    assert logic.robotNames() == ["arm"]
    saved = json.loads(logic.getParameterNode().bridgeState)
    assert [b["op"] for b in saved["bridges"]] == ["create_robot"]

    def visuals() -> list:
        return [n for n in scene_nodes("vtkMRMLModelNode")
                if n.GetAttribute("OpenIGTLink.ros2.robot") == "arm"]
    pump_until(lambda: len(visuals()) == 2 and any(
        n.GetID() in logic._planned for n in visuals()), what="the arm's base visual placed")
    sh = slicer.vtkMRMLSubjectHierarchyNode.GetSubjectHierarchyNode(slicer.mrmlScene)
    base = next(v for v in visuals() if v.GetAttribute("OpenIGTLink.ros2.link") == "base_link")
    link = base.GetParentTransformNode()
    assert link.GetName() == "arm:base_link" and base.GetPolyData().GetNumberOfPoints() > 0
    folder = sh.GetItemParent(sh.GetItemByDataNode(base))
    assert sh.GetItemName(folder) == "robot arm"
    assert sh.GetItemName(sh.GetItemParent(folder)) == "ROS2 robots"
    display = base.GetDisplayNode()
    assert (display.GetColor(), display.GetOpacity(), display.GetScalarVisibility()) == \
        ((1.0, 0.0, 0.0), 1.0, False)
    # No tf moves the upper link here: its visual waits for its link's transform.
    upper = next(v for v in visuals() if v.GetAttribute("OpenIGTLink.ros2.link") == "upper")
    assert upper.GetID() not in logic._planned and upper.GetParentTransformNode() is None
    # The connector's model nodes count as the robot's meshes: its load completes.
    def robot_line() -> str:
        widget.updateStatus()
        return str(ui.robotStatusLabel.text)
    pump_until(lambda: robot_line() == "arm: 2 of 2 meshes received",
               what="the robot's meshes counted")
    # The robot's load blocks the daemon's session for seconds, its heartbeat too: the
    # module may call the link silent meanwhile; the next heartbeat restores it.
    pump_until(logic.isConnected, what="the link live again")

    # Joint sliders: one per actuated joint, in degrees; moving one publishes the state.
    ui.robotCombo.currentText = "arm"
    ui.showJointsButton.emit("clicked(bool)", False)
    (label, slider), = ui.jointsWidget.layout().rows
    assert label == "shoulder:" and slider.suffix == " deg"
    assert (slider.minimum, slider.maximum) == pytest.approx((-85.94, 85.94), abs=0.01)
    moved = logic.setJoints("arm", widget._sliders, {"shoulder": 30.0})
    assert moved["shoulder"] == pytest.approx(np.radians(30.0))
    slider.value = 45.0
    slider.emit("valueChanged(double)", 45.0)
    assert not slicer.util.errors

    # "Another robot" offers a free name; removing the robot empties its folder.
    ui.anotherRobotButton.emit("clicked(bool)", False)
    assert ui.robotNameEdit.text == "robot2"
    ui.removeRobotButton.emit("clicked(bool)", False)
    assert ui.robotCombo.items == [] and visuals() == []
    assert not sh.GetItemByName("robot arm")
    assert all(n.GetAttribute("OpenIGTLink.ros2.robot") != "arm"
               for n in scene_nodes("vtkMRMLNode"))
    assert json.loads(logic.getParameterNode().bridgeState)["bridges"] == []
    with pytest.raises(RuntimeError, match="no robot '': load it first"):  # none shown
        ui.showJointsButton.emit("clicked(bool)", False)
    assert slicer.util.errors[-1].startswith("Failed to read the robot's joints. no robot")


def test_what_fails_is_shown_to_the_user(widget: Any, daemon: RunningDaemon,
                                         tmp_path: Path) -> None:
    import slicer
    logic, ui = widget.logic, widget.ui
    assert logic.robotNames() == [] and logic.staleLines() == [] and logic.robotLines() == []
    with pytest.raises(RuntimeError, match="press Connect"):
        ui.loadRobotButton.emit("clicked(bool)", False)
    with pytest.raises(RuntimeError, match="press Connect"):
        ui.refreshButton.emit("clicked(bool)", False)
    assert slicer.util.errors[-2:] == [
        "Failed to load the robot. not connected to the slicer-ros2-bridge daemon: press "
        "Connect (and start the daemon with `slicer-ros2-bridge run`)",
        "Failed to list the bridges. not connected to the slicer-ros2-bridge daemon: press "
        "Connect (and start the daemon with `slicer-ros2-bridge run`)"]
    missing = tmp_path / "absent.key"
    ui.keyFileEdit.text = str(missing)
    ui.keyFileEdit.emit("textChanged(QString)", str(missing))
    with pytest.raises(Exception, match="absent.key"):
        ui.connectButton.emit("toggled(bool)", True)
    assert slicer.util.errors[-1].startswith("Failed to (dis)connect.")
    ui.keyFileEdit.emit("textChanged(QString)", "")
    connect(widget, daemon.port)
    with pytest.raises(ValueError, match="select a model or markups node"):
        ui.sendButton.emit("clicked(bool)", False)
    text = slicer.mrmlScene.AddNewNodeByClass("vtkMRMLTextNode", "notes")
    with pytest.raises(ValueError, match="not a vtkMRMLTextNode"):
        logic.sendToROS(text, "/notes", "base_link")
    # A robot whose node does not exist: the GUI says so (issue 43, item 9: it "loaded"
    # with 0 links, waiting).
    ui.robotNodeEdit.emit("textChanged(QString)", "/no_such_node")
    with pytest.raises(Exception, match="NOT_FOUND: source.node: expected a node on the ROS "
                                        "graph holding parameter robot_description"):
        ui.loadRobotButton.emit("clicked(bool)", False)
    assert slicer.util.errors[-1].startswith("Failed to load the robot.")
    assert "/no_such_node: no such node" in slicer.util.errors[-1]
    widget.updateStatus()
    assert not ui.robotStatusLabel.text.startswith("demo:")
    ui.connectButton.checked = False
    ui.connectButton.emit("toggled(bool)", False)
    assert ui.statusLabel.text == "Not connected" and logic.client is None
    assert not logic.isActive()


def test_a_script_s_first_reference_call_connects_and_a_model_goes_to_ros(
        module: Any, daemon: RunningDaemon) -> None:
    """`getModuleLogic('ROS2Bridge').GetDefaultROS2Node()` before Connect connects to the
    settings' host and port; Send to ROS then pushes a real VTK model once."""
    import slicer
    import vtk
    logic = module.ROS2BridgeLogic()
    logic.getParameterNode().port = daemon.port
    ros_node = logic.GetDefaultROS2Node()
    assert logic.client is not None and logic.isConnected()
    assert logic.CreateROS2Node("second") is not None
    sphere = vtk.vtkSphereSource()
    sphere.Update()
    model = slicer.mrmlScene.AddNewNodeByClass("vtkMRMLModelNode", "ball")
    model.SetAndObservePolyData(sphere.GetOutput())
    shift = slicer.mrmlScene.AddNewNodeByClass("vtkMRMLLinearTransformNode", "shift")
    shift.matrix[0, 3] = 100.0  # mm
    model.SetAndObserveTransformNodeID(shift.GetID())
    publisher = logic.sendToROS(model, "/module_model", "base_link")
    assert publisher.device and "publisher: /module_model" in " ".join(logic.bridgeLines())
    # One POLYDATA went to the daemon: the surface in world coordinates, as triangles.
    (sent,) = [m for m in logic.connector.pushed if m.device_name == publisher.device]
    assert sent.body.points[:, 0].min() == pytest.approx(100.0 - 0.5, abs=0.02)  # moved 100 mm
    assert len(sent.body.polygons) == 4 * sphere.GetOutput().GetNumberOfPolys()
    # Markers: shown, listed, then removed with their nodes; reference robot calls.
    markers = logic.addMarkers("/module_markers", "MarkerArray", "base_link")
    assert markers.resolved_topic == "/module_markers"
    assert any(line.startswith("marker") and "/module_markers" in line
               for line in logic.bridgeLines())
    logic.removeMarkers("module_markers")
    assert not any("/module_markers" in line for line in logic.bridgeLines())
    assert logic.RemoveRobot("absent") is False
    # `getModuleLogic('ROS2')` before the GUI exists answers with this module's logic.
    slicer.util.moduleLogics["ROS2Bridge"] = logic
    from ROS2BridgeLib.reference import _ReferenceLogic
    assert _ReferenceLogic().GetDefaultROS2Node() is ros_node
    # Saving the scene keeps the bridges in the parameter node; closing it disconnects.
    logic.getParameterNode().bridgeState = ""
    slicer.mrmlScene.InvokeEvent(slicer.mrmlScene.StartSaveEvent)
    saved = json.loads(logic.getParameterNode().bridgeState)
    assert "create_publisher" in [b["op"] for b in saved["bridges"]]
    slicer.mrmlScene.Clear(0)
    assert logic.client is None and logic.connector is None and not logic.isActive()
    assert ros_node is not None
    logic.cleanup()


def test_point_clouds_and_points_markers_get_a_vertex_per_point(
        widget: Any, daemon: RunningDaemon, processes: Processes) -> None:
    """Issue 42 (8): the daemon sent one VERTICES cell per point, and Slicer's converter
    crashed on the second (the stand-in's connector raises there, as Slicer dies). Now it
    sends one polyvertex cell, of which the converter keeps the first point; the module
    gives every point of a cloud or a POINTS marker its vertex again, on every update."""
    import vtk
    from vtkmodules.util.numpy_support import vtk_to_numpy
    processes.python("data", "scene_data_publisher.py").wait_for_output("READY")
    connect(widget, daemon.port)
    logic = widget.logic
    cloud = logic.client.subscribe("/scene_cloud", "PointCloud2")
    logic.addMarkers("/scene_markers", "MarkerArray", "world")

    def model(predicate: Callable[[Any], bool]) -> Any:
        return next((n for n in scene_nodes("vtkMRMLModelNode") if predicate(n)), None)

    def cloud_node() -> Any:
        return model(lambda n: n.GetName() == cloud.device)

    def dots_node() -> Any:
        return model(lambda n: n.GetAttribute("OpenIGTLink.ros2.marker_type") == "points")

    def verts(node: Any) -> list[int]:
        out = vtk.vtkIdTypeArray()
        node.GetPolyData().GetVerts().ExportLegacyFormat(out)
        return vtk_to_numpy(out).tolist()

    pump_until(lambda: cloud_node() is not None and dots_node() is not None
               and cloud_node().GetPolyData().GetNumberOfPoints() == 4, what="cloud, markers")
    first = cloud_node().GetPolyData()
    pump_until(lambda: cloud_node().GetPolyData() is not first, what="the next cloud")
    for node, n in ((cloud_node(), 4), (dots_node(), 3)):
        assert verts(node) == [1, 0, 1, 1, 1, 2, 1, 3][:2 * n]
    # The cloud's colours came as the 4-component "RGBA" array: (40 i, 80, 120), opaque.
    rgba = vtk_to_numpy(cloud_node().GetPolyData().GetPointData().GetArray("RGBA"))
    np.testing.assert_allclose(rgba * 255, [[40 * i, 80, 120, 255] for i in range(4)],
                               atol=1e-3)


def test_the_module_plays_a_bag_and_seeks_it(widget: Any, processes: Processes,
                                             no_ros: dict[str, str], robot_bag: Any,
                                             demo: tuple[str, str]) -> None:
    """Issue 45: the module connects to a player (a process without ROS) as to the daemon;
    its logic reads the bag's clock, seeks, sets the rate and pauses, and the robot's link
    transform nodes in the scene follow: after a seek, the pose at the seek time."""
    pytest.importorskip("mcap_ros2", reason="the play extra (mcap-ros2-support)")
    from bags import NS
    from play_support import expected_link_poses, start_player

    player, port = start_player(processes, no_ros, str(robot_bag.mcap), "--paused",
                                "--start", "1.0", "--package-path", demo[1])
    connect(widget, port)
    logic = widget.logic
    status = logic.playbackStatus()
    assert status.paused and status.offset == 1.0 and status.duration == pytest.approx(2.0)
    logic.loadRobot("demo", "/robot_state_publisher", "robot_description")

    def flange() -> Any:
        return next((n for n in scene_nodes("vtkMRMLLinearTransformNode")
                     if n.GetName() == "demo:tool_flange"), None)

    def at(offset: float) -> np.ndarray:
        """base_link <- tool_flange (mm) at ``offset`` s: the robot's fixed frame is its root."""
        t = robot_bag.times[0] - NS // 100 + int(round(offset * NS))
        poses = expected_link_poses(robot_bag, robot_bag.state_at(t))
        return np.linalg.inv(poses["base_link"]) @ poses["tool_flange"]

    for offset in (1.0, 0.4, 1.7):
        if offset != 1.0:
            assert logic.seekPlayback(offset).offset == pytest.approx(offset)
        want = at(offset)
        pump_until(lambda want=want: flange() is not None and np.allclose(
            flange().matrix[:3, 3], want[:3, 3], atol=0.01), what=f"the pose at {offset} s")
    assert logic.setPlaybackRate(3.0).rate == 3.0
    assert not logic.resumePlayback().paused
    pump_until(lambda: logic.playbackStatus().ended, what="the end of the bag")
    pump_until(lambda: np.allclose(flange().matrix[:3, 3], at(2.0)[:3, 3], atol=0.01),
               what="the last pose")
    assert logic.pausePlayback().paused
    assert "NO-ROS GUARD" not in player.output() and "Traceback" not in player.output()

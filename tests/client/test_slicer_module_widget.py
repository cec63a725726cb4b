"""The ROS2Bridge module's widget and GUI file against tests/slicer_standin.py: the .ui's
widgets are the ones the code names, its parameter fields are the parameter node's, and
each control reaches the logic with what the GUI shows. 3D Slicer cannot run here: the
stand-in loads the .ui's XML as slicer.util.loadUI would, with no Qt."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
import types
from pathlib import Path
from typing import Any
from xml.etree import ElementTree as ET

import pytest

from slicer_client.joint_sliders import JointSlider
from slicer_client.send_plan import KIND_ORDER, SEND_TYPES
from slicer_standin import MODULE, load_module

UI = MODULE.parent / "Resources" / "UI" / "ROS2Bridge.ui"


def _load(monkeypatch: pytest.MonkeyPatch) -> Any:
    return load_module(lambda name, module: monkeypatch.setitem(sys.modules, name, module))


def _ui_widgets() -> dict[str, ET.Element]:
    return {w.get("name", ""): w for w in ET.parse(UI).getroot().iter("widget")}


def test_every_widget_the_code_names_is_in_the_ui_file() -> None:
    used = set(re.findall(r"\bui\.(\w+)", MODULE.read_text()))
    assert {"connectButton", "robotCombo", "sendNodeSelector", "jointsWidget"} <= used
    assert used <= set(_ui_widgets())


def test_the_ui_parameter_fields_are_the_parameter_node_s() -> None:
    tree = ast.parse((MODULE.parent / "ROS2BridgeLib" / "parameters.py").read_text())
    (node,) = [n for n in tree.body
               if isinstance(n, ast.ClassDef) and n.name == "ROS2BridgeParameterNode"]
    fields = {s.target.id for s in node.body
              if isinstance(s, ast.AnnAssign) and isinstance(s.target, ast.Name)}
    bound = {p.findtext("string"): name for name, w in _ui_widgets().items()
             for p in w.findall("property") if p.get("name") == "SlicerParameterName"}
    assert set(bound) == fields - {"bridgeState"}  # the saved bridges have no widget
    assert bound["port"] == "portSpin" and bound["keyFile"] == "keyFileEdit"


def test_the_ui_defaults_match_the_code_s(monkeypatch: pytest.MonkeyPatch) -> None:
    module = _load(monkeypatch)
    widgets = _ui_widgets()

    def texts(name: str, tag: str = "string") -> list[str]:
        return [e.text or "" for e in widgets[name].iter(tag)]

    assert texts("markerFrameEdit") == texts("sendFrameEdit") == [module.DEFAULT_FRAME]
    assert texts("sendNodeSelector")[:len(KIND_ORDER)] == list(KIND_ORDER)


@pytest.fixture
def widget(monkeypatch: pytest.MonkeyPatch) -> Any:
    module = _load(monkeypatch)
    made = module.ROS2BridgeWidget()
    made.setup()
    return made


def test_setup_loads_the_ui_and_binds_the_parameter_node(widget: Any) -> None:
    import slicer
    ui = widget.ui
    assert widget.layout.widgets == [ui.ROS2Bridge]
    assert ui.sendNodeSelector.scene is slicer.mrmlScene  # through the .ui's connection
    assert (ui.hostEdit.text, ui.portSpin.value, ui.robotNameEdit.text) == \
        ("127.0.0.1", 18944, "demo")
    assert ui.markerTypeCombo.currentText == "MarkerArray"
    widget.updateStatus()
    assert ui.statusLabel.text == "Not connected" and not ui.connectButton.checked
    assert widget._statusTimer.active and widget._statusTimer.interval == 500
    widget.cleanup()
    assert not widget._statusTimer.active and widget._parameterNode is None


def test_connect_takes_host_port_and_key_from_the_gui(widget: Any) -> None:
    calls: list = []
    widget.logic.connect = lambda *args: calls.append(("connect",) + args)
    widget.logic.disconnect = lambda: calls.append(("disconnect",))
    widget.logic.isActive = lambda: bool(calls) and calls[-1][0] == "connect"
    ui = widget.ui
    ui.hostEdit.text = "10.0.0.2"
    ui.hostEdit.emit("textChanged(QString)", "10.0.0.2")
    ui.portSpin.emit("valueChanged(int)", 18945)
    ui.connectButton.checked = True
    ui.connectButton.emit("toggled(bool)", True)
    assert calls == [("connect", "10.0.0.2", 18945, "")]
    assert ui.statusLabel.text == "Waiting for the daemon (retrying)..."
    ui.connectButton.emit("toggled(bool)", False)
    assert calls[-1] == ("disconnect",) and not ui.connectButton.checked


def test_status_lines_show_the_link_state_problems_and_stale_streams(widget: Any) -> None:
    logic, ui = widget.logic, widget.ui
    logic.transport = types.SimpleNamespace(connected=False, silent=True, address="h:1")
    logic.connector = types.SimpleNamespace(GetState=lambda: 2)
    logic.problems.extend(f"problem {i}" for i in range(7))
    logic.staleLines = lambda: ["/or_pose: stale"]
    widget.updateStatus()
    assert ui.statusLabel.text.startswith("LINK LOST: no heartbeat")
    assert ui.problemsLabel.text == "\n".join(f"problem {i}" for i in range(2, 7))
    assert ui.staleLabel.text == "/or_pose: stale" and ui.connectButton.checked
    logic.transport = types.SimpleNamespace(connected=True, silent=False, address="h:1")
    logic.client = types.SimpleNamespace(daemon_info={"node": "/slicer_bridge"})
    logic.robotLines = lambda: ["robot demo: loaded"]
    widget.updateStatus()
    assert ui.statusLabel.text == "Connected to /slicer_bridge (h:1)"
    assert ui.robotStatusLabel.text == "robot demo: loaded"


def test_robot_and_marker_controls_call_the_logic_with_the_gui_s_values(widget: Any) -> None:
    logic, ui = widget.logic, widget.ui
    calls: list = []
    robots = ["demo"]
    logic.loadRobot = lambda *args: calls.append(("load",) + args)
    logic.removeRobot = lambda name: (calls.append(("remove", name)), robots.remove(name))
    logic.robotNames = lambda: list(robots)
    logic.bridgeLines = lambda: ["robot: demo"]
    logic.addMarkers = lambda *args: calls.append(("markers",) + args)
    logic.removeMarkers = lambda topic: calls.append(("no markers", topic))
    ui.loadRobotButton.emit("clicked(bool)", False)
    assert calls[-1] == ("load", "demo", "/robot_state_publisher", "robot_description")
    assert ui.robotCombo.items == ["demo"] and ui.bridgeList.items == ["robot: demo"]
    robots.append("robot2")
    ui.anotherRobotButton.emit("clicked(bool)", False)
    assert ui.robotNameEdit.text == "robot3"  # the parameter node updates the GUI
    ui.removeRobotButton.emit("clicked(bool)", False)
    assert calls[-1] == ("remove", "demo") and ui.robotCombo.items == ["robot2"]
    ui.addMarkersButton.emit("clicked(bool)", False)
    ui.removeMarkersButton.emit("clicked(bool)", False)
    assert calls[-2:] == [("markers", "/visualization_marker_array", "MarkerArray", "base_link"),
                          ("no markers", "/visualization_marker_array")]


def test_a_failing_action_is_shown_and_raised(widget: Any) -> None:
    import slicer

    def refuse(*args: Any) -> None:
        raise RuntimeError("not connected")
    widget.logic.loadRobot = refuse
    with pytest.raises(RuntimeError):
        widget.ui.loadRobotButton.emit("clicked(bool)", False)
    assert slicer.util.errors == ["Failed to load the robot. not connected"]


def test_send_to_ros_offers_the_node_s_types_and_sends_what_is_chosen(widget: Any) -> None:
    logic, ui = widget.logic, widget.ui
    sent: list = []
    logic.sendToROS = lambda *args: sent.append(args)
    logic.bridgeLines = lambda: []
    model = types.SimpleNamespace(IsA=lambda cls: cls == "vtkMRMLModelNode")
    ui.sendNodeSelector.current_node = model
    ui.sendNodeSelector.emit("currentNodeChanged(vtkMRMLNode*)", model)
    assert ui.sendTypeCombo.items == list(SEND_TYPES["vtkMRMLModelNode"])
    ui.sendButton.emit("clicked(bool)", False)
    assert sent == [(model, "/slicer/model", "base_link", ui.sendTypeCombo.items[0])]
    ui.sendNodeSelector.emit("currentNodeChanged(vtkMRMLNode*)", None)
    assert ui.sendTypeCombo.items == []


def test_joint_sliders_are_made_per_joint_and_move_the_robot(widget: Any) -> None:
    logic, ui = widget.logic, widget.ui
    ui.robotCombo.addItem("demo")
    specs = [JointSlider("joint_1", "revolute", -90.0, 90.0, "deg", ("joint_1b",)),
             JointSlider("slide", "prismatic", 10.0, 100.0, "mm")]
    logic.jointSliders = lambda name: specs if name == "demo" else []
    moved: list = []
    logic.setJoints = lambda *args: moved.append(args)
    for _ in range(2):  # showing again replaces the rows
        ui.showJointsButton.emit("clicked(bool)", False)
    rows = ui.jointsWidget.layout().rows
    assert [label for label, _ in rows] == ["joint_1:", "slide:"]
    first, second = rows[0][1], rows[1][1]
    assert (first.decimals, first.suffix, second.suffix, second.value) == (1, " deg", " mm", 55.0)
    assert first.toolTip == "Also moves (mimic): joint_1b"
    first.value = 45.0
    first.emit("valueChanged(double)", 45.0)
    assert moved == [("demo", specs, {"joint_1": 45.0, "slide": 55.0})]


def test_the_module_answers_the_reference_once_slicer_has_started(
        monkeypatch: pytest.MonkeyPatch) -> None:
    module = _load(monkeypatch)
    import slicer
    parent = types.SimpleNamespace()
    module.ROS2Bridge(parent)
    assert parent.title == "ROS2 Bridge" and parent.dependencies == ["OpenIGTLinkIF"]
    installed: list = []
    monkeypatch.setattr(sys.modules["ROS2BridgeLib.reference"], "install_entry_points",
                        lambda slicer_module, logic: installed.append(logic) or True)
    slicer.app.emit("startupCompleted()")
    assert len(installed) == 1


@pytest.mark.integration  # a Python of its own, without the packages
def test_without_the_client_packages_the_module_says_what_to_install(tmp_path: Path) -> None:
    """A clone's module folder with neither the extension nor the wheel installed."""
    script = (
        "import sys, types\n"
        f"sys.path[:] = [p for p in sys.path if p not in ('', {str(MODULE.parents[3])!r})]\n"
        "sys.modules['protocol'] = None; sys.modules['slicer_client'] = None\n"
        f"sys.path.insert(0, {str(MODULE.parent)!r})\n"
        "import ROS2BridgeLib\n")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          cwd=tmp_path, timeout=60)
    assert done.returncode == 1
    assert "ImportError: The ROS2Bridge module needs the Python package(s) protocol, " \
        "slicer_client" in done.stderr
    assert "tools/build_client_wheel.py" in done.stderr
    assert "slicer.util.pip_install(" in done.stderr

"""The module's widget (ROS2BridgeWidget over Resources/UI/ROS2Bridge.ui) in a real scene:
Slicer's own slicer.util (loadUI, childWidgetVariables, tryWithErrorDisplay) over the Qt
widgets tools/slicer_core/qt_widgets.py imitates, the real parameter node under them. Each
control is driven as a user would (`emit`); where a section checks only the wiring, the
logic's method is replaced by a recorder, as the GUI's calls are what is checked."""

from __future__ import annotations

import logging
from types import SimpleNamespace
from typing import Any

import slicer

from scene_tools import error_of
from slicer_client.joint_sliders import JointSlider


class Shown(logging.Handler):
    """What slicer.util.errorDisplay showed (with no main window, it logs the text)."""

    def __init__(self) -> None:
        super().__init__(logging.ERROR)
        self.texts: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.texts.append(record.getMessage())


def main(session: Any, args: dict[str, Any]) -> dict[str, Any]:
    shown = Shown()
    logging.getLogger().addHandler(shown)
    out: dict[str, Any] = {}

    def make() -> Any:
        widget = session.module.ROS2BridgeWidget()
        widget.setup()
        return widget

    # setup: the .ui loaded, the scene passed on, the parameter node bound, the timer on.
    widget = make()
    ui = widget.ui
    widget.updateStatus()
    out["setup"] = {
        "layout": [w.name for w in widget.layout.widgets],
        "selector_scene": ui.sendNodeSelector.scene is slicer.mrmlScene,
        "fields": [ui.hostEdit.text, ui.portSpin.value, ui.robotNameEdit.text],
        "marker_type": ui.markerTypeCombo.currentText,
        "status": ui.statusLabel.text, "checked": ui.connectButton.checked,
        "timer": [widget._statusTimer.isActive(), widget._statusTimer.interval()]}
    widget.cleanup()
    out["cleanup"] = {"timer": widget._statusTimer.isActive(),
                      "parameter_node": widget._parameterNode is None}

    # Connect takes the host, port and key the GUI shows (kept in the parameter node).
    widget = make()
    logic, ui = widget.logic, widget.ui
    calls: list[list[Any]] = []
    logic.connect = lambda *a: calls.append(["connect", *a])
    logic.disconnect = lambda: calls.append(["disconnect"])
    logic.isActive = lambda: bool(calls) and calls[-1][0] == "connect"
    ui.hostEdit.text = "10.0.0.2"
    ui.hostEdit.emit("textChanged(QString)", "10.0.0.2")
    ui.portSpin.emit("valueChanged(int)", 18945)
    ui.connectButton.checked = True
    ui.connectButton.emit("toggled(bool)", True)
    out["connect"] = {"calls": list(calls), "status": ui.statusLabel.text,
                      "saved_port": logic.getParameterNode().port}
    ui.connectButton.emit("toggled(bool)", False)
    out["connect"].update(last=calls[-1], checked=ui.connectButton.checked)

    # The status lines: the link's state, the last problems, the stale streams.
    logic.transport = SimpleNamespace(connected=False, silent=True, address="h:1")
    logic.connector = SimpleNamespace(GetState=lambda: 2)
    logic.isActive = lambda: True
    logic.problems.extend(f"problem {i}" for i in range(7))
    logic.staleLines = lambda: ["/or_pose: stale"]
    widget.updateStatus()
    out["status_lost"] = [ui.statusLabel.text, ui.problemsLabel.text, ui.staleLabel.text,
                          ui.connectButton.checked]
    logic.transport = SimpleNamespace(connected=True, silent=False, address="h:1")
    logic.client = SimpleNamespace(daemon_info={"node": "/slicer_bridge"})
    logic.robotLines = lambda: ["robot demo: loaded"]
    widget.updateStatus()
    out["status_up"] = [ui.statusLabel.text, ui.robotStatusLabel.text]

    # Robot and marker controls call the logic with what the GUI shows.
    widget = make()
    logic, ui = widget.logic, widget.ui
    calls.clear()
    robots = ["demo"]
    logic.loadRobot = lambda *a: calls.append(["load", *a])
    logic.removeRobot = lambda name: (calls.append(["remove", name]), robots.remove(name))
    logic.robotNames = lambda: list(robots)
    logic.bridgeLines = lambda: ["robot: demo"]
    logic.addMarkers = lambda *a: calls.append(["markers", *a])
    logic.removeMarkers = lambda topic: calls.append(["no markers", topic])
    ui.loadRobotButton.emit("clicked(bool)", False)
    out["robot"] = {"load": calls[-1], "combo": list(ui.robotCombo.items),
                    "bridges": list(ui.bridgeList.items)}
    robots.append("robot2")
    ui.anotherRobotButton.emit("clicked(bool)", False)
    out["robot"]["another"] = ui.robotNameEdit.text  # the parameter node updates the GUI
    ui.removeRobotButton.emit("clicked(bool)", False)
    out["robot"].update(remove=calls[-1], combo_after=list(ui.robotCombo.items))
    ui.addMarkersButton.emit("clicked(bool)", False)
    ui.removeMarkersButton.emit("clicked(bool)", False)
    out["markers"] = calls[-2:]

    # A failing action is shown to the user, then raised.
    def refuse(*a: Any) -> None:
        raise RuntimeError("not connected")
    logic.loadRobot = refuse
    out["failing"] = {"raised": error_of(lambda: ui.loadRobotButton.emit("clicked(bool)",
                                                                          False)),
                      "shown": list(shown.texts)}

    # Send to ROS: the types the chosen node can go as; the chosen one is sent.
    sent: list[list[Any]] = []
    logic.sendToROS = lambda *a: sent.append([a[0].GetID(), *a[1:]])
    logic.bridgeLines = lambda: []
    model = slicer.mrmlScene.AddNewNodeByClass("vtkMRMLModelNode", "m")
    ui.sendNodeSelector.current_node = model
    ui.sendNodeSelector.emit("currentNodeChanged(vtkMRMLNode*)", model)
    out["send"] = {"types": list(ui.sendTypeCombo.items)}
    ui.sendButton.emit("clicked(bool)", False)
    out["send"]["sent"] = sent
    ui.sendNodeSelector.emit("currentNodeChanged(vtkMRMLNode*)", None)
    out["send"]["types_none"] = list(ui.sendTypeCombo.items)

    # Joint sliders: one per joint, made again when shown again; moving one moves all.
    ui.robotCombo.clear()
    ui.robotCombo.addItem("demo")
    specs = [JointSlider("joint_1", "revolute", -90.0, 90.0, "deg", ("joint_1b",)),
             JointSlider("slide", "prismatic", 10.0, 100.0, "mm")]
    logic.jointSliders = lambda name: specs if name == "demo" else []
    moved: list[Any] = []
    logic.setJoints = lambda name, sliders, values: moved.append([name, values])
    for _ in range(2):
        ui.showJointsButton.emit("clicked(bool)", False)
    rows = ui.jointsWidget.layout().rows
    first, second = rows[0][1], rows[1][1]
    out["sliders"] = {"labels": [label for label, _ in rows],
                      "first": [first.decimals, first.suffix, first.toolTip],
                      "second": [second.suffix, second.value]}
    first.value = 45.0
    first.emit("valueChanged(double)", 45.0)
    out["sliders"]["moved"] = moved
    logging.getLogger().removeHandler(shown)
    return out

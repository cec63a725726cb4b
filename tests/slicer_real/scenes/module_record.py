"""The module's Record section in a real scene against a real daemon (issue 45): the bag path
typed in, Record pressed; the daemon records what the module bridges; the section shows the
file and the elapsed time, then the final counts; a second start on the same file is refused
(shown as Slicer shows errors) and the button comes back up. The test reads the bag."""

from __future__ import annotations

from typing import Any

from scene_tools import connect


def main(session: Any, args: dict[str, Any]) -> dict[str, Any]:
    widget = session.module.ROS2BridgeWidget()
    widget.setup()
    session.logic = widget.logic  # what the user connects: the widget's logic
    logic, ui = connect(session, args["port"]), widget.ui
    logic.requireClient().subscribe(args["topic"], "PoseStamped")
    bag = args["bag"]
    ui.recordPathEdit.text = bag
    ui.recordPathEdit.emit("textChanged(QString)", bag)
    ui.recordButton.checked = True
    ui.recordButton.emit("toggled(bool)", True)
    out: dict[str, Any] = {"saved_path": logic.getParameterNode().recordPath,
                           "label_running": ui.recordLabel.text}
    session.pump(60, until=lambda: logic.recording.counts.get(args["topic"], 0) >= 20,
                 what="20 poses recorded")
    ui.recordButton.checked = False
    ui.recordButton.emit("toggled(bool)", False)
    final = logic.recording.status()
    out.update(final={"running": final["running"], "messages": final["messages"],
                      "topics": {t["topic"]: t["messages"] for t in final["topics"]}},
               label_final=ui.recordLabel.text)
    ui.recordButton.checked = True
    try:
        ui.recordButton.emit("toggled(bool)", True)
        out["second"] = ""
    except Exception as error:  # noqa: BLE001 - what Slicer shows
        out["second"] = f"{type(error).__name__}: {error}"
    widget.updateStatus()
    out["button_after"] = ui.recordButton.checked
    out["running_after"] = logic.recording.running
    widget.cleanup()
    return out

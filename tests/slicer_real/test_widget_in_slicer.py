"""The module's widget in a real scene (scenes/widget.py): Slicer's own slicer.util loads
the .ui and shows errors, over the Qt widgets tools/slicer_core/qt_widgets.py imitates
(slicer-core has no Qt); the parameter node under the GUI is a real MRML node."""

from __future__ import annotations

from slicer_client.send_plan import SEND_TYPES


def test_the_widget_s_controls_reach_the_logic_with_what_the_gui_shows(run_scene) -> None:
    got = run_scene("widget")
    assert got["setup"] == {
        "layout": ["ROS2Bridge"], "selector_scene": True,  # through the .ui's connection
        "fields": ["127.0.0.1", 18944, "demo"], "marker_type": "MarkerArray",
        "status": "Not connected", "checked": False, "timer": [True, 500]}
    assert got["cleanup"] == {"timer": False, "parameter_node": True}
    assert got["connect"] == {
        "calls": [["connect", "10.0.0.2", 18945, ""]],
        "status": "Waiting for the daemon (retrying)...", "saved_port": 18945,
        "last": ["disconnect"], "checked": False}
    lost = got["status_lost"]
    assert lost[0].startswith("LINK LOST: no heartbeat")
    assert lost[1:] == ["\n".join(f"problem {i}" for i in range(2, 7)), "/or_pose: stale", True]
    assert got["status_up"] == ["Connected to /slicer_bridge (h:1)", "robot demo: loaded"]
    assert got["robot"] == {
        "load": ["load", "demo", "/robot_state_publisher", "robot_description"],
        "combo": ["demo"], "bridges": ["robot: demo"], "another": "robot3",
        "remove": ["remove", "demo"], "combo_after": ["robot2"]}
    assert got["markers"] == [
        ["markers", "/visualization_marker_array", "MarkerArray", "base_link"],
        ["no markers", "/visualization_marker_array"]]
    assert got["failing"]["raised"] == "RuntimeError: not connected"
    assert got["failing"]["shown"] == ["Failed to load the robot.\n\nnot connected"]
    send = got["send"]
    assert send["types"] == list(SEND_TYPES["vtkMRMLModelNode"])
    assert send["sent"] == [["vtkMRMLModelNode1", "/slicer/model", "base_link",
                             send["types"][0]]]
    assert send["types_none"] == []
    assert got["sliders"] == {
        "labels": ["joint_1:", "slide:"], "first": [1, " deg", "Also moves (mimic): joint_1b"],
        "second": [" mm", 55.0], "moved": [["demo", {"joint_1": 45.0, "slide": 55.0}]]}

"""The ROS2Bridge module's transport and widget in a real Slicer scene, with no daemon (one
scene run for both: scenes/offline.py).

The transport (scenes/transport.py): ConnectorTransport over 3D Slicer's own OpenIGTLinkIF
connector, against an OpenIGTLink peer that does on cue what a daemon will not
(scenes/igtl_peer.py): commands, exactly-once sends, a loss said once, a silent heartbeat
(issue 23: a pulled cable leaves the connector's socket "connected"), and the module's
defaults (issue 25, item 11).

The widget (scenes/widget.py): Slicer's own slicer.util loads the .ui and shows errors, over
the Qt widgets tools/slicer_core/qt_widgets.py imitates (slicer-core has no Qt); the
parameter node under the GUI is a real MRML node.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from typing import Any

import pytest

from bridge.robots.demo.urdf import DEMO_URDF
from slicer_client.send_plan import SEND_TYPES
from support import REPO


@pytest.fixture(scope="module")
def offline(module_run_scene: Any) -> dict[str, Any]:
    return module_run_scene("offline")


def test_the_transport_over_slicer_s_connector(offline: dict[str, Any]) -> None:
    got = offline["transport"]
    assert got["watches_silence"] and not got["drops_late_values"]
    # A command goes as vtkSlicerOpenIGTLinkCommand; unanswered, it expires at its timeout
    # (answered: the self-test's round trip through a daemon, test_selftest_in_slicer.py).
    assert got["command_names"] == ["list_bridges"]
    assert got["expired"].startswith("CommandTimeoutError: ")
    assert 0.9 < got["expired_after_s"] < 5.0
    # Each text send is one message, changed or not; the outgoing node is Slicer's ASCII.
    assert got["texts"] == ["a", "a", "b"]
    assert got["outgoing"] == [["vtkMRMLTextNode", "pub:cmd", 3]]
    assert got["not_ascii"].startswith("ValueError: ") and "not ASCII" in got["not_ascii"]
    # A point list: one POINT per send, its control points' world positions and labels.
    assert got["node_kind"] == "vtkMRMLMarkupsFiducialNode"
    expected = [[[1.0, 2.0, 3.0], "entry"], [[4.0, 5.0, 6.0], "target"]]
    assert got["points"] == [expected, expected]
    # The heartbeat's STATUS node is counted and hidden; a stream's condition is handed on.
    assert got["heartbeat"]["count"] == 3 and got["heartbeat"]["connected"]
    # (A stream's STATUS node is hidden too, as Slicer's connector makes them: the module
    # hides only the heartbeat's, which the connector may one day show.)
    assert got["heartbeat"]["hidden"] == 1 and got["heartbeat"]["stream_hidden"] == 1
    assert got["stale_message"] == ["or_pose", 13, "stale", "no publisher of /or_pose"]
    assert got["live_condition"] == ["", 2]
    # 3.1 s without a heartbeat: the link is lost, said once; commands are refused at once.
    silent = got["silent"]
    assert silent["seen"][0] == ["up", True] and silent["seen"][1][0] == "down"
    assert "no heartbeat from the daemon for 3.1 s" in silent["seen"][1][1]
    assert not silent["connected"] and silent["silent"]
    assert silent["command"].startswith("ConnectionClosedError: ")
    assert "no heartbeat" in silent["command"]
    assert silent["commands_sent"] == 0
    assert got["said_once"] == ["up", "down"]
    assert got["back"] == {"last": ["up", False], "connected": True, "silent": False}
    # The socket closed: one loss (found by poll), one return (a duplicate event: nothing).
    assert got["loss"] == [["down"], ["up", False]]
    # Stopped at the end: refused at once.
    assert got["stopped"].startswith("ConnectionClosedError: ")
    assert "not connected" in got["stopped"]

    # A quick reconnect comes with no connector event at all (the test below).
    assert got["quick_reconnect"]["connector_events"] == []

    # The module's defaults fit the demo: the robot name the GUI offers is the demo's
    # robot, and the frame markers and models default to is the demo arm's root link.
    robot = ET.fromstring(DEMO_URDF)
    children = {joint.find("child").get("link") for joint in robot.iter("joint")}  # type: ignore[union-attr]
    (root,) = [link.get("name") for link in robot.iter("link")
               if link.get("name") not in children]
    assert got["default_frame"] == root == "base_link"
    assert got["robot_name"] == "demo"  # a fresh parameter node's default
    demo_runner = (REPO / "bridge" / "robots" / "demo_runner.py").read_text()
    assert '"create_robot", {"name": "demo"' in demo_runner


def test_a_silent_link_s_quick_reconnect_brings_the_link_back(offline: dict[str, Any]) -> None:
    """Found on Slicer's real connector (issue 42): OpenIGTLinkIO's client makes its new
    socket within one turn of its connection thread and announces nothing to MRML; the
    module, silent, waited for a heartbeat (sent after a hello only) or a ConnectedEvent,
    and stayed 'LINK LOST' while data flowed. Data on the incoming nodes now brings it up."""
    got = offline["transport"]["quick_reconnect"]
    assert got["told"] == [["up", False]] and not got["silent"]


def test_the_widget_s_controls_reach_the_logic_with_what_the_gui_shows(
        offline: dict[str, Any]) -> None:
    got = offline["widget"]
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

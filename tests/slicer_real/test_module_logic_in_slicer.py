"""The module's logic as a user's script and the GUI's buttons drive it, in a real scene
against a daemon (scenes/module_logic.py): each failure says what to do, the reference's
first call connects by itself, a robot's removal takes its nodes, folder and saved bridge,
and closing the scene disconnects."""

from __future__ import annotations

from pathlib import Path

from support import Processes, RunningDaemon
from slicer_real.test_saved_scene_in_slicer import ARM_URDF

PRESS_CONNECT = ("not connected to the slicer-ros2-bridge daemon: press Connect (and start "
                 "the daemon with `slicer-ros2-bridge run`)")


def test_the_module_logic_fails_clearly_connects_and_cleans_up(
        run_scene, daemon: RunningDaemon, processes: Processes, tmp_path: Path) -> None:
    processes.python("rsp", "param_node.py", "logic_arm_rsp", "--description",
                     ARM_URDF).wait_for_output("READY")
    missing = tmp_path / "absent.key"
    got = run_scene("module_logic", port=daemon.port, robot_node="/logic_arm_rsp",
                    missing_key=str(missing))
    before = got["before_connect"]
    assert before["robots"] == before["stale"] == before["lines"] == []
    assert before["load"] == f"RuntimeError: {PRESS_CONNECT}"
    assert before["bridges"] == f"RuntimeError: {PRESS_CONNECT}"
    assert "absent.key" in before["key"]
    assert got["first_call"] == {"client": True, "connected": True, "second": True,
                                 "reference_logic_same_node": True}
    assert got["send_text"].startswith("ValueError") and "not a vtkMRMLTextNode" in got["send_text"]
    assert "select a model or markups node" in got["send_none"]
    # A robot whose node does not exist: said (issue 43, item 9: it "loaded" with 0 links).
    assert "NOT_FOUND: source.node: expected a node on the ROS graph holding parameter " \
        "robot_description" in got["no_such_node"]
    assert "/no_such_node: no such node" in got["no_such_node"]
    assert got["robots_after_failure"] == []
    assert got["markers"]["topic"] == "/module_markers"
    assert len(got["markers"]["listed"]) == 1 and got["markers"]["listed"][0].startswith("marker")
    assert got["markers"]["after_remove"] == []
    assert got["remove_absent_robot"] is False
    robot = got["robot"]
    assert robot["loaded"] == {"robots": ["arm"], "folder": True, "saved": ["create_robot"]}
    assert robot["robots_after"] == [] and robot["nodes_after"] == 0
    assert not robot["folder_after"] and robot["saved_after"] == []
    assert robot["sliders_of_none"] == "RuntimeError: no robot '': load it first"
    assert got["after_close"] == {"client": True, "connector": True, "active": False}

"""A session saved as an .mrb in a real scene, and reopened in a new one against another
daemon (as a user reopens it the next day): the module re-creates the robot and the
bridges it saved (scenes/mrb_save.py, scenes/mrb_open.py)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from support import Processes, assert_clean_exit, start_daemon

# Two links with box and cylinder visuals (the daemon meshes them), one revolute joint.
ARM_URDF = """<robot name="arm">
  <link name="base_link"><visual><geometry><box size="0.1 0.1 0.02"/></geometry>
    <material name="red"><color rgba="1 0 0 1"/></material></visual></link>
  <link name="upper"><visual><origin xyz="0 0 0.05"/>
    <geometry><cylinder radius="0.01" length="0.1"/></geometry></visual></link>
  <joint name="shoulder" type="fixed"><parent link="base_link"/><child link="upper"/>
    <origin xyz="0 0 0.01"/></joint>
</robot>"""


@pytest.mark.parametrize("saved_as", ["session.mrb", "session.mrml"])
def test_a_saved_scene_reopened_restores_the_robot_and_the_bridges(
        run_scene, processes: Processes, tmp_path: Path, saved_as: str) -> None:
    rsp = processes.python("rsp", "param_node.py", "mrb_arm_rsp", "--description", ARM_URDF)
    rsp.wait_for_output("READY")
    mrb = tmp_path / saved_as
    first = start_daemon(processes)
    saved = run_scene("mrb_save", port=first.port, robot_node="/mrb_arm_rsp", mrb=str(mrb))
    assert saved["saved"] and saved["zipped"] and mrb.stat().st_size > 0
    assert_clean_exit(first)
    # The next day: another daemon, nothing bridged on it yet.
    second = start_daemon(processes)
    got = run_scene("mrb_open", port=second.port, mrb=str(mrb))
    assert got["opened"]
    ops = [b["op"] for b in json.loads(got["saved_state"])["bridges"]]
    assert sorted(ops) == ["create_robot", "create_subscriber"]
    assert got["robots"] == ["arm"]
    assert "robot: arm" in got["bridges"]
    assert any(line.startswith("subscriber: /mrb_text") for line in got["bridges"]), \
        got["bridges"]
    assert got["robot_lines"] == ["arm: 2 of 2 meshes received"]
    assert got["models"] == ["arm:base_link:0"] and got["parents"] == ["arm:base_link"]

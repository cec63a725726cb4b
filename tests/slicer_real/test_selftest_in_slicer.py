"""The module's self-test: it passes in a real Slicer scene against a daemon, checks the
scene alone without a daemon port, and skips cleanly (exit 2, saying why) where `slicer`
imports but there is no 3D Slicer application. (Its failure where no daemon listens is not
run here: it waits its own 10 s for the link first.)"""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from support import REPO, RunningDaemon, scaled

SELFTEST = REPO / "slicer_client" / "slicer_module" / "selftest.py"


@pytest.mark.parametrize("subject_hierarchy", [True, False], ids=["with", "without-sh-plugins"])
def test_the_self_test_passes_in_a_real_scene(run_scene, daemon: RunningDaemon,
                                              subject_hierarchy: bool) -> None:
    """Also where nothing made subject-hierarchy items for new nodes (Slicer's Qt plugins
    do, its core does not): the module files its nodes itself."""
    ports = [daemon.port] if subject_hierarchy else [daemon.port, None]
    got = run_scene("selftest", ports=ports, session={"subject_hierarchy": subject_hierarchy})
    passed = got["runs"][0]
    assert passed["code"] == 0, passed["stdout"] + passed["stderr"]
    assert passed["displayed"] == ["Scene planner applied to real MRML nodes",
                                   "Scene placement passed", "Daemon round trip passed"]
    assert passed["stdout"].strip().endswith("ROS2Bridge self-test passed")
    if subject_hierarchy:
        return
    (scene_only,) = got["runs"][1:]
    assert scene_only["code"] == 0, scene_only["stdout"] + scene_only["stderr"]
    assert scene_only["displayed"][-2:] == [
        "Scene placement passed", "ROS2BRIDGE_TEST_PORT not set: daemon round trip skipped"]
    assert scene_only["stdout"].strip().endswith("ROS2Bridge self-test passed")


def test_the_self_test_skips_where_slicer_has_no_application(slicer_python: Path) -> None:
    """slicer-core's `slicer` imports, but it is not 3D Slicer: exit 2, not a failure."""
    done = subprocess.run([str(slicer_python), str(SELFTEST)], capture_output=True,
                          text=True, timeout=scaled(60), cwd=REPO)
    assert done.returncode == 2, done.stdout + done.stderr
    assert "selftest.py runs inside 3D Slicer (slicer imports, but has no slicer.app" \
        in done.stderr
    assert "Traceback" not in done.stderr

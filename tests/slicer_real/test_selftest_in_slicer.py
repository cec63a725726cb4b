"""The module's self-test: it passes in a real Slicer scene against a daemon, checks the
scene alone without a daemon port, fails (saying so) where no daemon listens, and skips
cleanly (exit 2, saying why) where `slicer` imports but there is no 3D Slicer application."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from support import REPO, RunningDaemon, pick_free_port, scaled

SELFTEST = REPO / "slicer_client" / "slicer_module" / "selftest.py"


@pytest.mark.parametrize("subject_hierarchy", [True, False], ids=["with", "without-sh-plugins"])
def test_the_self_test_passes_in_a_real_scene(run_scene, daemon: RunningDaemon,
                                              subject_hierarchy: bool) -> None:
    """Also where nothing made subject-hierarchy items for new nodes (Slicer's Qt plugins
    do, its core does not): the module files its nodes itself."""
    unused = pick_free_port()
    ports = [daemon.port] if subject_hierarchy else [daemon.port, None, unused]
    got = run_scene("selftest", ports=ports, session={"subject_hierarchy": subject_hierarchy})
    passed = got["runs"][0]
    assert passed["code"] == 0, passed["stdout"] + passed["stderr"]
    assert passed["displayed"] == ["Scene planner applied to real MRML nodes",
                                   "Scene placement passed", "Daemon round trip passed"]
    assert passed["stdout"].strip().endswith("ROS2Bridge self-test passed")
    if subject_hierarchy:
        return
    scene_only, no_daemon = got["runs"][1:]
    assert scene_only["code"] == 0, scene_only["stdout"] + scene_only["stderr"]
    assert scene_only["displayed"][-2:] == [
        "Scene placement passed", "ROS2BRIDGE_TEST_PORT not set: daemon round trip skipped"]
    assert scene_only["stdout"].strip().endswith("ROS2Bridge self-test passed")
    assert no_daemon["code"] == 1
    assert "ROS2Bridge self-test FAILED" in no_daemon["stdout"]
    assert f"no daemon at 127.0.0.1:{unused}" in no_daemon["stderr"]


def test_the_self_test_skips_where_slicer_has_no_application(slicer_python: Path) -> None:
    """slicer-core's `slicer` imports, but it is not 3D Slicer: exit 2, not a failure."""
    done = subprocess.run([str(slicer_python), str(SELFTEST)], capture_output=True,
                          text=True, timeout=scaled(60), cwd=REPO)
    assert done.returncode == 2, done.stdout + done.stderr
    assert "selftest.py runs inside 3D Slicer (slicer imports, but has no slicer.app" \
        in done.stderr
    assert "Traceback" not in done.stderr

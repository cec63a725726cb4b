"""The module's self-test: it passes in a real Slicer scene against a daemon, and skips
cleanly (exit 2, saying why) where `slicer` imports but there is no 3D Slicer application."""

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
    got = run_scene("selftest", port=daemon.port,
                    session={"subject_hierarchy": subject_hierarchy})
    assert got["code"] == 0, got["_output"][-3000:]
    assert got["displayed"] == ["Scene planner applied to real MRML nodes",
                                "Scene placement passed", "Daemon round trip passed"]
    assert "ROS2Bridge self-test passed" in got["_output"]


def test_the_self_test_skips_where_slicer_has_no_application(slicer_python: Path) -> None:
    """slicer-core's `slicer` imports, but it is not 3D Slicer: exit 2, not a failure."""
    done = subprocess.run([str(slicer_python), str(SELFTEST)], capture_output=True,
                          text=True, timeout=scaled(60), cwd=REPO)
    assert done.returncode == 2, done.stdout + done.stderr
    assert "selftest.py runs inside 3D Slicer (slicer imports, but has no slicer.app" \
        in done.stderr
    assert "Traceback" not in done.stderr

"""The repository as a ROS 2 package: `colcon build` in a workspace, then the daemon
started the way `ros2 run slicer_ros2_bridge bridge` starts it.

ROS 2 from PyPI has no `ros2` command, so the test does what `ros2 run` does: source the
workspace's setup script, ask the ament index for the package's prefix, and run
`<prefix>/lib/slicer_ros2_bridge/bridge`. colcon is colcon-common-extensions from PyPI
(the `test` extra), building against the ROS 2 wheels of the venv. The executables name the
venv's Python themselves (issue 25, item 5): the daemon runs without the venv on PATH, on the
compiled tf store that colcon built.
"""

from __future__ import annotations

import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from installed_daemon import assert_serves_hello_and_a_pose
from support import REPO, Processes, pick_free_port

pytestmark = pytest.mark.ros

COLCON = Path(sys.executable).parent / "colcon"
PACKAGE = "slicer_ros2_bridge"


@pytest.fixture(scope="module")
def workspace(tmp_path_factory: pytest.TempPathFactory) -> Path:
    if not COLCON.exists():
        pytest.skip(f"needs colcon ({COLCON}): the `test` extra installs it (make setup)")
    ws = tmp_path_factory.mktemp("ws")
    result = subprocess.run(
        [str(COLCON), "--log-base", str(ws / "log"), "build", "--base-paths", str(REPO),
         "--build-base", str(ws / "build"), "--install-base", str(ws / "install")],
        cwd=str(ws), capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    # One package: the tf2_msgs sources inside it (bridge/interfaces) are not a second one.
    assert "Summary: 1 package finished" in result.stdout, result.stdout[-2000:]
    return ws


def _sourced(ws: Path, command: str, *, venv_on_path: bool = True) -> list[str]:
    """`command` in a shell that sourced the workspace, as a ROS user's terminal has
    (``venv_on_path``: with the venv's bin first on PATH, as an activated venv)."""
    venv_bin = shlex.quote(str(Path(sys.executable).parent))
    setup = shlex.quote(str(ws / "install" / "setup.sh"))
    path = f"export PATH={venv_bin}:$PATH && " if venv_on_path else ""
    return ["bash", "-c", f"{path}. {setup} && {command}"]


def test_the_package_is_installed_where_ros2_run_looks(workspace: Path) -> None:
    probe = ("from ament_index_python.packages import get_package_prefix; import bridge; "
             f"print(get_package_prefix('{PACKAGE}')); print(bridge.__file__)")
    result = subprocess.run(_sourced(workspace, f"python3 -c {shlex.quote(probe)}"),
                            cwd=str(workspace), capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr[-2000:]
    prefix, module = result.stdout.split()
    install = workspace / "install" / PACKAGE
    assert Path(prefix) == install
    assert Path(module).is_relative_to(install)  # the installed copy, not the clone
    for executable in ("bridge", "demo", "state_publisher"):
        path = install / "lib" / PACKAGE / executable
        assert path.is_file() and path.stat().st_mode & 0o111, path
        # The Python that built it (the venv's, with rclpy), not the first python3 on PATH.
        assert path.read_text().splitlines()[0] == f"#!{sys.executable}", path
    assert (install / "share" / PACKAGE / "package.xml").is_file()
    assert list(install.glob("lib/python3*/site-packages/bridge/tf/_compiled_store*.so")), \
        "colcon did not build the compiled tf store"


def test_ros2_run_bridge_answers_hello_and_bridges_a_topic(workspace: Path,
                                                           processes: Processes) -> None:
    port = pick_free_port()
    find = ("$(python3 -c \"from ament_index_python.packages import get_package_prefix; "
            f"print(get_package_prefix('{PACKAGE}'))\")")
    prefix = subprocess.run(_sourced(workspace, f"echo {find}"), capture_output=True,
                            text=True, timeout=60, cwd=str(workspace)).stdout.strip()
    assert prefix == str(workspace / "install" / PACKAGE)
    # Without the venv on PATH: the executable names its Python itself.
    daemon = processes.start("colcon-bridge", _sourced(
        workspace, f"exec {prefix}/lib/{PACKAGE}/bridge --port {port}", venv_on_path=False),
        cwd=workspace)
    assert_serves_hello_and_a_pose(daemon, port, processes, "/colcon_pose")
    assert "INFO bridge: tf buffer on the compiled store" in daemon.output()

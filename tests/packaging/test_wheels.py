"""The two wheels, built here and installed into fresh virtual environments.

- The daemon's wheel (`pip wheel .`) with the pinned ROS 2 wheels: without tf2_msgs it says
  so in one line; `build-interfaces` provides it; then the daemon answers a client's hello
  and bridges a topic.
- The client's wheel (tools/build_client_wheel.py): numpy only, into Python 3.9 as 3D
  Slicer 5.4-5.6 ship, talking to a real daemon.

Installs use the repository's pip cache (.cache/pip, filled by `make setup`).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import venv
from pathlib import Path

import pytest

from installed_daemon import assert_serves_hello_and_a_pose
from support import REPO, Processes, assert_clean_exit, pick_free_port, start_daemon

pytestmark = pytest.mark.ros

PIP_ENV = {**os.environ, "PIP_CACHE_DIR": str(REPO / ".cache" / "pip"),
           "PIP_DISABLE_PIP_VERSION_CHECK": "1"}
PIP_ENV.pop("_ROS_WHEELS_BOOTSTRAP_COMPLETE", None)
PIP_ENV.pop("VIRTUAL_ENV", None)


def _run(argv: list[str], *, timeout: float = 900, env: dict[str, str] | None = None
         ) -> subprocess.CompletedProcess[str]:
    return subprocess.run(argv, capture_output=True, text=True, timeout=timeout,
                          env=env or PIP_ENV, cwd=str(REPO))


def _pip_install(python: Path, *requirements: str) -> None:
    result = _run([str(python), "-m", "pip", "install", "--quiet", *requirements])
    if result.returncode != 0:
        if "No matching distribution" in result.stderr or "Could not fetch" in result.stderr:
            pytest.skip(f"the package index is unreachable here: {result.stderr[-300:]}")
        raise AssertionError(f"pip install {' '.join(requirements)} failed:\n"
                             f"{result.stdout[-2000:]}\n{result.stderr[-3000:]}")


def _python_3_9() -> str | None:
    """A working Python 3.9: on PATH, or one of pyenv's (whose shim may not select it)."""
    candidates = [shutil.which("python3.9")] + sorted(
        str(p) for p in Path(os.environ.get("PYENV_ROOT", Path.home() / ".pyenv"))
        .glob("versions/3.9*/bin/python3.9"))
    for candidate in candidates:
        if candidate and _run([candidate, "-c", "import venv, ensurepip"],
                              timeout=60).returncode == 0:
            return candidate
    return None


def _fresh_venv(folder: Path, python: str = sys.executable) -> Path:
    if python == sys.executable:
        venv.EnvBuilder(with_pip=True, clear=True).create(folder)
    else:
        result = _run([python, "-m", "venv", "--clear", str(folder)])
        assert result.returncode == 0, result.stderr
    return folder / "bin" / "python"


@pytest.fixture(scope="module")
def daemon_wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    result = _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet",
                   "--wheel-dir", str(out), str(REPO)])
    assert result.returncode == 0, result.stderr[-3000:]
    (wheel,) = out.glob("slicer_ros2_bridge-*.whl")
    return wheel


def test_the_daemon_wheel_reports_what_it_lacks_then_builds_it_and_bridges(
        daemon_wheel: Path, tmp_path: Path, processes: Processes) -> None:
    python = _fresh_venv(tmp_path / "venv")
    _pip_install(python, str(daemon_wheel))
    cli = str(python.parent / "slicer-ros2-bridge")

    # tf2_msgs has no PyPI wheel: one line saying how to get it, no traceback.
    lacking = _run([cli, "run", "--port", str(pick_free_port())], timeout=120)
    assert lacking.returncode == 2
    assert "Traceback" not in lacking.stderr
    lines = lacking.stderr.strip().splitlines()
    assert len(lines) == 1, lacking.stderr
    assert "tf2_msgs is not installed in this environment" in lines[0]
    assert "slicer-ros2-bridge build-interfaces" in lines[0]

    _pip_install(python, f"{daemon_wheel}[interfaces]")
    built = _run([cli, "build-interfaces"])
    assert built.returncode == 0, built.stdout[-2000:] + built.stderr[-3000:]
    assert "tf2_msgs" in built.stdout

    port = pick_free_port()
    daemon = processes.start("wheel-daemon", [cli, "run", "--port", str(port)])
    assert_serves_hello_and_a_pose(daemon, port, processes, "/wheel_pose")


def test_the_client_wheel_installs_with_numpy_alone_into_python_3_9(
        tmp_path: Path, processes: Processes) -> None:
    python39 = _python_3_9()
    if python39 is None:
        pytest.skip("needs a Python 3.9 with venv (3D Slicer 5.4-5.6's version) to check the "
                    "client wheel on it")
    built = _run([sys.executable, str(REPO / "tools" / "build_client_wheel.py"),
                  "--out", str(tmp_path / "dist")])
    assert built.returncode == 0, built.stderr[-3000:]
    wheel = Path(built.stdout.strip().splitlines()[-1])
    assert wheel.name == "slicer_ros2_bridge_client-0.1.0-py3-none-any.whl"
    python = _fresh_venv(tmp_path / "venv39", python39)
    _pip_install(python, str(wheel))
    installed = _run([str(python), "-m", "pip", "list", "--format=freeze"]).stdout
    names = {line.split("==")[0].lower() for line in installed.splitlines()}
    assert names - {"pip", "setuptools", "numpy"} == {"slicer-ros2-bridge-client"}

    daemon = start_daemon(processes)
    script = ("import sys, slicer_client\n"
              f"ros = slicer_client.connect('127.0.0.1', {daemon.port}, reconnect=False)\n"
              "print('node', ros.daemon_info['node'])\n"
              "print('version', sys.version_info[:2])\n"
              "ros.close()\n")
    # Run outside the repository, so only the installed packages can be imported.
    result = subprocess.run([str(python), "-c", script], capture_output=True, text=True,
                            timeout=60, cwd=str(tmp_path), env=PIP_ENV)
    assert result.returncode == 0, result.stderr[-3000:]
    assert "node /slicer_bridge" in result.stdout
    assert "version (3, 9)" in result.stdout
    assert_clean_exit(daemon)

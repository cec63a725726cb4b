"""The two wheels, built here and installed into fresh virtual environments.

- The daemon's wheel (`pip wheel .`) with the pinned ROS 2 wheels: without tf2_msgs it says
  so in one line; `build-interfaces` provides it; then the daemon answers a client's hello
  and bridges a topic.
- The client's wheel (tools/build_client_wheel.py): numpy only, into the oldest Python it
  declares (3.9, as 3D Slicer 5.4-5.6 ship) with the oldest and the newest numpy there,
  loading the demo robot from a real `slicer-ros2-bridge demo`.

Installs use the repository's pip cache (.cache/pip, filled by `make setup`).
"""

from __future__ import annotations

import fnmatch
import json
import os
import re
import shutil
import subprocess
import sys
import tomllib
import venv
import zipfile
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pytest

from installed_daemon import assert_serves_hello_and_a_pose
from support import (REPO, Processes, RunningDaemon, assert_clean_exit, pick_free_port,
                     scaled)

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


def _python(version: str) -> str | None:
    """A working Python X.Y with venv: on PATH, or one of pyenv's (whose shim may not
    select it)."""
    candidates = [shutil.which(f"python{version}")] + sorted(
        str(p) for p in Path(os.environ.get("PYENV_ROOT", Path.home() / ".pyenv"))
        .glob(f"versions/{version}.*/bin/python{version}"))
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


def test_the_readme_s_install_line_names_the_daemon_wheel(daemon_wheel: Path) -> None:
    """Issue 25, item 4: with the compiled tf store inside, the wheel carries the Python's and
    the platform's tags; the README's install line names it with a glob that matches it."""
    readme = (REPO / "README.md").read_text()
    (pattern,) = re.findall(r'pip install "\$\(echo (dist/slicer_ros2_bridge-[^)]+\.whl)\)'
                            r'\[interfaces\]"', readme)
    assert fnmatch.fnmatch(f"dist/{daemon_wheel.name}", pattern), (pattern, daemon_wheel.name)
    with zipfile.ZipFile(daemon_wheel) as wheel:
        compiled = [n for n in wheel.namelist() if "_compiled_store" in n and n.endswith(".so")]
    tag = f"cp{sys.version_info.major}{sys.version_info.minor}"
    if compiled:
        assert daemon_wheel.name.endswith(f"-{tag}-{tag}-linux_x86_64.whl"), daemon_wheel.name
    else:
        assert daemon_wheel.name.endswith("-py3-none-any.whl"), daemon_wheel.name


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


# ---------------------------------------------------------------- the client's wheel

CLIENT_PYPROJECT = REPO / "packaging" / "client" / "pyproject.toml"
# The demo arm (bridge/robots/demo/urdf.py): its links, and its visuals (one mesh each).
DEMO_LINKS = ("base_link", "shoulder_link", "upper_arm_link", "elbow_link", "forearm_link",
              "wrist_1_link", "wrist_2_link", "wrist_3_link", "tool_flange", "finger_left",
              "finger_right")
DEMO_VISUALS = 14


def client_declares() -> tuple[str, str]:
    """(oldest Python "X.Y", oldest numpy) the client wheel declares in its pyproject."""
    project = tomllib.loads(CLIENT_PYPROJECT.read_text())["project"]
    python = re.fullmatch(r">=\s*(\d+\.\d+)", project["requires-python"])
    (numpy,) = [re.fullmatch(r"numpy>=\s*([\d.]+)", d) for d in project["dependencies"]
                if d.startswith("numpy")]
    assert python and numpy, project
    return python[1], numpy[1]


@pytest.fixture(scope="module")
def client_wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("client-wheel")
    built = _run([sys.executable, str(REPO / "tools" / "build_client_wheel.py"),
                  "--out", str(out)])
    assert built.returncode == 0, built.stderr[-3000:]
    wheel = Path(built.stdout.strip().splitlines()[-1])
    assert wheel.name == "slicer_ros2_bridge_client-0.1.0-py3-none-any.whl"
    return wheel


@pytest.fixture(scope="module")
def demo(module_processes: Processes) -> Iterator[RunningDaemon]:
    """`slicer-ros2-bridge demo`: the daemon with the demo robot moving."""
    port = pick_free_port()
    child = module_processes.bridge("demo", "--port", str(port))
    child.wait_for_output("slicer-ros2-bridge demo is running", timeout=60)
    running = RunningDaemon(child, port)
    yield running
    assert_clean_exit(running)


def _image_sum(width: int, height: int) -> int:
    """What tests/peers/stream_publisher.py --image sends, summed (its seed and draw)."""
    return int(np.random.default_rng(1).integers(0, 255, size=width * height * 3,
                                                 dtype=np.uint8).astype(np.int64).sum())


@pytest.mark.parametrize("numpy_version", ["oldest declared", "newest there"])
def test_the_client_wheel_on_the_oldest_python_and_numpy_it_declares(
        numpy_version: str, client_wheel: Path, demo: RunningDaemon, tmp_path: Path,
        processes: Processes) -> None:
    """The client wheel in a fresh venv of the oldest Python it declares (3D Slicer 5.4-5.6
    ship 3.9), with the oldest numpy it declares and with the newest that Python gets,
    against `slicer-ros2-bridge demo`: the robot's meshes, an image and a model sent to
    ROS, all messages of 3 KB and more, whose CRC the numpy code computes (no native
    CRC package in that venv). Issue 25, item 1: numpy before 2.1 failed every such
    message."""
    python_version, numpy_floor = client_declares()
    interpreter = _python(python_version)
    if interpreter is None:
        pytest.skip(f"needs Python {python_version} with venv (the oldest the client wheel "
                    f"declares) on PATH or in pyenv; none here")
    python = _fresh_venv(tmp_path / "venv", interpreter)
    numpy_requirement = f"numpy=={numpy_floor}" if numpy_version == "oldest declared" \
        else "numpy"
    _pip_install(python, str(client_wheel), numpy_requirement)
    installed = _run([str(python), "-m", "pip", "list", "--format=freeze"]).stdout
    versions = dict(line.split("==", 1) for line in installed.splitlines() if "==" in line)
    assert set(versions) - {"pip", "setuptools", "numpy"} == {"slicer-ros2-bridge-client"}
    if numpy_version == "oldest declared":
        assert versions["numpy"] in (numpy_floor, f"{numpy_floor}.0"), versions

    width, height = 64, 48  # rgb8: 9 KB
    processes.python("wheel-image", "stream_publisher.py", "/wheel_image", "10", "--image",
                     f"{width}x{height}").wait_for_output("READY", timeout=30)
    echo = processes.python("wheel-model", "echo_subscriber.py", "/wheel_model",
                            "shape_msgs/msg/Mesh", "--count", "1")
    echo.wait_for_output("READY", timeout=30)
    seen = tmp_path / "model-seen"
    # Outside the repository, so only the installed packages can be imported.
    probe = processes.start("wheel-probe", [str(python), "-u", str(
        Path(__file__).resolve().parent / "client_wheel_probe.py"), str(demo.port),
        "/wheel_image", "/wheel_model", str(seen)], cwd=tmp_path, env=PIP_ENV)

    def step(name: str) -> dict[str, Any]:
        line = probe.wait_for_output(f'RESULT {{"step": "{name}"', timeout=120)
        return dict(json.loads(line.split("RESULT ", 1)[1]))

    environment = step("environment")
    assert environment["python"] == [int(v) for v in python_version.split(".")]
    assert environment["numpy"] == versions["numpy"]
    assert environment["crc_backend"] == "python"  # numpy's CRC, not a native package's
    robot = step("robot")
    assert robot["links"] == sorted(DEMO_LINKS), robot
    assert robot["meshes"] == DEMO_VISUALS and robot["bodies_over_3kb"] >= 5, robot
    image = step("image")
    assert sorted(image["shape"]) == sorted([1, height, width, 3])[-len(image["shape"]):]
    assert image["sum"] == _image_sum(width, height), image
    mesh = json.loads(echo.wait_for_output("MSG ", timeout=120).split("MSG ", 1)[1])
    seen.touch()
    model = step("model")
    assert model == {"step": "model", "points": 900, "triangles": 841, "seen": True,
                     "errors": []}
    assert len(mesh["vertices"]) == 900 and len(mesh["triangles"]) == 841
    assert mesh["vertices"][31] == {"x": 0.001, "y": 0.001, "z": 0.0}  # mm -> m
    assert probe.popen.wait(scaled(60)) == 0, probe.output()[-3000:]


def test_make_client_wheel_needs_no_ros_set_up(tmp_path: Path) -> None:
    """Issue 43, item 11: `make client-wheel` ran the whole ROS set-up (make setup) first,
    where the client's wheel needs Python and pip only. Made with the system's Python and
    no venv: make's plan names build_client_wheel.py and nothing of the set-up."""
    plan = _run(["make", "-n", "--no-print-directory", "-C", str(REPO), "client-wheel",
                 "PYTHON=python3"])
    assert plan.returncode == 0, plan.stderr
    assert "tools/build_client_wheel.py --out dist" in plan.stdout
    assert "setup_env.py" not in plan.stdout and ".venv" not in plan.stdout, plan.stdout


def test_the_player_wheel_plays_a_bag_in_a_venv_without_ros(
        tmp_path: Path, processes: Processes, robot_bag: Any,
        demo_files: tuple[str, str]) -> None:
    """Issue 45: `slicer-ros2-bridge-play` from the player's wheel (no ROS 2 wheel; what a
    Windows or macOS laptop installs) in a fresh venv where `import rclpy` fails, serving a
    bag written by rosbags: the client places the robot's flange at the bag's pose."""
    import re

    import slicer_client
    from bags import NS
    from play_support import expected_link_poses

    from tools.build_client_wheel import build

    wheel = build(tmp_path / "dist", "player")
    python = _fresh_venv(tmp_path / "venv")
    _pip_install(python, str(wheel))
    no_rclpy = _run([str(python), "-c", "import rclpy"])
    assert no_rclpy.returncode != 0 and "No module named 'rclpy'" in no_rclpy.stderr
    player = processes.start("player-wheel", [
        str(python.parent / "slicer-ros2-bridge-play"), str(robot_bag.mcap), "--paused",
        "--start", "1.0", "--package-path", demo_files[1], "--port", "0"])
    match = re.search(r"listening on [\d.]+:(\d+)",
                      player.wait_for_output("listening on", timeout=60))
    assert match
    ros = slicer_client.connect("127.0.0.1", int(match.group(1)), reconnect=False)
    try:
        robot = ros.robot("demo")
        robot.wait_until_loaded(60)
        t = robot_bag.times[0] - NS // 100 + NS
        poses = expected_link_poses(robot_bag, robot_bag.state_at(t))
        want = np.linalg.inv(poses["base_link"]) @ poses["tool_flange"]
        got = robot.links["tool_flange"].matrix
        assert got is not None
        np.testing.assert_allclose(np.asarray(got)[:3, 3], want[:3, 3], atol=0.01)
    finally:
        ros.close()
    assert "Traceback" not in player.output()

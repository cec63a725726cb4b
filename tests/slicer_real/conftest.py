"""The real-Slicer tier: the ROS2Bridge module and SlicerROS2's API in a real MRML scene
(slicer-core from PyPI), fed by 3D Slicer's own OpenIGTLinkIF connector, against a real
daemon and real rclpy peers. Only Qt is imitated (tools/slicer_core/qt_layer.py).

The scene runs in the peer's Python (tools/slicer_core/peer.py builds it from
../shared/peers/slicer-openigtlinkif, minutes once, then cached in .cache/slicer-peer):
each test starts a scene script of tests/slicer_real/scenes/ there, with `run_scene`, and
asserts on the values it returns. Where the peer cannot be built, the tier skips, saying why.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Iterator

import pytest

from support import (TIME_SCALE, Processes, RunningDaemon, assert_clean_exit, children_of,
                     scaled, spare_domain, start_daemon, wait_until)
from tools.slicer_core.peer import PeerUnavailableError, peer_python

SCENES = Path(__file__).resolve().parent / "scenes"
RUNNER = Path(__file__).resolve().parents[2] / "tools" / "slicer_core" / "run_scene.py"


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    here = Path(__file__).resolve().parent
    for item in items:
        if here in item.path.parents:
            item.add_marker(pytest.mark.integration)


@pytest.fixture(scope="session")
def slicer_python() -> Path:
    """The real Slicer core's Python (built once per checkout), or a skip saying why not."""
    try:
        return peer_python()
    except PeerUnavailableError as error:
        pytest.skip(str(error))


@pytest.fixture(scope="module")
def daemon(module_processes: Processes) -> Iterator[RunningDaemon]:
    running = start_daemon(module_processes)
    yield running
    assert_clean_exit(running)


@pytest.fixture(scope="module")
def demo(module_processes: Processes) -> Iterator[RunningDaemon]:
    """`slicer-ros2-bridge demo` on a ROS domain of its own (other modules' robots are
    /robot_state_publisher too), once its two children run."""
    child = module_processes.bridge("demo", "--port", "0",
                                    env={"ROS_DOMAIN_ID": spare_domain(1)})
    line = child.wait_for_output(" (OpenIGTLink); ROS node", timeout=60)
    port = int(line.split(" (OpenIGTLink)")[0].rsplit(":", 1)[1])
    child.wait_for_output("Stop with Ctrl-C", timeout=60)
    wait_until(lambda: sum("joint_motion" in cmd or "state_publisher" in cmd
                           for _, _, cmd in children_of(child.pid)) == 2,
               what="the demo's two children")
    yield RunningDaemon(child, port)
    child.stop()


class SceneRunner:
    def __init__(self, python: Path, processes: Processes) -> None:
        self.python, self.processes = python, processes

    def __call__(self, scene: str, timeout: float = 120.0, **args: Any) -> dict[str, Any]:
        """Run scenes/<scene>.py's main(session, args) in a real Slicer core; its result."""
        env = {"SLICER_BRIDGE_TEST_TIME_SCALE": str(TIME_SCALE), "PYTHONPATH": ""}
        child = self.processes.start(f"scene-{scene}", [
            str(self.python), "-u", str(RUNNER), str(SCENES / f"{scene}.py"), json.dumps(args)],
            env=env)
        try:
            child.popen.wait(scaled(timeout))
        except Exception:  # noqa: BLE001 - a hung scene fails with its output
            child.stop()
            raise AssertionError(f"scene {scene} did not end within {scaled(timeout)} s:\n"
                                 f"{child.output()[-4000:]}") from None
        output = child.output()
        results = [line for line in output.splitlines() if line.startswith("RESULT ")]
        assert child.popen.returncode == 0 and results, \
            f"scene {scene} failed (exit {child.popen.returncode}):\n{output[-6000:]}"
        result: dict[str, Any] = json.loads(results[-1][len("RESULT "):])
        result["_output"] = output
        return result


@pytest.fixture
def run_scene(slicer_python: Path, processes: Processes) -> SceneRunner:
    return SceneRunner(slicer_python, processes)


@pytest.fixture(scope="module")
def module_run_scene(slicer_python: Path, module_processes: Processes) -> SceneRunner:
    """run_scene for one scene run whose result several tests of a module assert on."""
    return SceneRunner(slicer_python, module_processes)


"""Run SlicerROS2's own unit tests, unchanged, against this project's daemon, in a real
MRML scene.

    sudo .venv/bin/python tools/reference_suite/run.py PATH/TO/ROS2Tests.py

`PATH/TO/ROS2Tests.py` is `Testing/Python/ROS2Tests.py` of rosmed/slicer_ros2_module, as
it is (its code is not part of this project: fetch it yourself). What it runs against:

* 3D Slicer's ``slicer`` module: the real one of the Slicer peer (tools/slicer_core:
  slicer-core's MRML scene, Slicer's OpenIGTLinkIF connector; SLICER_PEER_PREFIX: a peer
  already built), with the ROS2Bridge module loaded and its entry points installed at
  startupCompleted, as Slicer does (tools/slicer_core/session.py); the suite runs in the
  peer's Python, by real_scene.py. Only Qt is imitated (tools/slicer_core/qt_layer.py);
* VTK: the peer's (slicer-core's);
* ROS: a daemon started here, on a ROS domain of its own;
* ``/opt/ros/$ROS_DISTRO/{setup.sh,bin/ros2}``: ros2_cli.py and setup.sh from this folder,
  mounted there in a private mount namespace (so this needs root and ``unshare``; the host's
  /opt is not touched), with turtlesim as tests/peers/turtlesim_node.py and its interfaces
  built from tests/interfaces/turtlesim.

The cases run with unittest's own runner, verbosely; the last line says how many passed,
and the exit code is 0 only if all did (2: the peer cannot be had here).
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import unittest
from pathlib import Path
from typing import List

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
DISTRO = "jazzy"
_IN_NAMESPACE = "SLICER_ROS2_BRIDGE_REFERENCE_SUITE_NS"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("suite", type=Path, help="SlicerROS2's Testing/Python/ROS2Tests.py")
    # Earlier a choice beside a stand-in of `slicer`; the real scene is now the only one.
    parser.add_argument("--real-slicer", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if not args.suite.is_file():
        parser.error(f"expected the reference's ROS2Tests.py, got {args.suite} (no such file)")
    if os.environ.get(_IN_NAMESPACE) != "1":
        return _rerun_in_a_mount_namespace()
    _mount_ros_standin()
    sys.path[:0] = [str(REPO), str(REPO / "tests")]
    from interface_builds import use_test_interfaces  # tests/: the turtlesim interfaces
    use_test_interfaces()
    os.environ.update(ROS_DISTRO=DISTRO, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
                      ROS_DOMAIN_ID=str(random.randint(102, 232)))
    daemon, port = _start_daemon()
    try:
        return _run_in_real_slicer(args.suite, port)
    finally:
        daemon.send_signal(signal.SIGINT)
        daemon.wait(timeout=30)


def _rerun_in_a_mount_namespace() -> int:
    if os.geteuid() != 0 or shutil.which("unshare") is None:
        print("run.py: expected root and unshare (it mounts the ros2 stand-in at /opt/ros in "
              "a private mount namespace), got neither: run it with sudo", file=sys.stderr)
        return 2
    env = dict(os.environ, **{_IN_NAMESPACE: "1"})
    return subprocess.call(["unshare", "--mount", "--propagation", "private",
                            sys.executable, *sys.argv], env=env)


def _mount_ros_standin() -> None:
    """/opt/ros/<distro>/{setup.sh, bin/ros2} in this namespace only (a tmpfs over /opt)."""
    staging = Path(tempfile.mkdtemp(prefix="reference-suite-opt-"))
    root = staging / "ros" / DISTRO
    (root / "bin").mkdir(parents=True)
    (root / "setup.sh").symlink_to(HERE / "setup.sh")
    (root / "bin" / "ros2").symlink_to(HERE / "ros2_cli.py")  # finds the repo through it
    subprocess.run(["mount", "--bind", str(staging), "/opt"], check=True)


def _start_daemon() -> tuple[subprocess.Popen[str], int]:
    port = random.randint(20000, 40000)
    # The daemon of this checkout (`slicer-ros2-bridge` is `python -m bridge.console`).
    daemon = subprocess.Popen([sys.executable, "-u", "-m", "bridge.console", "run",
                               "--port", str(port)], stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT, text=True, cwd=REPO)
    assert daemon.stdout is not None
    for line in daemon.stdout:
        sys.stdout.write(f"[daemon] {line}")
        if "listening on" in line:
            return daemon, port
    raise SystemExit(f"the daemon did not start (exit code {daemon.wait()})")


def _run_in_real_slicer(suite_path: Path, port: int) -> int:
    """The suite in the Slicer peer's Python (real_scene.py), its output passed on."""
    from tools.slicer_core.peer import PeerUnavailableError, peer_python
    try:
        python = peer_python()
    except PeerUnavailableError as error:
        print(f"run.py: the real Slicer core is not available here: {error}", file=sys.stderr)
        return 2
    env = dict(os.environ, PYTHONPATH="")
    return subprocess.call([str(python), "-u", str(HERE / "real_scene.py"), str(suite_path),
                            str(port)], env=env, cwd=REPO)


def run_suite_file(suite_path: Path, where: str = "slicer-ros2-bridge") -> int:
    """Import the suite as it is and run its five classes in its own run()'s order; 0 if
    every case passed. `slicer` is the peer's real one (real_scene.py runs this)."""
    spec = importlib.util.spec_from_file_location("ROS2Tests", suite_path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    logic = module.ROS2TestsLogic
    cases: List[type] = [logic.TestTurtlesimNode, logic.TestCreateAndAddPubSub,
                         logic.TestParameterNode, logic.TestTf2BroadcasterAndLookupNode,
                         logic.TestServiceClient]  # the order of its own run()
    suite = unittest.TestSuite(unittest.TestLoader().loadTestsFromTestCase(case)
                               for case in cases)
    started = time.monotonic()
    result = unittest.TextTestRunner(verbosity=2, stream=sys.stdout).run(suite)
    failed = len(result.failures) + len(result.errors)
    print(f"\nSlicerROS2's unit tests against {where}: "
          f"{result.testsRun - failed} of {result.testsRun} passed "
          f"in {time.monotonic() - started:.1f} s")
    return 0 if result.wasSuccessful() else 1


if __name__ == "__main__":
    sys.exit(main())

"""Test harness shared by the whole suite.

- ROS isolation: this host is shared, so the session gets its own ROS_DOMAIN_ID, discovery
  stays on localhost, rcl logs go to a temporary folder, and so does $XDG_CACHE_HOME. Set
  at import time, before any test module imports rclpy, and inherited by every process a
  test starts.
- `free_port`: a TCP port nobody listens on.
- `processes`: starts a child (the daemon, an rclpy peer) and guarantees it is stopped.
- `module_processes`: the same, shared by the tests of one module.
- `turtlesim_interfaces`: turtlesim's interfaces (not on PyPI) for the children a test
  starts, built once into a cache (interface_builds.py); skips where they cannot be built.
  `turtle_daemon`: a daemon that can use them; `turtlesim`: the node, started as SlicerROS2's
  suite starts it (tests/reference_suite.py).
- every test fails if it leaves a child process of the test runner behind.
- Fast DDS port locks a killed ROS process left taken are released when the session starts
  and after each test's processes are stopped (support.release_left_port_locks).
- property tests (hypothesis) have no per-example deadline.
- tiers: a test that starts processes (the daemon, ROS peers, Debian's C++ examples, a
  build) is marked `integration`; the rest, unit and in-process tests, are the fast tier
  that `make test-fast` runs (`-m "not integration"`).
"""

from __future__ import annotations

import atexit
import fcntl
import os
import random
import shutil
import signal
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING, Iterator

import pytest
from hypothesis import settings

from interface_builds import BuildUnavailable, BuiltInterfaces, use_test_interfaces
from reference_suite import as_the_suite, stop_group
from play_support import NO_ROS_SITECUSTOMIZE
from support import (DOMAIN_BLOCK, DOMAIN_LOCKS, Child, Processes, RunningDaemon,
                     assert_clean_exit, children_of, pick_free_port, release_left_port_locks,
                     scaled, start_daemon)

if TYPE_CHECKING:  # rosbags (the test extra): imported by the player's tests only
    from bags import RobotBag


_DOMAIN_LOCKS: list[object] = []  # the open lock files of this session's domains


def _reserve_domains() -> int:
    """The first of `DOMAIN_BLOCK` ROS domains that no other session of this suite on this
    host uses while this one runs: each session holds an exclusive lock on its block's file
    until it ends (a random pick alone let two concurrent sessions share one domain, one
    time in a hundred). 0 is left alone: other ROS users tend to sit on it."""
    folder = DOMAIN_LOCKS
    folder.mkdir(exist_ok=True)
    firsts = list(range(1, 100 - DOMAIN_BLOCK + 2, DOMAIN_BLOCK))
    random.Random(os.getpid() ^ time.time_ns()).shuffle(firsts)
    for first in firsts:
        handle = open(folder / f"{first}.lock", "w")  # not inherited: children never hold it
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.close()
            continue
        _DOMAIN_LOCKS.append(handle)  # held until this process ends, however it ends
        return first
    raise RuntimeError(f"every block of ROS domains in 1-99 is in use by other sessions of "
                       f"this suite (their locks in {folder})")


_DOMAIN_ID = _reserve_domains()
os.environ["ROS_DOMAIN_ID"] = str(_DOMAIN_ID)
release_left_port_locks()  # an earlier session's killed process must not hang this one
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.pop("ROS_STATIC_PEERS", None)
os.environ["ROS_LOG_DIR"] = tempfile.mkdtemp(prefix="slicer-ros2-bridge-roslog-")
# The robot code keeps the demo package and the meshes it read in $XDG_CACHE_HOME between
# runs: the session keeps its own, so no test meets another run's entries and nothing is
# written in the home folder (pip's cache stays where it was).
os.environ.setdefault("PIP_CACHE_DIR", os.path.join(
    os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "pip"))
os.environ["XDG_CACHE_HOME"] = tempfile.mkdtemp(prefix="slicer-ros2-bridge-cache-")
atexit.register(shutil.rmtree, os.environ["XDG_CACHE_HOME"], True)
os.environ["RCUTILS_LOGGING_BUFFERED_STREAM"] = "0"
os.environ["PYTHONUNBUFFERED"] = "1"

# Property tests: no per-example time limit (hypothesis' default is 200 ms), which a loaded
# machine exceeds without anything being wrong. Loaded before the test modules are, so
# their own @settings inherit it.
settings.register_profile("suite", deadline=None)
settings.load_profile("suite")


def pytest_report_header(config: pytest.Config) -> str:
    return (f"ROS_DOMAIN_ID={_DOMAIN_ID} ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST "
            f"ROS_LOG_DIR={os.environ['ROS_LOG_DIR']}")


# A test that uses one of these starts processes, as does every packaging test (builds,
# installs); a test that starts them otherwise says so itself (`pytest.mark.integration`).
_PROCESS_FIXTURES = frozenset({"processes", "module_processes", "turtlesim_interfaces"})
_PACKAGING = Path(__file__).parent / "packaging"


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item,
                              call: pytest.CallInfo[None]) -> Iterator[pytest.TestReport]:
    """A failed test that used a daemon shows the daemon's last log lines: what it saw
    (a ROS callback failing, a client refused) is often the reason."""
    report: pytest.TestReport = yield
    if report.failed:
        funcargs = getattr(item, "funcargs", {})
        daemon = funcargs.get("daemon")
        child = getattr(daemon, "child", None)
        if isinstance(child, Child):
            report.sections.append(("daemon log, last 60 lines",
                                    "\n".join(child.lines()[-60:])))
    return report


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        fixtures = set(getattr(item, "fixturenames", ()))
        if (fixtures & _PROCESS_FIXTURES or item.get_closest_marker("interop") is not None
                or _PACKAGING in item.path.parents):
            item.add_marker(pytest.mark.integration)


@pytest.fixture
def free_port() -> int:
    return pick_free_port()


@pytest.fixture
def processes(tmp_path: Path) -> Iterator[Processes]:
    manager = Processes(tmp_path)
    try:
        yield manager
    finally:
        manager.stop_all()


@pytest.fixture(scope="module")
def module_processes(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Processes]:
    """Children shared by the tests of one module (a daemon, long-running peers)."""
    manager = Processes(tmp_path_factory.mktemp("module-processes"))
    try:
        yield manager
    finally:
        manager.stop_all()


@pytest.fixture(scope="session")
def turtlesim_interfaces() -> BuiltInterfaces:
    """The `turtlesim` interfaces (tests/interfaces/turtlesim), importable by every process
    started from now on (PYTHONPATH, LD_LIBRARY_PATH, AMENT_PREFIX_PATH), not by this one."""
    try:
        return use_test_interfaces()
    except BuildUnavailable as error:
        pytest.skip(str(error))


@pytest.fixture(scope="module")
def turtle_daemon(turtlesim_interfaces: BuiltInterfaces,
                  module_processes: Processes) -> Iterator[RunningDaemon]:
    """A daemon that can use turtlesim's interfaces (started once they are exported)."""
    running = start_daemon(module_processes)
    yield running
    assert_clean_exit(running)


@pytest.fixture
def turtlesim(processes: Processes) -> Iterator[Child]:
    """`ros2 run turtlesim turtlesim_node` through the suite's shell line, until READY."""
    node = processes.start("turtlesim", ["sh", "-c", as_the_suite("run turtlesim turtlesim_node")])
    try:
        node.wait_for_output("READY", timeout=60)
        yield node
    finally:
        stop_group(node)


@pytest.fixture(autouse=True)
def no_leftover_children() -> Iterator[None]:
    """Fail a test that leaves behind a child it started (module-scoped ones excepted, and
    what they start meanwhile: a module's daemon starts its mesh readers with its first
    robot, and ends them as it ends)."""
    before = frozenset(pid for pid, _, _ in children_of(os.getpid()))
    yield
    # A child that is exiting may take a moment to go.
    deadline = time.monotonic() + scaled(3.0)
    left = [c for c in children_of(os.getpid(), not_under=before) if c[0] not in before]
    while left and time.monotonic() < deadline:
        time.sleep(0.05)
        left = [c for c in children_of(os.getpid(), not_under=before) if c[0] not in before]
    for pid, _, _ in left:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    assert not left, f"the test left child processes behind: {left}"


# --- the player's tests (test_play*.py): no ROS, the demo robot's bag by rosbags ---------

@pytest.fixture(scope="module")
def no_ros(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """The environment of a process where `import rclpy` (and every ROS import) fails."""
    folder = tmp_path_factory.mktemp("no-ros")
    (folder / "sitecustomize.py").write_text(NO_ROS_SITECUSTOMIZE)
    return {"PYTHONPATH": str(folder)}


@pytest.fixture(scope="module")
def demo_files() -> tuple[str, str]:
    """The demo robot's URDF text and its package folder (meshes by --package-path)."""
    from bridge.robots.demo import demo_urdf_path
    from bridge.robots.demo.urdf import DEMO_PACKAGE

    urdf, packages = demo_urdf_path()
    return urdf.read_text(), f"{DEMO_PACKAGE}={packages[DEMO_PACKAGE]}"


@pytest.fixture(scope="module")
def robot_bag(tmp_path_factory: pytest.TempPathFactory,
              demo_files: tuple[str, str]) -> "RobotBag":
    from bags import write_robot_bag

    return write_robot_bag(tmp_path_factory.mktemp("bags") / "robot", demo_files[0])

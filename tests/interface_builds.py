"""Interface packages the tests need that PyPI lacks (turtlesim's, in tests/interfaces/),
built once with `slicer-ros2-bridge build-interfaces --prefix` into a cache keyed by their
sources (.cache/test-interfaces/<hash>/prefix, inside the repository), then made usable by
every child process a test starts.

A process finds packages of a separate prefix only through environment variables read at
its start (the type support libraries are looked up by name on LD_LIBRARY_PATH), so the
test process itself cannot use them: `use_test_interfaces` prepends PYTHONPATH,
LD_LIBRARY_PATH and AMENT_PREFIX_PATH in os.environ, which children inherit.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from bridge.interfaces import (ToolMissingError, check_build_tools, prefix_exports,
                               this_environment, with_exports)

REPO = Path(__file__).resolve().parent.parent
SOURCES = REPO / "tests" / "interfaces"
CACHE = REPO / ".cache" / "test-interfaces"
BUILD_TIMEOUT_S = 1800.0


class BuildUnavailable(Exception):
    """The build cannot run here (no compiler, no cmake, no generators): tests skip."""


@dataclass(frozen=True)
class BuiltInterfaces:
    prefix: Path
    exports: dict[str, str]  # what was prepended to os.environ's path variables
    reused: bool  # found in the cache (no build this session)
    seconds: float  # what making them available took


def sources_digest() -> str:
    """The cache key: the interface sources, and the Python and environment built for."""
    digest = hashlib.sha256()
    for path in sorted(SOURCES.rglob("*")):
        if path.is_file():
            digest.update(str(path.relative_to(SOURCES)).encode())
            digest.update(path.read_bytes())
    digest.update(f"{sys.version}\n{sys.prefix}".encode())
    return digest.hexdigest()[:16]


def build_test_interfaces() -> BuiltInterfaces:
    """The cached build for these sources, building it first if there is none (one cmake
    build per package; another session building the same waits for it, then reuses it)."""
    started = time.monotonic()
    home = CACHE / sources_digest()
    prefix, complete = home / "prefix", home / "complete"
    CACHE.mkdir(parents=True, exist_ok=True)
    with (CACHE / f"{home.name}.lock").open("w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        reused = complete.exists()
        if not reused:
            _build(home, prefix)
            complete.write_text(f"built in {time.monotonic() - started:.0f} s\n")
    return BuiltInterfaces(prefix, prefix_exports(prefix), reused, time.monotonic() - started)


def _build(home: Path, prefix: Path) -> None:
    try:
        check_build_tools(this_environment(prefix))
    except ToolMissingError as error:
        raise BuildUnavailable(f"cannot build the test interfaces ({SOURCES}): {error}") from None
    # A build that died half-way left no `complete` marker: start again from nothing.
    shutil.rmtree(home, ignore_errors=True)
    home.mkdir(parents=True)
    log = home / "build-interfaces.log"
    with log.open("w") as out:
        # --force: a turtlesim importable from elsewhere must not leave the prefix empty.
        result = subprocess.run(
            [sys.executable, "-m", "bridge.cli", "build-interfaces", str(SOURCES), "--force",
             "--prefix", str(prefix), "--build-dir", str(home / "build")],
            cwd=REPO, stdout=out, stderr=subprocess.STDOUT, timeout=BUILD_TIMEOUT_S)
    if result.returncode != 0:
        raise AssertionError(f"building the test interfaces failed (exit code "
                             f"{result.returncode}; {log}):\n{log.read_text()[-4000:]}")
    shutil.rmtree(home / "build")  # its logs are in the output; the objects are not needed


def use_test_interfaces() -> BuiltInterfaces:
    """Build (or reuse) the test interfaces and export them to the children to come."""
    built = build_test_interfaces()
    merged = with_exports(os.environ, built.exports)
    for name in built.exports:
        os.environ[name] = merged[name]
    return built


if __name__ == "__main__":  # what a second session does: tests time it
    found = build_test_interfaces()
    print(f"{'reused' if found.reused else 'built'} {found.prefix} in {found.seconds:.2f} s")

#!/usr/bin/env python3
"""Line coverage of the compiled modules' Cython sources (the .pyx files setup.py builds),
which `make coverage` (Python only) cannot see: `make coverage-native`, and
tests/bridge/test_native_coverage.py, which holds each file to a floor.

1. `build`: the same modules built with Cython's line tracing (setup.py's `traced_modules`)
   into .cache/native-coverage/<digest of their sources>/, once per digest, never in place:
   the production modules stay untraced (tracing costs the lanes several times their time).
2. `measure`: the native modules' own tests (NATIVE_TESTS) run in a child Python under
   coverage with Cython's plugin (Cython.Coverage), each compiled module imported from the
   traced build; it writes which modules it imported, the tests' exit status and each
   .pyx's executable and missed lines as JSON. Code a middleware thread runs is not traced
   (bridge/ros/_rcl_reader.pyx says why), nor run from one here (UNTRACEABLE_FIXTURES).

Usage: python tools/native_coverage.py [pytest arguments; default: default_tests()]
"""

from __future__ import annotations

import fcntl
import hashlib
import importlib.abc
import importlib.machinery
import importlib.util
import json
import os
import shlex
import shutil
import signal
import subprocess
import sys
import sysconfig
from dataclasses import dataclass
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
CACHE = REPO / ".cache" / "native-coverage"
# setup.py's switch to the traced build (its TRACED_BUILD): the directory to build into.
TRACED_BUILD = "SLICER_ROS2_BRIDGE_TRACED_BUILD"
# The compiled modules (setup.py builds each where it can) and the packages that hold them.
EXT_SUFFIX = sysconfig.get_config_var("EXT_SUFFIX")
MODULES = ("bridge.core._native_stream", "bridge.tf._compiled_store", "bridge.ros._rcl_reader")
# The tests that drive them: the lane against the Python path, the compiled tf store
# against the pure Python one, the rcl reader with real publishers.
NATIVE_TESTS = ("tests/bridge/test_native_stream.py", "tests/bridge/test_tf_store_equivalence.py",
                "tests/bridge/test_raw_reader.py", "tests/bridge/test_raw_reader_misuse.py")
# Tests not run against the traced modules: a native lane written from a middleware thread
# (tests/bridge/test_raw_reader.py's lane_reader), where tracing would take the interpreter's
# lock, which that thread must never wait for; there is no tracer in that thread anyway.
UNTRACEABLE_FIXTURES = frozenset({"lane_reader"})
# Left out for time: the two long property tests of the tf store (250 and 200 examples,
# a minute traced); the store's other tests leave 4 more points of it unrun without them.
LONG_TESTS = ("tests/bridge/test_tf_store_equivalence.py::test_both_stores_give_the_same_results",
              "tests/bridge/test_tf_store_equivalence.py::test_a_full_buffer_forgets_alike")


class NativeCoverageUnavailable(Exception):
    """The traced modules cannot be built here (no Cython, C compiler or coverage)."""


@dataclass(frozen=True)
class FileCoverage:
    path: str  # the .pyx's path in the repository, e.g. bridge/core/_native_stream.pyx
    statements: frozenset[int]  # the lines Cython traces
    missing: frozenset[int]

    @property
    def executed(self) -> frozenset[int]:
        return self.statements - self.missing

    @property
    def percent(self) -> float:
        return 100.0 * len(self.executed) / len(self.statements) if self.statements else 0.0


@dataclass(frozen=True)
class Measured:
    exit_status: int  # the tests' (pytest's)
    modules: dict[str, str]  # each compiled module the tests imported -> its file
    files: dict[str, FileCoverage]
    log: Path  # the tests' output


def sources() -> list[Path]:
    """What the traced build is made from: the compiled modules' sources and setup.py."""
    found = [REPO / "setup.py"]
    for pattern in ("*.pyx", "*.pxd", "*.h"):
        found += (REPO / "bridge").rglob(pattern)
    return sorted(found)


def digest() -> str:
    """Of the sources, Cython's version and this Python's ABI: a build's cache key."""
    from importlib.metadata import version

    h = hashlib.sha256(f"{version('Cython')} {EXT_SUFFIX} "
                       f"{sys.version}".encode())
    for path in sources():
        h.update(str(path.relative_to(REPO)).encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()[:16]


def build() -> Path:
    """The traced modules' directory (a package tree: bridge/core/_native_stream.*.so beside
    its .pyx copy and .c), built when it is not there for these sources."""
    try:
        import Cython  # noqa: F401
        import Cython.Coverage  # noqa: F401  (needs coverage's C tracer)
    except ImportError as error:
        raise NativeCoverageUnavailable(
            f"Cython with coverage's plugin support: {error}") from error
    compiler = shlex.split(sysconfig.get_config_var("CC") or "cc")[0]
    if shutil.which(compiler) is None:
        raise NativeCoverageUnavailable(f"no C compiler: {compiler!r} is not on PATH")
    out = CACHE / digest()
    out.parent.mkdir(parents=True, exist_ok=True)
    # One build at a time per digest (concurrent test sessions); "built" is written last,
    # so a build cut short is made again. In place, not renamed after: the C files name the
    # sources by this path, relative to the repository, as the measured run resolves them.
    with open(out.parent / f"{out.name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if (out / "built").is_file():
            return out
        shutil.rmtree(out, ignore_errors=True)
        out.mkdir()
        env = {**os.environ, TRACED_BUILD: str(out.relative_to(REPO))}
        result = subprocess.run([sys.executable, "setup.py", "-q", "build_ext", "--build-lib",
                                 str(out), "--build-temp", str(out / "temp"), "--parallel",
                                 "2"], cwd=REPO, env=env, capture_output=True, text=True)
        if result.returncode != 0:
            raise RuntimeError(f"the traced build failed ({result.returncode}):\n"
                               f"{result.stderr[-4000:]}")
        shutil.rmtree(out / "temp", ignore_errors=True)
        (out / "built").write_text(" ".join(built_modules(out)) + "\n")
    _forget_other_builds(out)
    return out


def _forget_other_builds(kept: Path) -> None:
    """Earlier sources' builds (about 10 MB each) that no run is using."""
    for lock_file in kept.parent.glob("*.lock"):
        other = lock_file.with_suffix("")
        if other == kept:
            continue
        with open(lock_file, "w") as lock:
            try:
                fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                continue  # being built now
            shutil.rmtree(other, ignore_errors=True)
            lock_file.unlink()


def built_modules(tree: Path) -> list[str]:
    """The compiled modules present in ``tree`` (setup.py skips one it cannot build)."""
    return [name for name in MODULES if (tree / (name.replace(".", "/") + EXT_SUFFIX)).is_file()]


def default_tests() -> list[str]:
    """pytest's arguments for the native modules' tests, as the coverage run takes them."""
    return [*NATIVE_TESTS, *(f"--deselect={test}" for test in LONG_TESTS)]


def measure(tree: Path, pytest_args: list[str], out: Path,
            timeout: float | None = None) -> Measured:
    """The tests in ``pytest_args`` run against the traced modules of ``tree`` under
    coverage, in a child Python (cwd: the repository); their report in ``out``. A run past
    ``timeout`` seconds is stopped with the processes it started (subprocess.TimeoutExpired)."""
    out.mkdir(parents=True, exist_ok=True)
    log = out / "pytest.log"
    env = dict(os.environ)
    # Not measured twice: `make coverage` hands its configuration to every child Python.
    for name in ("COVERAGE_PROCESS_START", "COVERAGE_PROCESS_CONFIG"):
        env.pop(name, None)
    (out / "report.json").unlink(missing_ok=True)
    with open(log, "w") as output:
        child = subprocess.Popen([sys.executable, str(Path(__file__).resolve()), "--inner",
                                  str(tree.resolve()), str(out), "--", *pytest_args],
                                 cwd=REPO, env=env, stdout=output, stderr=subprocess.STDOUT,
                                 start_new_session=True)
        try:
            child.wait(timeout)
        except subprocess.TimeoutExpired:
            os.killpg(child.pid, signal.SIGKILL)
            child.wait()
            raise
    report_file = out / "report.json"
    if not report_file.is_file():
        raise RuntimeError(f"the measured run wrote no report; its output:\n"
                           f"{log.read_text()[-4000:]}")
    report = json.loads(report_file.read_text())
    files = {path: FileCoverage(path, frozenset(lines["statements"]),
                                frozenset(lines["missing"]))
             for path, lines in report["files"].items()}
    return Measured(report["exit_status"], report["modules"], files, log)


class _TracedFinder(importlib.abc.MetaPathFinder):
    """Imports each compiled module from the traced tree, before its package's folder (a
    package's __init__ may import it, as bridge/tf's does)."""

    def __init__(self, tree: Path) -> None:
        self._files = {name: tree / (name.replace(".", "/") + EXT_SUFFIX)
                       for name in built_modules(tree)}

    def find_spec(self, fullname: str, path: object = None,
                  target: object = None) -> importlib.machinery.ModuleSpec | None:
        file = self._files.get(fullname)
        return importlib.util.spec_from_file_location(fullname, file) if file else None


class _Untraceable:
    """Deselects the tests of UNTRACEABLE_FIXTURES."""

    def pytest_collection_modifyitems(self, config: Any, items: list[Any]) -> None:
        kept = [item for item in items
                if not UNTRACEABLE_FIXTURES & set(getattr(item, "fixturenames", ()))]
        config.hook.pytest_deselected(items=[item for item in items if item not in kept])
        items[:] = kept


def _inner(tree: Path, out: Path, pytest_args: list[str]) -> None:
    """In the child: the traced modules first, coverage on, the tests, the report."""
    import coverage

    sys.path.insert(0, str(REPO))
    sys.meta_path.insert(0, _TracedFinder(tree))
    cov = coverage.Coverage(data_file=str(out / ".coverage"), config_file=False,
                            include=[f"{tree.resolve()}/*"])
    cov.set_option("run:plugins", ["Cython.Coverage"])
    cov.set_option("report:exclude_lines", ["pragma: no cover"])
    cov.start()
    import pytest

    status = pytest.main(["-p", "no:cacheprovider", *pytest_args], plugins=[_Untraceable()])
    cov.stop()
    cov.save()
    files = {}
    measured = {Path(name) for name in cov.get_data().measured_files()}
    # A module never imported has no tracer record: coverage would read its .pyx as Python.
    for pyx in sorted(path for path in tree.resolve().rglob("*.pyx") if path in measured):
        _, statements, _, missing, _ = cov.analysis2(str(pyx))
        files[str(pyx.relative_to(tree.resolve()))] = {"statements": sorted(statements),
                                             "missing": sorted(missing)}
    modules = {name: getattr(sys.modules[name], "__file__", "") for name in MODULES
               if name in sys.modules}
    (out / "report.json").write_text(json.dumps({"exit_status": int(status),
                                                 "modules": modules, "files": files}))


def ranges(lines: frozenset[int]) -> str:
    """``1-3, 7``: lines as coverage's report lists them."""
    spans: list[list[int]] = []
    for line in sorted(lines):
        if spans and spans[-1][1] == line - 1:
            spans[-1][1] = line
        else:
            spans.append([line, line])
    return ", ".join(str(a) if a == b else f"{a}-{b}" for a, b in spans)


def main(argv: list[str]) -> int:
    if argv[:1] == ["--inner"]:
        _inner(Path(argv[1]), Path(argv[2]), argv[4:])
        return 0
    try:
        tree = build()
    except NativeCoverageUnavailable as error:
        print(f"native coverage: not measured here: {error}", file=sys.stderr)
        return 1
    measured = measure(tree, argv or default_tests(), CACHE / "last-run")
    print(measured.log.read_text().rstrip().splitlines()[-1])
    print(f"{'Name':<36} {'Stmts':>6} {'Miss':>6} {'Cover':>6}   Missing")
    for path, file in sorted(measured.files.items()):
        print(f"{path:<36} {len(file.statements):>6} {len(file.missing):>6} "
              f"{file.percent:>5.0f}%   {ranges(file.missing)}")
    for name in MODULES:
        if name not in measured.modules:
            print(f"{name}: not imported by these tests", file=sys.stderr)
    return measured.exit_status


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

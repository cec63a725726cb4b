"""Build ROS 2 interface packages into an environment made of the ROS 2 PyPI wheels.

One package is: configure (cmake), build and install (make install), then a check in a fresh
interpreter of the environment that its messages import and serialize. Packages are built
dependencies first, up to `parallel` independent ones at once, each step reporting progress
(steps.py). `slicer-ros2-bridge build-interfaces` and tools/setup_env.py both call
`build_interfaces`. Standard library only.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import sysconfig
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

from bridge.interfaces.errors import StepFailedError, ToolMissingError
from bridge.interfaces.packages import InterfacePackage, order_packages
from bridge.interfaces.steps import (RunningStep, Say, Step, last_line, make_progress,
                                     wait_a_moment)

MIN_CMAKE = (3, 20)
# Included after the package's project(): removes what the wheels' CMake exports name but
# this machine lacks (see the file). Any package, not only ours, needs it.
WHEEL_FIXUPS = Path(__file__).resolve().parent / "wheel_fixups.cmake"
# Variables a process needs to use packages installed into a prefix outside its environment.
PATH_VARIABLES = ("PYTHONPATH", "LD_LIBRARY_PATH", "AMENT_PREFIX_PATH")


@dataclass(frozen=True)
class Target:
    """Where packages go: `python`'s environment (`env_prefix`, whose ROS wheels provide the
    generators), installed into it or into a separate `install_prefix`."""

    python: Path
    env_prefix: Path
    install_prefix: Path
    exports: Mapping[str, str] = field(default_factory=dict)  # PATH_VARIABLES to prepend

    def child_env(self) -> dict[str, str]:
        env = with_exports(os.environ, self.exports)
        # A Python of this environment must bootstrap its own library path, even when the
        # caller is a Python of another environment that has already done so.
        env.pop("_ROS_WHEELS_BOOTSTRAP_COMPLETE", None)
        env["PATH"] = os.pathsep.join([str(self.python.parent), env.get("PATH", "")])
        # ament's CMake looks up type supports and generators here, and only here when set.
        env["AMENT_PREFIX_PATH"] = os.pathsep.join(map(str, self.search_prefixes()))
        return env

    def search_prefixes(self) -> list[Path]:
        """Where dependencies are looked for: the install prefix, the environment, and a
        sourced ROS install's AMENT_PREFIX_PATH."""
        found: list[Path] = []
        sourced = os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)
        for prefix in [self.install_prefix, self.env_prefix, *map(Path, filter(None, sourced))]:
            if prefix not in found:
                found.append(prefix)
        return found


def this_environment(prefix: Path | None = None) -> Target:
    """This interpreter's environment as the target, installing into it or into `prefix`."""
    here = Path(sys.prefix)
    if prefix is None or prefix.resolve() == here.resolve():
        return Target(Path(sys.executable), here, here)
    prefix = prefix.resolve()
    return Target(Path(sys.executable), here, prefix, prefix_exports(prefix))


def prefix_exports(prefix: Path) -> dict[str, str]:
    """What to prepend to PATH_VARIABLES so that this interpreter (and its children) can use
    packages built into `prefix`: the Python modules, their libraries (the type support
    dispatch finds them by name on LD_LIBRARY_PATH), and the ament index entries."""
    site = sysconfig.get_path("purelib", vars={"base": str(prefix), "platbase": str(prefix)})
    return {"PYTHONPATH": site, "LD_LIBRARY_PATH": str(prefix / "lib"),
            "AMENT_PREFIX_PATH": str(prefix)}


def with_exports(env: Mapping[str, str], exports: Mapping[str, str]) -> dict[str, str]:
    """`env` with each of `exports` put first on its path variable (once)."""
    merged = dict(env)
    for name, value in exports.items():
        rest = [part for part in merged.get(name, "").split(os.pathsep) if part and part != value]
        merged[name] = os.pathsep.join([value, *rest])
    return merged


@dataclass(frozen=True)
class Plan:
    order: list[InterfacePackage]  # dependencies first
    skip: dict[str, str]  # importable already (not forced): name -> where from

    @property
    def to_build(self) -> list[InterfacePackage]:
        return [p for p in self.order if p.name not in self.skip]


def plan_build(packages: Sequence[InterfacePackage], target: Target, *,
               force: bool) -> Plan:
    """Order `packages` and find those the environment has already. Raises the
    `InputError`s (a missing dependency, a cycle) before anything is built."""
    names = sorted({p.name for p in packages} | {d for p in packages for d in p.depends})
    importable = _importable(target, names)
    indexed = {name for name in names
               if any((prefix / "share" / "ament_index" / "resource_index" / "packages" /
                       name).is_file() for prefix in target.search_prefixes())}
    order = order_packages(packages, lambda name: name in importable or name in indexed)
    skip = {} if force else {p.name: importable[p.name] for p in order if p.name in importable}
    return Plan(order, skip)


_PROBE = """\
import importlib.util, json, os, sys
if sys.path and sys.path[0] in ("", os.getcwd()):
    sys.path.pop(0)  # not the folder we happen to run in
found = {}
for name in sys.argv[1:]:
    spec = importlib.util.find_spec(name)
    if spec is not None and spec.origin:  # a folder of that name alone does not count
        found[name] = os.path.dirname(spec.origin)
print(json.dumps(found))
"""


def _importable(target: Target, names: Sequence[str]) -> dict[str, str]:
    """Which of `names` the target's Python can import, and from where."""
    candidates = [n for n in names if n.isidentifier()]
    result = subprocess.run([str(target.python), "-c", _PROBE, *candidates],
                            capture_output=True, text=True, env=target.child_env(), timeout=120)
    if result.returncode != 0:
        raise ToolMissingError(f"expected {target.python} to run, got exit code "
                               f"{result.returncode}: {result.stderr.strip()[-500:]}")
    found: dict[str, str] = json.loads(result.stdout.strip().splitlines()[-1])
    return found


def cmake_version(cmake: str) -> tuple[int, ...] | None:
    try:
        out = subprocess.run([cmake, "--version"], capture_output=True, text=True,
                             check=True, timeout=60).stdout
    except (OSError, subprocess.SubprocessError):
        return None
    found = re.search(r"(\d+)\.(\d+)", out)
    return tuple(int(part) for part in found.groups()) if found else None


def find_cmake(target: Target) -> str | None:
    """A cmake >= MIN_CMAKE: the system's, or the cmake wheel's in the environment."""
    candidates = [shutil.which("cmake"), str(target.env_prefix / "bin" / "cmake")]
    for cmake in candidates:
        if cmake and (cmake_version(cmake) or (0,)) >= MIN_CMAKE:
            return cmake
    return None


def missing_build_tools() -> list[str]:
    """The compilers and make that are not on PATH."""
    return [tool for tool in ("cc", "c++", "make") if shutil.which(tool) is None]


def check_build_tools(target: Target) -> str:
    """Everything a build needs, before it starts; returns the cmake to use."""
    missing = missing_build_tools()
    if missing:
        raise ToolMissingError(f"expected the build tools cc, c++ and make on PATH, got none "
                               f"for {', '.join(missing)} (on Debian: apt-get install "
                               f"build-essential)")
    cmake = find_cmake(target)
    if cmake is None:
        wanted = ".".join(map(str, MIN_CMAKE))
        raise ToolMissingError(f"expected cmake >= {wanted} on PATH or in {target.env_prefix}"
                               f"/bin, got {shutil.which('cmake') or 'none'}: pip install cmake")
    if not any((prefix / "share" / "rosidl_default_generators").is_dir()
               for prefix in target.search_prefixes()):
        raise ToolMissingError(f"expected the ROS interface generators in {target.env_prefix}, "
                               f"got none: pip install 'slicer-ros2-bridge[interfaces]' (the "
                               f"ROS 2 wheels of rosidl_default_generators and ament_cmake)")
    return cmake


_IMPORT_CHECK = """\
import importlib, sys
from rclpy.serialization import deserialize_message, serialize_message
from rclpy.type_support import check_for_type_support
PARTS = ("Request", "Response", "Goal", "Result", "Feedback")
checked = 0
for name in sys.argv[1:]:
    for interface in [v for v in vars(importlib.import_module(name)).values()
                      if isinstance(v, type) and hasattr(type(v), "_TYPE_SUPPORT")]:
        check_for_type_support(interface)
        for message in [getattr(interface, p) for p in PARTS if hasattr(interface, p)] or [
                interface]:
            check_for_type_support(message)
            if deserialize_message(serialize_message(message()), message) != message():
                sys.exit(f"{name}.{message.__name__} does not survive serialization")
        checked += 1
print(f"{checked} types import and serialize")
"""


def package_steps(package: InterfacePackage, tag: str, target: Target, *, cmake: str,
                  build_dir: Path, jobs: int) -> list[Step]:
    """Configure, build and install, check: the commands for one package, with their logs."""
    env = target.child_env()
    prefixes = ";".join(str(p) for p in target.search_prefixes())
    modules = [f"{package.name}.{kind}" for kind in package.kinds()] or [package.name]
    return [
        Step(f"{tag}: configuring (cmake)",
             [cmake, str(package.path), f"-DCMAKE_INSTALL_PREFIX={target.install_prefix}",
              f"-DCMAKE_PREFIX_PATH={prefixes}", f"-DPython3_EXECUTABLE={target.python}",
              f"-DCMAKE_PROJECT_INCLUDE={WHEEL_FIXUPS}", "-DBUILD_TESTING=OFF"],
             build_dir, build_dir / "configure.log", env),
        Step(f"{tag}: building and installing (make -j{jobs} install)",
             ["make", f"-j{jobs}", "install"], build_dir, build_dir / "build.log", env,
             where=make_progress),
        Step(f"{tag}: checking that {', '.join(modules)} import in a fresh interpreter",
             [str(target.python), "-c", _IMPORT_CHECK, *modules], build_dir,
             build_dir / "import-check.log", env),
    ]


@dataclass
class _Building:
    package: InterfacePackage
    running: RunningStep
    rest: list[Step]


def build_interfaces(packages: Sequence[InterfacePackage], target: Target, *, force: bool,
                     build_root: Path, say: Say, parallel: int = 1) -> list[str]:
    """Build `packages` into `target`, dependencies first, up to `parallel` at once; returns
    the names built. Input errors come before anything is built; a failed step raises
    `StepFailedError` once the other packages' running steps have ended (nothing is left
    half-installed)."""
    plan = plan_build(packages, target, force=force)
    total = len(plan.order)
    tags = {p.name: f"[{i}/{total}] {p.name}" for i, p in enumerate(plan.order, 1)}
    for name, where in plan.skip.items():
        say(f"{tags[name]}: importable already ({where}), skipped")
    todo = plan.to_build
    if not todo:
        return []
    cmake = check_build_tools(target)
    jobs = max(1, min(4, os.cpu_count() or 1))
    building = {p.name for p in todo}
    finished: set[str] = set()
    running: list[_Building] = []
    failure: StepFailedError | None = None
    try:
        while todo or running:
            for package in list(todo):
                if failure is not None or len(running) >= parallel:
                    break
                if all(d in finished for d in package.depends if d in building):
                    todo.remove(package)
                    build_dir = build_root / package.name
                    # From scratch: a CMake cache of an older source or layout would refuse it.
                    shutil.rmtree(build_dir, ignore_errors=True)
                    build_dir.mkdir(parents=True)
                    steps = package_steps(package, tags[package.name], target, cmake=cmake,
                                          build_dir=build_dir, jobs=jobs)
                    running.append(_Building(package, RunningStep(steps[0], say).start(),
                                             steps[1:]))
            for entry in list(running):
                try:
                    took = entry.running.check()
                except StepFailedError as error:
                    running.remove(entry)
                    if failure is None:
                        failure = error
                        todo.clear()
                        if running:
                            say(f"{tags[entry.package.name]} failed: letting the running steps "
                                f"of {', '.join(e.package.name for e in running)} end")
                    continue
                if took is None:
                    continue
                running.remove(entry)
                if entry.rest and failure is None:
                    next_step, *rest = entry.rest
                    running.append(_Building(entry.package, RunningStep(next_step, say).start(),
                                             rest))
                elif not entry.rest:
                    finished.add(entry.package.name)
                    checked = last_line(entry.running.step.log.read_text(errors="replace"))
                    say(f"{tags[entry.package.name]}: built and installed; {checked}")
            if running:
                wait_a_moment()
    except BaseException:  # interrupted: nothing of ours runs on
        for entry in running:
            entry.running.stop()
        raise
    if failure is not None:
        raise failure
    return [p.name for p in plan.order if p.name in finished]


def describe_exports(exports: Mapping[str, str]) -> str:
    """Shell lines that make packages built into a separate prefix usable."""
    return "\n".join(f'export {name}="{value}${{{name}:+:${name}}}"'
                     for name, value in exports.items())

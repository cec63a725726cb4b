"""ROS interface packages the daemon needs that have no PyPI wheel, and how to build them.

`tf2_msgs` (TFMessage, TF2Error) and `control_msgs` (FollowJointTrajectory and the rest of
ros2_control's interfaces, for the demo arm's trajectory action) ship here as their upstream
definitions (control_msgs/README.md says which release). A ROS 2 install
from apt has it already; an environment made of PyPI wheels gets it built into itself
with CMake and the ROS interface generators (the `interfaces` extra), by `make setup`
(tools/setup_env.py) in a clone, or by `slicer-ros2-bridge build-interfaces` after
`pip install slicer-ros2-bridge[interfaces]`.

No ROS import here: this runs before ROS is known to be importable.
"""

from __future__ import annotations

import importlib.util
import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

__all__ = ["MIN_CMAKE", "InterfaceBuildError", "build_steps", "cmake_version",
           "interface_packages", "missing_interfaces", "missing_runtime_line"]

INTERFACES_DIR = Path(__file__).resolve().parent
MIN_CMAKE = (3, 20)


class InterfaceBuildError(Exception):
    """A build step failed or a tool is missing; the text says which and what to do."""


@dataclass(frozen=True)
class BuildStep:
    argv: list[str]
    cwd: Path
    log: Path


# Built in this order (a package may depend on one built before it); any other shipped
# package comes after these, by name.
BUILD_ORDER = ("tf2_msgs", "control_msgs")
# What the daemon cannot run without.
REQUIRED = ("tf2_msgs",)


def interface_packages() -> list[Path]:
    """The interface package folders shipped here (each has a package.xml), in build order."""
    found = [p for p in INTERFACES_DIR.iterdir() if (p / "package.xml").is_file()]
    rank = {name: i for i, name in enumerate(BUILD_ORDER)}
    return sorted(found, key=lambda p: (rank.get(p.name, len(rank)), p.name))


def missing_interfaces() -> list[str]:
    """The shipped interface packages this Python cannot import."""
    return [p.name for p in interface_packages() if importlib.util.find_spec(p.name) is None]


def missing_runtime_line() -> str | None:
    """One line saying what the daemon lacks in this environment and how to get it, or None.

    Checked before the daemon imports ROS, so that a wheel installed without ROS, or
    without tf2_msgs, says so instead of showing a traceback.
    """
    if importlib.util.find_spec("rclpy") is None:
        return ("rclpy is not installed in this environment: the daemon needs ROS 2 Jazzy. "
                "Install this package with its dependencies (pip install slicer-ros2-bridge "
                "brings the ROS 2 wheels), or run it with a sourced ROS 2 Jazzy install.")
    # control_msgs serves the demo arm's trajectory controller only: the daemon runs without.
    missing = [name for name in missing_interfaces() if name in REQUIRED]
    if missing:
        return (f"{', '.join(missing)} is not installed in this environment (it has no PyPI "
                f"wheel). Build it into this environment with `pip install "
                f"'slicer-ros2-bridge[interfaces]' && slicer-ros2-bridge build-interfaces` "
                f"(needs a C/C++ compiler and make), or source a ROS 2 install that has it.")
    return None


def cmake_version(cmake: str) -> tuple[int, ...] | None:
    try:
        out = subprocess.run([cmake, "--version"], capture_output=True, text=True,
                             check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return None
    found = re.search(r"(\d+)\.(\d+)", out)
    return tuple(int(part) for part in found.groups()) if found else None


def build_steps(package: Path, *, build_dir: Path, prefix: Path, python: str,
                cmake: str) -> list[BuildStep]:
    """Configure and install one interface package into `prefix` (an environment whose
    ROS wheels provide the generators), as commands with their logs."""
    jobs = str(max(1, min(4, os.cpu_count() or 1)))
    return [
        BuildStep([cmake, str(package), f"-DCMAKE_INSTALL_PREFIX={prefix}",
                   f"-DCMAKE_PREFIX_PATH={prefix}", f"-DPython3_EXECUTABLE={python}",
                   "-DBUILD_TESTING=OFF"], build_dir, build_dir / "configure.log"),
        BuildStep(["make", f"-j{jobs}", "install"], build_dir, build_dir / "build.log"),
    ]


def build_into_this_environment(build_root: Path) -> list[str]:
    """Build every missing interface package into `sys.prefix`; returns the names built.
    Raises `InterfaceBuildError` naming the missing tool or the failed step's log."""
    cmake = shutil.which("cmake")
    if cmake is None or (cmake_version(cmake) or (0,)) < MIN_CMAKE:
        raise InterfaceBuildError(
            f"expected cmake >= {'.'.join(map(str, MIN_CMAKE))}, got "
            f"{'none' if cmake is None else cmake}: pip install cmake (or your system's)")
    for tool in ("cc", "c++", "make"):
        if shutil.which(tool) is None:
            raise InterfaceBuildError(f"expected the build tool {tool!r} on PATH, got none "
                                      f"(on Debian: apt-get install build-essential)")
    built = []
    for package in interface_packages():
        if importlib.util.find_spec(package.name) is not None:
            continue
        build_dir = build_root / package.name
        build_dir.mkdir(parents=True, exist_ok=True)
        for step in build_steps(package, build_dir=build_dir, prefix=Path(sys.prefix),
                                python=sys.executable, cmake=cmake):
            with step.log.open("w") as out:
                result = subprocess.run(step.argv, cwd=step.cwd, stdout=out,
                                        stderr=subprocess.STDOUT)
            if result.returncode != 0:
                tail = "\n".join(step.log.read_text(errors="replace").splitlines()[-15:])
                raise InterfaceBuildError(f"building {package.name} failed: {' '.join(step.argv)}"
                                          f" exited with {result.returncode} (log: {step.log})"
                                          f"\n{tail}")
        built.append(package.name)
    return built

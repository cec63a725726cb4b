"""ROS interface packages: the ones the daemon needs that have no PyPI wheel, and building
any interface package into an environment made of the ROS 2 PyPI wheels.

`tf2_msgs` (TFMessage, TF2Error) and `control_msgs` (FollowJointTrajectory and the rest of
ros2_control's interfaces, for the demo arm's trajectory action) ship here as their upstream
definitions (control_msgs/README.md says which release). A ROS 2 install from apt has them
already; an environment made of PyPI wheels gets them built into itself with CMake and the
ROS interface generators (the `interfaces` extra), by `make setup` (tools/setup_env.py) in a
clone, or by `slicer-ros2-bridge build-interfaces` after `pip install
slicer-ros2-bridge[interfaces]`. The same command builds a user's own packages (build.py).

No ROS import here: this runs before ROS is known to be importable, and with any Python
(tools/setup_env.py).
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

from bridge.interfaces.build import (MIN_CMAKE, Target, build_interfaces, check_build_tools,
                                     cmake_version, describe_exports, find_cmake,
                                     missing_build_tools, prefix_exports, this_environment,
                                     with_exports)
from bridge.interfaces.errors import (DependencyCycleError, InputError, InterfaceBuildError,
                                      MissingDependencyError, PackageError, StepFailedError,
                                      ToolMissingError)
from bridge.interfaces.packages import InterfacePackage, find_packages, read_package
from bridge.interfaces.steps import Step, compile_progress, last_line, pip_progress, run_step

__all__ = ["INTERFACES_DIR", "MIN_CMAKE", "DependencyCycleError", "InputError",
           "InterfaceBuildError", "InterfacePackage", "MissingDependencyError", "PackageError",
           "Step", "StepFailedError", "Target", "ToolMissingError", "build_interfaces",
           "check_build_tools", "cmake_version", "compile_progress", "describe_exports",
           "find_cmake",
           "find_packages", "interface_packages", "last_line", "missing_build_tools",
           "missing_interfaces", "missing_runtime_line", "pip_progress", "prefix_exports",
           "read_package",
           "run_step", "shipped_packages", "this_environment", "with_exports"]

INTERFACES_DIR = Path(__file__).resolve().parent


# Started in this order (what the daemon needs before what the demo needs); the build
# orders by package.xml dependencies first.
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


def shipped_packages() -> list[InterfacePackage]:
    """The interface packages shipped here, read, in BUILD_ORDER."""
    return [read_package(folder) for folder in interface_packages()]

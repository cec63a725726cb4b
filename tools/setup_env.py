#!/usr/bin/env python3
"""Build the project's environment in `.venv` inside the repository, in one step.

What it does, printing each step:
  1. checks the tools it needs (C/C++ compiler, make, Python headers, cmake >= 3.20 or the
     cmake wheel from PyPI in its place);
  2. creates `.venv` and installs the project with its pinned dependencies (ROS 2 Jazzy from
     PyPI wheels, test tools, interface build tools);
  3. builds the `tf2_msgs` and `control_msgs` interface packages (bridge/interfaces/) into
     the venv, because they have no PyPI wheel.

It needs no root and writes nothing outside the repository (pip's cache and temporary files
go to `.cache/`). A second run that finds a stamp matching the inputs returns in a moment.
Run it with any Python >= 3.10: `python3 tools/setup_env.py` (what `make setup` does).
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import sysconfig
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
# How to build the interfaces is the package's own knowledge (the CLI's build-interfaces
# uses it too); it imports nothing but the standard library.
from bridge.interfaces import (INTERFACES_DIR, MIN_CMAKE, build_steps,  # noqa: E402
                               cmake_version, interface_packages)

VENV = REPO / ".venv"
CACHE = REPO / ".cache"
BUILD = REPO / "build"
STAMP = VENV / ".slicer-ros2-bridge-setup"
CMAKE_WHEEL = "cmake==3.31.6"
# The ROS wheels are built for these CPython versions only.
SUPPORTED_PYTHONS = ((3, 10), (3, 11), (3, 12), (3, 13))
# Inputs whose change means the environment must be rebuilt (the install builds the compiled
# tf store from its .pyx, so an edit of it is one).
STAMP_INPUTS = ("pyproject.toml", "setup.py", "tools/setup_env.py",
                "bridge/tf/_compiled_store.pyx")


class SetupError(Exception):
    """A precondition is missing; the message names it and how to get it."""


def say(text: str) -> None:
    print(f"[setup] {text}", flush=True)


def venv_python() -> Path:
    return VENV / "bin" / "python"


def inputs_digest() -> str:
    digest = hashlib.sha256()
    for name in STAMP_INPUTS:
        digest.update(name.encode())
        digest.update((REPO / name).read_bytes())
    for path in sorted(INTERFACES_DIR.rglob("*")):
        if path.is_file():
            digest.update(str(path.relative_to(REPO)).encode())
            digest.update(path.read_bytes())
    digest.update(sys.version.encode())
    return digest.hexdigest()


def child_env() -> dict[str, str]:
    """Environment for the tools we start: caches inside the repo, no leaked ROS bootstrap."""
    env = dict(os.environ)
    # A Python started from another ROS venv would skip this venv's library-path bootstrap.
    env.pop("_ROS_WHEELS_BOOTSTRAP_COMPLETE", None)
    env.pop("PYTHONHOME", None)
    env["PIP_CACHE_DIR"] = str(CACHE / "pip")
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    env["TMPDIR"] = str(CACHE / "tmp")
    env["PATH"] = f"{VENV / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    return env


def run(cmd: list[str], *, cwd: Path = REPO, log: Path | None = None) -> None:
    """Run a command; on failure show the tail of its output and raise."""
    started = time.monotonic()
    if log is None:
        result = subprocess.run(cmd, cwd=cwd, env=child_env())
        failed = result.returncode != 0
        tail = ""
    else:
        with log.open("w") as out:
            result = subprocess.run(cmd, cwd=cwd, env=child_env(), stdout=out,
                                    stderr=subprocess.STDOUT)
        failed = result.returncode != 0
        tail = "\n".join(log.read_text(errors="replace").splitlines()[-30:])
    if failed:
        where = f" (full log: {log})" if log else ""
        raise SetupError(f"command failed with exit code {result.returncode}{where}: "
                         f"{' '.join(cmd)}\n{tail}")
    say(f"  done in {time.monotonic() - started:.1f} s")


def check_python() -> None:
    if sys.version_info[:2] not in SUPPORTED_PYTHONS:
        wanted = ", ".join(f"{a}.{b}" for a, b in SUPPORTED_PYTHONS)
        raise SetupError(f"Python {wanted} is needed (the ROS 2 Jazzy wheels exist only for "
                         f"those); this is {sys.version.split()[0]} at {sys.executable}")
    try:
        import venv  # noqa: F401
        import ensurepip  # noqa: F401
    except ImportError as error:
        raise SetupError(f"Python's venv/ensurepip module is missing ({error}); on Debian: "
                         f"apt-get install python3-venv") from None


def check_build_tools() -> None:
    missing = [tool for tool in ("cc", "c++", "make") if shutil.which(tool) is None]
    if missing:
        raise SetupError(f"missing build tool(s): {', '.join(missing)} (needed to build the "
                         f"tf2_msgs interfaces); on Debian: apt-get install build-essential")
    header = Path(sysconfig.get_paths()["include"]) / "Python.h"
    if not header.exists():
        raise SetupError(f"Python headers not found (expected {header}); on Debian: "
                         f"apt-get install python3-dev")


def ensure_cmake() -> str:
    """A cmake >= 3.20: the system's, or else the cmake wheel installed into the venv."""
    venv_cmake = VENV / "bin" / "cmake"
    for candidate in (shutil.which("cmake"), str(venv_cmake) if venv_cmake.exists() else None):
        if candidate and (cmake_version(candidate) or (0,)) >= MIN_CMAKE:
            return candidate
    say(f"cmake >= {'.'.join(map(str, MIN_CMAKE))} not found: installing {CMAKE_WHEEL} "
        f"into the venv")
    run([str(venv_python()), "-m", "pip", "install", CMAKE_WHEEL], log=CACHE / "pip-cmake.log")
    if (cmake_version(str(venv_cmake)) or (0,)) < MIN_CMAKE:
        raise SetupError(f"cmake from the {CMAKE_WHEEL} wheel does not run: {venv_cmake}")
    return str(venv_cmake)


def create_venv() -> None:
    if venv_python().exists():
        say(f"venv exists: {VENV}")
        return
    say(f"creating venv {VENV} with {sys.executable}")
    run([sys.executable, "-m", "venv", str(VENV)])


def install_project() -> None:
    say("installing the project and its pinned dependencies (ROS 2 Jazzy wheels, "
        "pyigtl, numpy, yourdfpy, trimesh, test and interface-build tools)")
    run([str(venv_python()), "-m", "pip", "install", "-e", f"{REPO}[test,interfaces]"],
        log=CACHE / "pip-install.log")


def build_interfaces(cmake: str) -> None:
    for package in interface_packages():
        build_dir = BUILD / "interfaces" / package.name
        # From scratch: a CMake cache left by an older layout would refuse the source.
        shutil.rmtree(build_dir, ignore_errors=True)
        build_dir.mkdir(parents=True)
        say(f"building interface package {package.name} into the venv (cmake, ~10 s)")
        for step in build_steps(package, build_dir=build_dir, prefix=VENV,
                                python=str(venv_python()), cmake=cmake):
            run(step.argv, cwd=step.cwd, log=step.log)


def verify() -> None:
    say("checking the environment: rclpy, tf2_msgs, geometry_msgs, pyigtl, yourdfpy")
    probe = ("import rclpy, pyigtl, yourdfpy, trimesh, numpy; "
             "from tf2_msgs.msg import TFMessage, TF2Error; "
             "from control_msgs.action import FollowJointTrajectory; "
             "from geometry_msgs.msg import TransformStamped; "
             "TFMessage(transforms=[TransformStamped()]); print('ok')")
    run([str(venv_python()), "-c", probe])


def main() -> int:
    started = time.monotonic()
    try:
        digest = inputs_digest()
        if venv_python().exists() and STAMP.exists() and STAMP.read_text().strip() == digest:
            say(f"environment up to date ({VENV}); nothing to do")
            return 0
        check_python()
        check_build_tools()
        for folder in (CACHE / "pip", CACHE / "tmp", BUILD):
            folder.mkdir(parents=True, exist_ok=True)
        STAMP.unlink(missing_ok=True)
        create_venv()
        install_project()
        cmake = ensure_cmake()
        build_interfaces(cmake)
        verify()
        STAMP.write_text(digest + "\n")
    except SetupError as error:
        print(f"[setup] ERROR: {error}", file=sys.stderr, flush=True)
        return 1
    say(f"environment ready in {time.monotonic() - started:.0f} s: {VENV}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

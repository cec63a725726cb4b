#!/usr/bin/env python3
"""Build the project's environment in `.venv` inside the repository, in one step.

What it does, printing each step:
  1. checks the tools it needs (C/C++ compiler, make, Python headers, cmake >= 3.20 or the
     cmake wheel from PyPI in its place);
  2. creates `.venv` and installs the project with its pinned dependencies (ROS 2 Jazzy from
     PyPI wheels, test tools, interface build tools);
  3. builds the `tf2_msgs` and `control_msgs` interface packages (bridge/interfaces/) into
     the venv, because they have no PyPI wheel: both at once (they do not depend on each
     other; control_msgs is the long one), and only when their sources, the ROS pins or
     Python changed since they were built.

Every step says when it starts, what it is doing every few seconds, and how long it took.

It needs no root and writes nothing outside the repository (pip's cache and temporary files
go to `.cache/`). A second run that finds a stamp matching the inputs returns in a moment.
Run it with any Python >= 3.10: `python3 tools/setup_env.py` (what `make setup` does).
"""

from __future__ import annotations

import hashlib
import os
import signal
import sys
import sysconfig
import time
from pathlib import Path
from typing import Callable

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
# How to build the interfaces, and how to run a long step without going silent, is the
# package's own knowledge (the CLI's build-interfaces uses it too); it imports nothing but
# the standard library.
from bridge.interfaces import (INTERFACES_DIR, MIN_CMAKE, InterfaceBuildError,  # noqa: E402
                               Step, StepFailedError, Target, build_interfaces,
                               compile_progress, find_cmake, last_line, missing_build_tools,
                               pip_progress, run_step, shipped_packages)

VENV = REPO / ".venv"
CACHE = REPO / ".cache"
BUILD = REPO / "build"
STAMP = VENV / ".slicer-ros2-bridge-setup"
# The venv's packages and compiled modules were installed from these inputs: a run cut short
# after them (Ctrl-C in the interface build) does not install them again.
PACKAGES_STAMP = VENV / ".slicer-ros2-bridge-packages"
# What the interface packages in the venv were built from (see interfaces_digest).
INTERFACES_STAMP = VENV / ".slicer-ros2-bridge-interfaces"
CMAKE_WHEEL = "cmake==3.31.6"
# The ROS wheels are built for these CPython versions only.
SUPPORTED_PYTHONS = ((3, 10), (3, 11), (3, 12), (3, 13))
# Inputs whose change means the environment must be rebuilt (the install builds the compiled
# modules from their sources, so an edit of one is one).
STAMP_INPUTS = ("pyproject.toml", "setup.py", "tools/setup_env.py",
                "bridge/tf/_compiled_store.pyx", "bridge/ros/_rcl_reader.pyx",
                "bridge/core/_native_stream.pyx", "bridge/core/send_batch.h")


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
    digest.update(interfaces_digest().encode())
    return digest.hexdigest()


def interfaces_digest() -> str:
    """What the built interface packages depend on: their sources, the ROS wheels' pins and
    Python. A set-up rerun for anything else (a new test tool) keeps them."""
    digest = hashlib.sha256()
    for path in sorted(INTERFACES_DIR.rglob("*")):
        # What the build reads, not the Python that runs it or the READMEs.
        if path.suffix in (".msg", ".srv", ".action", ".xml", ".cmake") or \
                path.name == "CMakeLists.txt":
            digest.update(str(path.relative_to(REPO)).encode())
            digest.update(path.read_bytes())
    pins = [line for line in (REPO / "pyproject.toml").read_text().splitlines()
            if '"ros-jazzy-' in line]
    digest.update("\n".join(pins).encode())
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


def run(label: str, cmd: list[str], log: Path,
        where: Callable[[str], str | None] = last_line) -> None:
    """Run a command, saying what it does every few seconds; on failure show the tail of its
    log and raise."""
    where = pip_progress if "pip" in label else where
    try:
        run_step(Step(f"[setup] {label}", cmd, REPO, log, child_env(), where=where),
                 say=print_flushed)
    except StepFailedError as error:
        raise SetupError(str(error)) from None


def print_flushed(text: str) -> None:
    print(text, flush=True)


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
    missing = missing_build_tools()
    if missing:
        raise SetupError(f"missing build tool(s): {', '.join(missing)} (needed to build the "
                         f"tf2_msgs interfaces); on Debian: apt-get install build-essential")
    header = Path(sysconfig.get_paths()["include"]) / "Python.h"
    if not header.exists():
        raise SetupError(f"Python headers not found (expected {header}); on Debian: "
                         f"apt-get install python3-dev")


def venv_target() -> Target:
    return Target(venv_python(), VENV, VENV)


def ensure_cmake() -> None:
    """A cmake >= 3.20: the system's, or else the cmake wheel installed into the venv."""
    if find_cmake(venv_target()) is not None:
        return
    say(f"cmake >= {'.'.join(map(str, MIN_CMAKE))} not found: installing {CMAKE_WHEEL} into "
        f"the venv")
    run("pip install cmake", [str(venv_python()), "-m", "pip", "install", CMAKE_WHEEL],
        CACHE / "pip-cmake.log")
    if find_cmake(venv_target()) is None:
        raise SetupError(f"cmake from the {CMAKE_WHEEL} wheel does not run: "
                         f"{VENV / 'bin' / 'cmake'}")


def create_venv() -> None:
    if venv_python().exists():
        say(f"venv exists: {VENV}")
        return
    say(f"creating venv {VENV} with {sys.executable}")
    run("python -m venv", [sys.executable, "-m", "venv", str(VENV)], CACHE / "venv.log")


def install_project() -> None:
    say("installing the project and its pinned dependencies (ROS 2 Jazzy wheels, pyigtl, "
        "numpy, yourdfpy, trimesh, test and interface-build tools)")
    run("pip install", [str(venv_python()), "-m", "pip", "install", "-e",
                        f"{REPO}[test,interfaces]"], CACHE / "pip-install.log")


def build_compiled_modules() -> None:
    """The compiled modules again, in place, now that the venv has rcl's headers: pip
    builds the project before it installs the ROS wheels, so its own build could make the
    tf store but not the rcl reader (setup.py says where each comes from)."""
    say("building the compiled modules (tf store, rcl reader) in place")
    run("setup.py build_ext", [str(venv_python()), "setup.py", "-q", "build_ext", "--inplace",
                               "--force"], CACHE / "build-ext.log", where=compile_progress)


def build_shipped_interfaces() -> None:
    """tf2_msgs and control_msgs, both at once; kept when built from the same inputs."""
    digest = interfaces_digest()
    same = INTERFACES_STAMP.exists() and INTERFACES_STAMP.read_text().strip() == digest
    started = time.monotonic()
    say("building the interface packages tf2_msgs and control_msgs into the venv (cmake; "
        "both at once, ~1-2 min on 2 quiet cores, 5-15 on a busy machine)" if not same else
        "interface packages: keeping those built from the same sources")
    INTERFACES_STAMP.unlink(missing_ok=True)
    try:
        build_interfaces(shipped_packages(), venv_target(), force=not same,
                         build_root=BUILD / "interfaces", say=say, parallel=2)
    except InterfaceBuildError as error:
        raise SetupError(str(error)) from None
    INTERFACES_STAMP.write_text(digest + "\n")
    say(f"  interface packages done in {time.monotonic() - started:.1f} s")


def verify() -> None:
    probe = ("import rclpy, pyigtl, yourdfpy, trimesh, numpy; "
             "from tf2_msgs.msg import TFMessage, TF2Error; "
             "from control_msgs.action import FollowJointTrajectory; "
             "from geometry_msgs.msg import TransformStamped; "
             "TFMessage(transforms=[TransformStamped()]); print('ok')")
    say("checking the environment: rclpy, tf2_msgs, control_msgs, geometry_msgs, pyigtl, "
        "yourdfpy")
    run("import check", [str(venv_python()), "-c", probe], CACHE / "verify.log")


def set_up() -> int:
    started = time.monotonic()
    digest = inputs_digest()
    if venv_python().exists() and STAMP.exists() and STAMP.read_text().strip() == digest:
        say(f"environment up to date ({VENV}); nothing to do")
        return 0
    check_python()
    check_build_tools()
    for folder in (CACHE / "pip", CACHE / "tmp", BUILD):
        folder.mkdir(parents=True, exist_ok=True)
    STAMP.unlink(missing_ok=True)
    if venv_python().exists() and PACKAGES_STAMP.exists() \
            and PACKAGES_STAMP.read_text().strip() == digest:
        say("packages: keeping those installed from the same inputs (the last run stopped "
            "after them)")
    else:
        PACKAGES_STAMP.unlink(missing_ok=True)
        create_venv()
        install_project()
        build_compiled_modules()
        PACKAGES_STAMP.write_text(digest + "\n")
    ensure_cmake()
    build_shipped_interfaces()
    verify()
    STAMP.write_text(digest + "\n")
    say(f"environment ready in {time.monotonic() - started:.0f} s: {VENV}")
    return 0


def guarded(body: Callable[[], int]) -> int:
    """``body()``'s exit status; a `SetupError` is one line and 1, and Ctrl-C (SIGINT) one
    line and 130 (128 + SIGINT, as a shell reports it), never a traceback. By then the
    interrupted step's processes are stopped (`run_step`), and the stamp, removed before
    anything changed, makes the next run redo what was cut short."""
    try:
        return body()
    except SetupError as error:
        print(f"[setup] ERROR: {error}", file=sys.stderr, flush=True)
        return 1
    except KeyboardInterrupt:
        print("[setup] interrupted (Ctrl-C); run `make setup` again to finish",
              file=sys.stderr, flush=True)
        return 128 + signal.SIGINT


def main() -> int:
    return guarded(set_up)


if __name__ == "__main__":
    sys.exit(main())

"""For colcon (ament_python), which drives setup.py, and for the one compiled module; everything
else is in pyproject.toml.

The files below make the package a ROS 2 package once installed into a colcon workspace:
its ament index marker, its package.xml, and the executables `ros2 run` finds under
lib/slicer_ros2_bridge. A pip install carries them too, harmlessly, under its prefix.

The compiled tf store (bridge/tf/_compiled_store.pyx) is built when Cython is importable
(pip fetches it; `make setup` puts it in the venv, for colcon; with apt's ROS, `pip install
Cython` or apt's cython3). Without Cython or a C compiler the package installs without it and
the daemon runs the pure Python store (bridge/tf/store.py), with the same results, slower.

`ros2 run`'s executables get the building Python as their interpreter, as ament_python's
console scripts do: their `/usr/bin/env python3` found whichever python3 came first on PATH,
not the one with rclpy (a venv's, for ROS from PyPI).
"""

import os
import shutil
import sys
from pathlib import Path

from setuptools import Extension, setup

PACKAGE = "slicer_ros2_bridge"
HERE = Path(__file__).resolve().parent


def compiled_modules() -> list:
    try:
        from Cython.Build import cythonize
    except ImportError:
        return []
    # -ffp-contract=off: no fused multiply-add, so each formula rounds as Python's does and
    # the compiled store's results equal the pure Python store's to the bit.
    store = Extension("bridge.tf._compiled_store", ["bridge/tf/_compiled_store.pyx"],
                      extra_compile_args=["-O2", "-ffp-contract=off"], optional=True)
    # The native lane of streamed poses (bridge/core/_native_stream.pyx): same rule.
    lane = Extension("bridge.core._native_stream", ["bridge/core/_native_stream.pyx"],
                     depends=["bridge/core/send_batch.h"],
                     extra_compile_args=["-O2", "-ffp-contract=off"], optional=True)
    modules = [store, lane, *rcl_reader()]
    traced = os.environ.get(TRACED_BUILD)
    if traced:
        # The copies' own paths in the C files (not "bridge/..."), which the plugin follows.
        return cythonize(traced_modules(modules, Path(traced)), quiet=True,
                         compiler_directives={"linetrace": True},
                         relative_path_in_code_position_comments=False)
    return cythonize(modules, quiet=True)


# The coverage build of the same modules (tools/native_coverage.py sets it to a directory).
TRACED_BUILD = "SLICER_ROS2_BRIDGE_TRACED_BUILD"


def traced_modules(modules: list, out: Path) -> list:
    """The modules with Cython's line tracing, for coverage (tools/native_coverage.py): built
    from copies of their sources in ``out``, so their C files lie beside those copies (where
    Cython's coverage plugin looks, by the absolute paths traced) and never beside the
    production ones, which `build_ext --inplace` would then take as up to date."""
    for module in modules:
        for source in [*module.sources, *module.depends]:
            (out / source).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(HERE / source, out / source)
        module.sources = [str(out / source) for source in module.sources]
        module.depends = [str(out / source) for source in module.depends]
        # CYTHON_TRACE_NOGIL: the lanes' code runs without the interpreter's lock. -O1:
        # half the compile time of -O2; -ffp-contract=off stays, the tests compare bits.
        module.define_macros.append(("CYTHON_TRACE_NOGIL", "1"))
        module.extra_compile_args = ["-O1" if arg == "-O2" else arg
                                     for arg in module.extra_compile_args]
    return modules


def rcl_reader() -> list:
    """The reader that takes /tf without the interpreter's lock (bridge/ros/_rcl_reader.pyx),
    where rcl's headers are found: beside this Python (ROS 2 from PyPI) or in a sourced ROS
    prefix. Linked by name only: at run time rclpy has loaded the same libraries."""
    prefixes = [Path(sys.prefix), *(Path(p) for p in
                                    os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)
                                    if p)]
    for prefix in prefixes:
        include = prefix / "include"
        if (include / "rcl" / "rcl" / "rcl.h").is_file():
            dirs = sorted(str(d) for d in include.iterdir() if (d / d.name).is_dir())
            return [Extension("bridge.ros._rcl_reader", ["bridge/ros/_rcl_reader.pyx"],
                              include_dirs=dirs, library_dirs=[str(prefix / "lib")],
                              libraries=["rcl", "rmw", "rcutils"], extra_compile_args=["-O2"],
                              optional=True)]
    return []


def ros2_executables() -> list:
    """The executables under lib/<package>, written to build/ with this Python's shebang."""
    out = HERE / "build" / "ros2_executables"
    out.mkdir(parents=True, exist_ok=True)
    made = []
    for name in ("bridge", "demo", "state_publisher"):
        body = (HERE / "ros2_executables" / name).read_text().split("\n", 1)[1]
        target = out / name
        target.write_text(f"#!{sys.executable}\n{body}")
        target.chmod(0o755)
        made.append(os.path.relpath(target))  # setuptools takes data_files relative only
    return made


setup(python_requires=">=3.10", ext_modules=compiled_modules(), data_files=[
    ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
    (f"share/{PACKAGE}", ["package.xml"]),
    (f"lib/{PACKAGE}", ros2_executables()),
])

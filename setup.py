"""For colcon (ament_python), which drives setup.py, and for the one compiled module; everything
else is in pyproject.toml.

The files below make the package a ROS 2 package once installed into a colcon workspace:
its ament index marker, its package.xml, and the executables `ros2 run` finds under
lib/slicer_ros2_bridge. A pip install carries them too, harmlessly, under its prefix.

The compiled tf store (bridge/tf/_compiled_store.pyx) is optional: without Cython (a colcon
build outside the venv) or a C compiler, the package installs without it and the daemon runs
the pure Python store (bridge/tf/store.py), with the same results, slower.
"""

from setuptools import Extension, setup

PACKAGE = "slicer_ros2_bridge"


def compiled_modules() -> list:
    try:
        from Cython.Build import cythonize
    except ImportError:
        return []
    # -ffp-contract=off: no fused multiply-add, so each formula rounds as Python's does and
    # the compiled store's results equal the pure Python store's to the bit.
    store = Extension("bridge.tf._compiled_store", ["bridge/tf/_compiled_store.pyx"],
                      extra_compile_args=["-O2", "-ffp-contract=off"], optional=True)
    return cythonize([store], quiet=True)


setup(python_requires=">=3.10", ext_modules=compiled_modules(), data_files=[
    ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
    (f"share/{PACKAGE}", ["package.xml"]),
    (f"lib/{PACKAGE}", ["ros2_executables/bridge", "ros2_executables/demo",
                        "ros2_executables/state_publisher"]),
])

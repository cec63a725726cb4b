"""For colcon (ament_python), which drives setup.py; everything else is in pyproject.toml.

The files below make the package a ROS 2 package once installed into a colcon workspace:
its ament index marker, its package.xml, and the executables `ros2 run` finds under
lib/slicer_ros2_bridge. A pip install carries them too, harmlessly, under its prefix.
"""

from setuptools import setup

PACKAGE = "slicer_ros2_bridge"

setup(python_requires=">=3.10", data_files=[
    ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
    (f"share/{PACKAGE}", ["package.xml"]),
    (f"lib/{PACKAGE}", ["ros2_executables/bridge", "ros2_executables/demo",
                        "ros2_executables/state_publisher"]),
])

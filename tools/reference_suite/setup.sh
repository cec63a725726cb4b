# Sourced by SlicerROS2's unit tests in place of /opt/ros/$ROS_DISTRO/setup.sh (README.md
# here). Prints nothing. ros2_cli.py finds the project's venv by itself and the Python
# modules of every AMENT_PREFIX_PATH prefix (the tests' turtlesim interfaces); this only
# says which ROS this is, as a ROS setup.sh does.
export ROS_VERSION=2
export ROS_PYTHON_VERSION=3
export ROS_DISTRO="${ROS_DISTRO:-jazzy}"

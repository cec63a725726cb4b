# slicer-ros2-bridge on the official ROS 2 Jazzy image.
#
#   docker build -t slicer-ros2-bridge .
#   docker run --rm -it --net=host slicer-ros2-bridge                 # the daemon
#   docker run --rm -it --net=host slicer-ros2-bridge demo            # with the demo robot
#   docker run --rm -it --net=host -v $PWD/bridges.yaml:/bridges.yaml \
#       slicer-ros2-bridge run --config /bridges.yaml
#
# --net=host: DDS discovery needs the host's network to see your other ROS 2 nodes, and
# 3D Slicer on the host then reaches the daemon at 127.0.0.1:18944. Pass the same
# ROS_DOMAIN_ID as your robot (-e ROS_DOMAIN_ID=...). Without host networking the daemon
# must listen on all interfaces: `run --host 0.0.0.0 --allow <CIDR>` with
# `-p 127.0.0.1:18944:18944` (docs/security.md).
#
# Here ROS 2 (rclpy, the message packages, and the real tf2_msgs) comes from the image's
# apt packages, not from PyPI wheels, so the project is installed without its ROS pins.
FROM ros:jazzy

RUN apt-get update \
    && apt-get install -y --no-install-recommends \
        python3-venv python3-numpy python3-yaml python3-lxml \
        ros-jazzy-tf2-msgs ros-jazzy-common-interfaces \
    && rm -rf /var/lib/apt/lists/*

# A venv that sees the ROS Python packages of /opt/ros and apt's numpy.
RUN python3 -m venv --system-site-packages /opt/bridge
ENV PATH=/opt/bridge/bin:$PATH

# setup.py builds the compiled tf store (Cython, fetched by pip as a build requirement; the
# image's compiler) and installs the ROS package files it lists.
COPY pyproject.toml setup.py package.xml README.md /src/
COPY resource /src/resource
COPY ros2_executables /src/ros2_executables
COPY protocol /src/protocol
COPY bridge /src/bridge
COPY slicer_client /src/slicer_client
RUN pip install --no-cache-dir \
        pyigtl==0.3.4 yourdfpy==0.0.60 trimesh==5.2.0 pycollada==0.9.3 crcmod==1.7 pin==4.1.0 \
        mcap==1.6.0 \
    && pip install --no-cache-dir --no-deps /src

# The daemon needs no privileges: run it as an ordinary user (docs/security.md).
RUN useradd --create-home --uid 10001 --shell /usr/sbin/nologin bridge
USER bridge
WORKDIR /home/bridge
ENV ROS_LOG_DIR=/home/bridge/.ros/log

EXPOSE 18944
# /ros_entrypoint.sh (from the ros image) sources /opt/ros/jazzy/setup.bash first.
ENTRYPOINT ["/ros_entrypoint.sh", "slicer-ros2-bridge"]
CMD ["run"]

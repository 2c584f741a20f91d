# A stand-in for ros:jazzy-ros-base, for the real-engine tests (tests/e2e/test_docker_engine.py):
# no image registry is reachable from the test machines, so ROS 2 Jazzy comes from PyPI
# wheels and the root file system from debootstrap (tests/helpers/docker_engine.py makes
# both). What the project's Dockerfile relies on is what it mimics: /ros_entrypoint.sh,
# which sets up ROS and execs its arguments, and rclpy importable by `python3`.
#
# Test-only: pip installs from the wheelhouse in the build context and nowhere else, also
# in images built on this one (PIP_NO_INDEX), so no build needs the package index.
ARG ROOTFS
FROM ${ROOTFS}

# ROOTFS already holds python3 (Debian 12's is 3.11, the one the ROS 2 Jazzy wheels are
# built for), python3-venv and procps (debootstrap --include): no apt run here.
ENV ROS_DISTRO=jazzy \
    LANG=C.UTF-8

COPY wheels /opt/wheelhouse
ENV PIP_NO_INDEX=1 \
    PIP_FIND_LINKS=/opt/wheelhouse \
    PIP_DISABLE_PIP_VERSION_CHECK=1

# A venv of its own: the wheels in Debian's system Python give a std_msgs without msg.
RUN python3 -m venv /opt/ros/jazzy/venv \
    && /opt/ros/jazzy/venv/bin/pip install --no-cache-dir \
        "ros-jazzy-rclpy[fastrtps]" ros-jazzy-std-msgs "pytest<9"

COPY ros_entrypoint.sh /ros_entrypoint.sh
ENTRYPOINT ["/ros_entrypoint.sh"]
CMD ["bash"]

# ros-isolated-test on ROS 2 Jazzy: the runner as the container's entrypoint (PID 1).
#
#   docker build -t ros-isolated-test .
#   docker run --rm -v "$PWD:/ws" -w /ws ros-isolated-test \
#       run --junit-xml results/talker.xml -- python3 -m pytest test/test_talker.py
#
# Containers that share the host's network and IPC namespaces talk ROS to each other (and
# to the host): give them the host's PID namespace and lock directory too, for distinct
# IDs (see "Docker" in README.md):
#   docker run --rm --network host --ipc host --pid host \
#       -v /tmp/ros-isolated-test-domains:/tmp/ros-isolated-test-domains ...
#
# The base is an argument, so the same file builds on any ROS 2 image that has
# /ros_entrypoint.sh and python3 (Kilted, Humble, an image of your own):
#   docker build --build-arg BASE=ros:kilted-ros-base -t ros-isolated-test:kilted .
ARG BASE=ros:jazzy-ros-base
FROM ${BASE}

# pip and venv from Ubuntu; the runner itself needs only click, filelock and lxml.
RUN apt-get update \
    && apt-get install -y --no-install-recommends python3-pip python3-venv \
    && rm -rf /var/lib/apt/lists/*

COPY pyproject.toml README.md /opt/ros-isolated-test/
COPY ros_isolated_test /opt/ros-isolated-test/ros_isolated_test

# A venv that still sees the image's ROS Python packages (rclpy comes from ROS, not PyPI).
RUN python3 -m venv --system-site-packages /opt/ros-isolated-test/venv \
    && /opt/ros-isolated-test/venv/bin/pip install --no-cache-dir /opt/ros-isolated-test \
    && ln -s /opt/ros-isolated-test/venv/bin/ros-isolated-test /usr/local/bin/ros-isolated-test \
    && ros-isolated-test --version

# The default lock directory is /tmp/ros-isolated-test-domains: bind-mount the host's
# to share one pool between containers and the host.

# ros_entrypoint.sh sources ROS, then execs the runner, which becomes PID 1: it reaps
# orphaned zombies, passes SIGTERM (docker stop) on to the test, and exits with its code.
ENTRYPOINT ["/ros_entrypoint.sh", "ros-isolated-test"]
CMD ["--help"]

#!/bin/bash
# What sourcing /opt/ros/jazzy/setup.bash gives in ros:jazzy-ros-base, for the PyPI wheels:
# their libraries on LD_LIBRARY_PATH and their packages on PYTHONPATH, so any python3
# (the system's, a venv's) imports rclpy. The wheels' own start-up hook, which would set
# the same again, is told it already ran.
set -e
venv=/opt/ros/jazzy/venv
site=$(echo "$venv"/lib/python3*/site-packages)
libs=$venv/lib
for dir in "$site"/ros_*.libs; do
  if [[ -d $dir ]]; then libs=$libs:$dir; fi
done
export LD_LIBRARY_PATH=$libs${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
export PYTHONPATH=$site${PYTHONPATH:+:$PYTHONPATH}
export AMENT_PREFIX_PATH=$venv${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}
export _ROS_WHEELS_BOOTSTRAP_COMPLETE=1
exec "$@"

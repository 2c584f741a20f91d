#!/usr/bin/env bash
# Installs only what the demo runs (scripts/setup.sh --demo: ROS 2 Jazzy, colcon and
# ros-isolated-test in .venv), then runs the demo as a user meets it: examples/crosstalk_demo
# built with a plain `colcon build` and tested with `colcon test` (six ROS 2 tests that
# publish on one topic at once): ros-isolated-test's colcon extension, on because it is
# installed, gives each its own domain and all pass; then the control, the same with
# ROS_ISOLATED_TEST_COLCON=off (one shared domain: they hear each other and fail). It ends
# naming the page the extension wrote. Arguments go to examples/demo.py (--help).
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$root"
scripts/setup.sh --demo
exec .venv/bin/python examples/demo.py "$@"

#!/usr/bin/env bash
# Installs what is missing, then runs the demo: six ROS 2 tests that publish on one topic,
# run in parallel through ros-isolated-test (each on its own domain: all pass), then the
# same tests through ament's plain runner (one shared domain: they hear each other and fail).
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$root"
scripts/setup.sh
exec .venv/bin/python examples/demo.py "$@"

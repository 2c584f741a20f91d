#!/usr/bin/env bash
# Installs what is missing, then runs every check: ruff, mypy and the whole test suite
# (real rclpy over Fast DDS, real colcon and ctest). Extra arguments go to pytest.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$root"
scripts/setup.sh
.venv/bin/ruff check ros_isolated_test tests examples scripts benches
.venv/bin/mypy
scripts/py310_smoke.sh
exec .venv/bin/python -m pytest "$@"

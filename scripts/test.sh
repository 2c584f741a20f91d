#!/usr/bin/env bash
# Installs what is missing, then runs every check: ruff, mypy and the whole test suite
# (real rclpy over Fast DDS, real colcon and ctest). Extra arguments go to pytest.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$root"
scripts/setup.sh
.venv/bin/ruff check ros_isolated_test tests examples scripts benches install_check setup.py
.venv/bin/ruff format --check ros_isolated_test tests examples scripts benches install_check setup.py
.venv/bin/mypy
scripts/py310_smoke.sh
# The runner's own tests on Ubuntu 24.04's Python 3.12 and packages (.venv-py312).
scripts/ubuntu_tier.sh
if (($#)); then
  exec .venv/bin/python -m pytest "$@"
fi
# The whole suite, two sessions at once (pytest-xdist): one runs the ros and colcon tests one
# at a time, as a developer's machine does; the other every other module whole (the groups:
# tests/conftest.py). Two sessions at once are two users of one machine, which every test
# must bear (the busy machine, tests/conftest.py).
exec .venv/bin/python -m pytest -n 2 --dist loadgroup

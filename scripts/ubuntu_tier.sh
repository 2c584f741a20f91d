#!/usr/bin/env bash
# The runner, coordinator, pytest-plugin, result-file and report tests on ROS 2 Jazzy's platform:
# Python 3.12 with exactly the setuptools, click, filelock and lxml Ubuntu 24.04 ships
# (.venv-py312, made by scripts/py310_smoke.sh, which scripts/test.sh runs first).
# ROS's wheels exist for 3.11 only, so tests that need rclpy or colcon are left out here
# (tests/e2e/test_ros_package.py runs Ubuntu's versions with ROS, in .venv-distro). Its
# allowed skips: the tests run as other users (other-users, setuid-helper), since pyenv's
# 3.12 lives where other users may not run it, and the few rclpy controls among the unit
# tests (rclpy), since ROS is not here; any other skip fails this tier. Extra arguments go
# to pytest.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$root"
venv=.venv-py312
if [[ ! -x $venv/bin/python ]]; then
  if [[ ${ROS_ISOLATED_TEST_NO_SKIPS:-} == 1 ]]; then
    echo "ubuntu tier: no $venv (scripts/py310_smoke.sh makes it from Python 3.12)" >&2
    exit 1
  fi
  echo "ubuntu tier: skipped, no $venv (no Python 3.12 on this machine)"
  exit 0
fi
modules=(
  tests/unit/domain_coordinator
  tests/e2e/test_lean_runner.py
  tests/unit/cli/test_cli.py
  tests/unit/cli/test_run_arguments.py
  tests/unit/cli/test_run.py
  tests/unit/cli/test_run_result_paths.py
  tests/unit/ament/test_run_test_isolated.py
  tests/unit/pytest_plugin/test_plugin.py
  tests/unit/pytest_plugin/test_holding.py
  tests/unit/pytest_plugin/test_options.py
  tests/unit/xunit/test_result_file.py
  tests/unit/xunit/test_placeholder.py
  tests/unit/xunit/test_serialise.py
  tests/e2e/test_normalise_samples.py
  tests/e2e/test_hostile_results.py
  # lxml 5.2.1 reads an external parameter entity with resolve_entities='internal' alone.
  tests/unit/xunit/test_reader_entities.py
  tests/unit/xunit/test_safe_parser.py
  tests/unit/xunit/test_sanitiser.py
  tests/unit/xunit/test_builder.py
  # One odd value never loses the report's page: Python 3.12's own limits on numbers
  # and instants, Ubuntu's lxml.
  tests/unit/report/test_bounded_values.py
)
log=$(mktemp)
trap 'rm -f "$log"' EXIT
status=0
# Not strict here: the skips are checked below, by capability.
ROS_ISOLATED_TEST_NO_SKIPS=0 "$venv/bin/python" -m pytest -p no:cacheprovider -q -rs \
  -m "not ros and not colcon" "${modules[@]}" "$@" | tee "$log" || status=$?
if grep '^SKIPPED ' "$log" | grep -Ev '\[(other-users|setuid-helper|rclpy)\]'; then
  echo "ubuntu tier: skipped for want of more than other users or rclpy (above); this tier allows only those" >&2
  exit 1
fi
exit "$status"

#!/usr/bin/env bash
# Installs everything the demo and the test suite need, into .venv beside this script's
# project: system build tools (cmake, a C++ compiler) from Debian when missing, then
# ros-isolated-test with real ROS 2 Jazzy, ament_cmake and colcon from PyPI.
# Safe to run again: it only installs again when pyproject.toml changed.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$root"

python=${ROS_ISOLATED_TEST_PYTHON:-python3.11}
if ! command -v "$python" >/dev/null 2>&1; then
  echo "setup: $python not found; the ROS 2 Jazzy wheels need CPython 3.11 (set ROS_ISOLATED_TEST_PYTHON to another interpreter)" >&2
  exit 1
fi

missing=()
for tool in cmake ctest make g++ unshare; do
  command -v "$tool" >/dev/null 2>&1 || missing+=("$tool")
done
if ((${#missing[@]})); then
  echo "setup: installing system packages for: ${missing[*]}"
  sudo=""
  [[ $(id -u) -ne 0 ]] && sudo=sudo
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq cmake make g++ util-linux >/dev/null
fi

stamp=.venv/.installed-$(sha256sum pyproject.toml | cut -c1-16)
if [[ ! -f $stamp ]]; then
  echo "setup: installing ros-isolated-test, ROS 2 Jazzy, ament_cmake and colcon into .venv (about a minute)"
  # Reuse an existing .venv: pip only adds what changed, and a running test keeps working.
  [[ -x .venv/bin/python ]] || "$python" -m venv .venv
  # pip's notes about local index folders that do not exist here are noise: keep real errors.
  .venv/bin/python -m pip install -q --upgrade pip 2>&1 | { grep -v '^WARNING: Location' || true; }
  .venv/bin/python -m pip install -q -e ".[ros,dev]" 2>&1 | { grep -v '^WARNING: Location' || true; }
  .venv/bin/ros-isolated-test --help >/dev/null
  rm -f .venv/.installed-*
  touch "$stamp"
fi

#!/usr/bin/env bash
# Installs everything the demo and the test suite need: system build tools (cmake, a C++
# compiler, googletest, node, Gazebo's transport tools, docker.io and debootstrap) from
# Debian when missing, xunit-viewer from npm into node_modules, then ros-isolated-test
# with real ROS 2 Jazzy, ament_cmake and colcon from PyPI into .venv, and with ROS 2
# Kilted into .venv-kilted.
# --demo installs only what scripts/demo.sh runs: cmake and make, and ros-isolated-test
# with ROS 2 Jazzy, ament_cmake and colcon in .venv (no dev tools, no Kilted, distro or
# coordinator venvs, no Docker, Debian packaging, Chromium or npm); a later run without it
# adds the rest.
# Safe to run again: it only installs again when pyproject.toml changed.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$root"
mode=all
case ${1:-} in
  --demo) mode=demo ;;
  "") ;;
  *) echo "setup: unknown argument $1; use no argument (everything) or --demo" >&2; exit 2 ;;
esac

# The distribution's Python 3.11 when it has one: every user can run it, so the tests
# can start runners as other users (the shared lock directory's multi-user cases); a
# Python under root's home cannot be run by them.
default_python=python3.11
if /usr/bin/python3.11 -c 'import venv, ensurepip' >/dev/null 2>&1; then
  default_python=/usr/bin/python3.11
fi
python=${ROS_ISOLATED_TEST_PYTHON:-$default_python}
if ! command -v "$python" >/dev/null 2>&1; then
  echo "setup: $python not found; the ROS 2 Jazzy wheels need CPython 3.11 (set ROS_ISOLATED_TEST_PYTHON to another interpreter)" >&2
  exit 1
fi

missing=()
if [[ $mode == demo ]]; then
  # The demo's package is CMake with no compiled code: cmake, ctest and make are all it builds with.
  for tool in cmake ctest make; do
    command -v "$tool" >/dev/null 2>&1 || missing+=("$tool")
  done
  if ((${#missing[@]})); then
    echo "setup: installing system packages for: ${missing[*]}"
    sudo=""
    [[ $(id -u) -ne 0 ]] && sudo=sudo
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq cmake make >/dev/null
  fi
  missing=()
else  # everything the test suite needs, to "fi  # mode"
for tool in cmake ctest make g++ unshare; do
  command -v "$tool" >/dev/null 2>&1 || missing+=("$tool")
done
# googletest builds a real gtest binary in the tests; node and npm run xunit-viewer.
[[ -f /usr/include/gtest/gtest.h ]] || missing+=(libgtest-dev)
[[ -f /usr/include/gmock/gmock.h && -d /usr/src/gmock ]] || missing+=(libgmock-dev)
command -v npm >/dev/null 2>&1 || missing+=(npm)
# Gazebo's transport tools (ign-transport-topic): the simulation isolation tests talk
# over the real transport. Debian has no `ign` wrapper; the tools live under libexec.
ign_tool() {
  compgen -G '/usr/libexec/ignition/transport*/ign-transport-topic' >/dev/null ||
    command -v ign-transport-topic >/dev/null 2>&1
}
ign_tool || missing+=(ignition-transport-cli)
# A Docker engine and debootstrap: the real-engine tier builds the project's image on a
# stand-in base it makes itself. Debian's docker.io only where no engine is at hand.
docker_engine() { command -v dockerd >/dev/null 2>&1 || docker info >/dev/null 2>&1; }
docker_engine || missing+=(docker.io)
command -v debootstrap >/dev/null 2>&1 || missing+=(debootstrap)
# Headless Chromium: the tests open `report --html`'s page as a person would.
command -v chromium >/dev/null 2>&1 || missing+=(chromium)
# The Debian package (scripts/package_deb.sh): Debian's build tools, and the Python packages
# its dh_auto_test runs the built package with (Debian's python3, not a venv).
deb_tools=(debhelper dh-python python3-all python3-setuptools fakeroot python3-click python3-filelock python3-lxml)
deb_build() {
  command -v dpkg-buildpackage >/dev/null 2>&1 && command -v dh_python3 >/dev/null 2>&1 &&
    command -v fakeroot >/dev/null 2>&1 && /usr/bin/python3 -c 'import click, filelock, lxml' >/dev/null 2>&1
}
deb_build || missing+=(debhelper)
if ((${#missing[@]})); then
  echo "setup: installing system packages for: ${missing[*]}"
  sudo=""
  [[ $(id -u) -ne 0 ]] && sudo=sudo
  $sudo apt-get update -qq
  packages=(cmake make g++ util-linux libgtest-dev libgmock-dev google-mock)
  command -v npm >/dev/null 2>&1 || packages+=(nodejs npm)
  ign_tool || packages+=(ignition-transport-cli)
  docker_engine || packages+=(docker.io)
  command -v debootstrap >/dev/null 2>&1 || packages+=(debootstrap)
  command -v chromium >/dev/null 2>&1 || packages+=(chromium)
  deb_build || packages+=("${deb_tools[@]}")
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq "${packages[@]}" >/dev/null
fi

npm_stamp=node_modules/.installed-$(cat package.json package-lock.json | sha256sum | cut -c1-16)
if [[ ! -f $npm_stamp ]]; then
  echo "setup: installing xunit-viewer (npm) into node_modules"
  npm ci --no-audit --no-fund --loglevel=error
  touch "$npm_stamp"
fi
fi  # mode

# Everything (the ros and dev extras) or the demo's part (the ros extra): a full install
# serves the demo too; a demo install is completed by the next full run.
hash=$(sha256sum pyproject.toml | cut -c1-16)
stamp=.venv/.installed-$hash
extras=ros,dev
if [[ $mode == demo ]]; then
  [[ -f $stamp ]] || stamp=.venv/.installed-demo-$hash
  extras=ros
fi
if [[ ! -f $stamp ]]; then
  echo "setup: installing ros-isolated-test, ROS 2 Jazzy, ament_cmake and colcon into .venv (about a minute)"
  # Reuse an existing .venv: pip only adds what changed, and a running test keeps working.
  [[ -x .venv/bin/python ]] || "$python" -m venv .venv
  # pip's output goes to a log, shown only when the install fails.
  log=.venv/install.log
  if ! { .venv/bin/python -m pip install -q --upgrade pip &&
         .venv/bin/python -m pip install -q -e ".[$extras]"; } >"$log" 2>&1; then
    grep -v '^WARNING: Location' "$log" >&2
    echo "setup: pip install failed (full log: $log)" >&2
    exit 1
  fi
  .venv/bin/ros-isolated-test --help >/dev/null
  rm -f .venv/.installed-*
  touch "$stamp"
fi

# The demo needs no more than .venv (and the CMake package linked below).
if [[ $mode == all ]]; then
# ROS 2 Kilted beside Jazzy, in a venv of its own (the wheels of two distros cannot share
# one): the Kilted tier of the test suite and the benchmarks against Kilted's runner use
# it. ROS_ISOLATED_TEST_NO_KILTED=1 leaves it out (that tier then says it was skipped).
kilted_stamp=.venv-kilted/.installed-$(sha256sum pyproject.toml | cut -c1-16)
if [[ ${ROS_ISOLATED_TEST_NO_KILTED:-} != 1 && ! -f $kilted_stamp ]]; then
  echo "setup: installing ros-isolated-test with ROS 2 Kilted into .venv-kilted (about a minute)"
  [[ -x .venv-kilted/bin/python ]] || "$python" -m venv .venv-kilted
  log=.venv-kilted/install.log
  if ! { .venv-kilted/bin/python -m pip install -q --upgrade pip &&
         .venv-kilted/bin/python -m pip install -q -e ".[kilted]"; } >"$log" 2>&1; then
    grep -v '^WARNING: Location' "$log" >&2
    echo "setup: pip install failed (full log: $log)" >&2
    exit 1
  fi
  .venv-kilted/bin/ros-isolated-test --help >/dev/null
  rm -f .venv-kilted/.installed-*
  touch "$kilted_stamp"
fi

# colcon's domain-ID coordinator (a colcon extension) apart from .venv, in
# .venv/colcon-coordinator: only a colcon given that folder on PYTHONPATH loads it
# (tests/e2e/test_colcon_coordinator.py). Installed into .venv itself, it would set
# ROS_DOMAIN_ID for every colcon run of the suite.
coordinator=colcon-ros-domain-id-coordinator==0.2.4
coordinator_stamp=.venv/colcon-coordinator/.installed-${coordinator}
if [[ -x .venv/bin/python && ! -f $coordinator_stamp ]]; then
  echo "setup: installing $coordinator into .venv/colcon-coordinator"
  rm -rf .venv/colcon-coordinator
  log=.venv/install-coordinator.log
  if ! .venv/bin/python -m pip install -q --no-deps --target .venv/colcon-coordinator "$coordinator" >"$log" 2>&1; then
    grep -v '^WARNING: Location' "$log" >&2
    echo "setup: pip install failed (full log: $log)" >&2
    exit 1
  fi
  touch "$coordinator_stamp"
fi

# What a Jazzy user on Ubuntu 24.04 has, in .venv-distro: ROS 2 Jazzy (the ros extra) and
# colcon on exactly the setuptools, click, filelock and lxml Ubuntu ships
# (scripts/ubuntu-24.04-constraints.txt), and NOT this project: tests/e2e/test_ros_package.py
# builds it there as a package of a colcon workspace. ROS_ISOLATED_TEST_NO_DISTRO=1 leaves
# it out (those tests then say they were skipped).
constraints=scripts/ubuntu-24.04-constraints.txt
distro_stamp=.venv-distro/.installed-$(cat pyproject.toml "$constraints" | sha256sum | cut -c1-16)
if [[ ${ROS_ISOLATED_TEST_NO_DISTRO:-} != 1 && ! -f $distro_stamp ]]; then
  echo "setup: installing ROS 2 Jazzy and colcon on Ubuntu 24.04's Python packages into .venv-distro (about a minute)"
  [[ -x .venv-distro/bin/python ]] || "$python" -m venv .venv-distro
  mapfile -t ros_extra < <(.venv/bin/python -c 'import tomllib
print("\n".join(tomllib.load(open("pyproject.toml", "rb"))["project"]["optional-dependencies"]["ros"]))')
  log=.venv-distro/install.log
  if ! { .venv-distro/bin/python -m pip install -q --upgrade pip &&
         .venv-distro/bin/python -m pip install -q -c "$constraints" -r "$constraints" "${ros_extra[@]}"; } >"$log" 2>&1; then
    grep -v '^WARNING: Location' "$log" >&2
    echo "setup: pip install failed (full log: $log)" >&2
    exit 1
  fi
  rm -f .venv-distro/.installed-*
  touch "$distro_stamp"
fi

fi  # mode

# An editable install does not copy data files: CMake's find_package(ros_isolated_test)
# looks for the package config under .venv/share, next to .venv/bin on PATH.
for venv in .venv .venv-kilted; do
  [[ -d $venv ]] || continue
  mkdir -p "$venv/share/ros_isolated_test"
  [[ -e $venv/share/ros_isolated_test/cmake ]] || ln -s "$root/ros_isolated_test/cmake" "$venv/share/ros_isolated_test/cmake"
done

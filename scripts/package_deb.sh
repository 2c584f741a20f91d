#!/usr/bin/env bash
# Builds the Debian package of ros_isolated_test as the ROS build farm would, offline:
#   scripts/package_deb.sh OUTDIR
# leaves OUTDIR/ros-jazzy-ros-isolated-test_<version>-0noble_all.deb.
#
# bloom-generate rosdebian (ROS 2 Jazzy, Ubuntu noble) writes debian/ into a temporary copy
# of the package (the checkout is never written); dpkg-buildpackage -b -us -uc builds it,
# dh_auto_test included. Everything bloom and rosdep read is written locally first: a
# rosdistro index (ROSDISTRO_INDEX_URL=file://...) whose jazzy is a ROS 2 distribution on
# noble, and a rosdep source list (ROSDEP_SOURCE_PATH) with the keys package.xml names.
#
# Changes to bloom's output, which the bloom release repository carries as its patches
# (git-bloom-patch):
# - debian/rules: `dh_auto_test || true` becomes `dh_auto_test`: a failing test fails the
#   build. The test runs the built package (pybuild's default, unittest discovery, finds no
#   tests in it): `--version`, then `run` of a test on an ID of its own, with its result file
#   (click, filelock and lxml: package.xml's test depends, so the build has them);
# - debian/rules: dh_python3 looks after the bytecode under /opt/ros/jazzy/lib (py3compile
#   on install, py3clean on removal), so apt-get remove leaves nothing behind;
# - debian/control: `Architecture: all` (bloom's template says any): the package is pure
#   Python, the same on every architecture;
# - debian/control: an empty entry in Build-Depends (bloom's template joins an empty list)
#   is dropped;
# - debian/control: ros-jazzy-ros-workspace joins Depends. The farm's bloom-release adds it
#   to every ROS 2 package (it owns /opt/ros/jazzy/setup.sh, which puts the package's bin
#   and Python folders on the paths); a standalone bloom-generate leaves it out. It is not
#   added to Build-Depends: the build sources /opt/ros/jazzy/setup.sh only where present,
#   needs nothing else of it, and this machine need not have ROS from apt.
#
# Needs: bloom and rosdep (pip: bloom, rosdep, rosdistro, catkin_pkg; found on PATH or in
# .venv), and from apt debhelper, dh-python, python3-all, python3-setuptools, fakeroot and
# the package's test dependencies (python3-click, python3-filelock, python3-lxml).
# scripts/setup.sh installs them all. PACKAGE_DEB_KEEP=1 keeps the temporary folder (the
# logs, debian/) for a look.
set -euo pipefail

if [[ $# -ne 1 ]]; then
  echo "usage: scripts/package_deb.sh OUTDIR (the folder that receives the .deb)" >&2
  exit 2
fi
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
mkdir -p "$1"
out=$(cd "$1" && pwd)

tool() {
  if command -v "$1" >/dev/null 2>&1; then
    command -v "$1"
  elif [[ -x $root/.venv/bin/$1 ]]; then
    echo "$root/.venv/bin/$1"
  else
    echo "package_deb: $1 not found: pip install bloom rosdep (scripts/setup.sh installs them into .venv)" >&2
    exit 1
  fi
}
bloom_generate=$(tool bloom-generate)
rosdep=$(tool rosdep)
for needed in dpkg-buildpackage dh_python3 fakeroot; do
  if ! command -v "$needed" >/dev/null 2>&1; then
    echo "package_deb: $needed not found: apt install debhelper dh-python fakeroot (scripts/setup.sh does)" >&2
    exit 1
  fi
done

work=$(mktemp -d "${TMPDIR:-/tmp}/package-deb.XXXXXX")
[[ ${PACKAGE_DEB_KEEP:-} == 1 ]] || trap 'rm -rf "$work"' EXIT

# The package: the checkout's files as git lists them (tracked, and new files not ignored);
# outside git (an unpacked sdist), the folder's files but for venvs and build output.
src=$work/ros_isolated_test
mkdir -p "$src"
(
  cd "$root"
  if git rev-parse --is-inside-work-tree >/dev/null 2>&1; then
    git ls-files -z --cached --others --exclude-standard |
      while IFS= read -r -d '' file; do [[ -e $file ]] && printf '%s\0' "$file"; done |
      tar --null -T - -cf -
  else
    tar --exclude='./.venv*' --exclude=./build --exclude=./install --exclude=./log \
      --exclude='*.egg-info' --exclude=__pycache__ -cf - .
  fi
) | tar -xf - -C "$src"

# The rosdistro index: one ROS 2 distribution, jazzy, on Ubuntu noble.
mkdir -p "$work/rosdistro/jazzy"
cat >"$work/rosdistro/index-v4.yaml" <<'EOF'
%YAML 1.1
---
distributions:
  jazzy:
    distribution: [jazzy/distribution.yaml]
    distribution_status: active
    distribution_type: ros2
    python_version: 3
type: index
version: 4
EOF
cat >"$work/rosdistro/jazzy/distribution.yaml" <<'EOF'
%YAML 1.1
---
release_platforms:
  ubuntu: [noble]
repositories: {}
type: distribution
version: 2
EOF

# The rosdep keys package.xml names, as rosdep's base.yaml and python.yaml map them.
mkdir -p "$work/rosdep/sources.list.d"
cat >"$work/rosdep/base.yaml" <<'EOF'
python3-click:
  debian: [python3-click]
  ubuntu: [python3-click]
python3-filelock:
  debian: [python3-filelock]
  ubuntu: [python3-filelock]
python3-lxml:
  debian: [python3-lxml]
  ubuntu: [python3-lxml]
EOF
echo "yaml file://$work/rosdep/base.yaml" >"$work/rosdep/sources.list.d/50-local.list"

export ROSDISTRO_INDEX_URL="file://$work/rosdistro/index-v4.yaml"
export ROSDEP_SOURCE_PATH=$work/rosdep/sources.list.d
export ROS_HOME=$work/ros_home # rosdep's cache, away from the user's
export ROS_DISTRO=jazzy
"$rosdep" update --rosdistro jazzy >"$work/rosdep-update.log" 2>&1 ||
  { cat "$work/rosdep-update.log" >&2; exit 1; }

cd "$src"
# bloom starts `bloom-update` from PATH in the background, which asks PyPI for a newer bloom
# and writes ~/.bloom: offline, and leaving the user's home alone, a no-op takes its place.
mkdir -p "$work/bin"
printf '#!/bin/sh\nexit 0\n' >"$work/bin/bloom-update"
chmod +x "$work/bin/bloom-update"
PATH="$work/bin:$PATH" "$bloom_generate" rosdebian \
  --os-name ubuntu --os-version noble --ros-distro jazzy . >"$work/bloom.log" 2>&1 ||
  { cat "$work/bloom.log" >&2; exit 1; }

# The release repository's patches (see the top of this file).
grep -q 'dh_auto_test || true' debian/rules ||
  { echo "package_deb: bloom's rules changed: no 'dh_auto_test || true' to make strict" >&2; exit 1; }
sed -i 's/dh_auto_test || true/dh_auto_test/' debian/rules
cat >>debian/rules <<'EOF'

# From the release repository: dh_auto_test runs the built package in pybuild's build folder.
export PYBUILD_TEST_CUSTOM=1
export PYBUILD_TEST_ARGS={interpreter} -m ros_isolated_test --version && \
	ROS_ISOLATED_TEST_LOCK_DIR={home_dir}/locks {interpreter} -m ros_isolated_test run \
	--junit-xml {home_dir}/smoke.xml -- {interpreter} -c pass && grep -q 'failures="0"' {home_dir}/smoke.xml

# From the release repository: the Python files under the prefix get their bytecode from
# py3compile when installed and lose it to py3clean when removed, as Debian's own Python
# packages do; without it, the bytecode Python writes there when root runs the command
# stays behind after apt-get remove.
override_dh_python3:
	dh_python3
	dh_python3 /opt/ros/jazzy/lib
EOF
sed -i -E '/^Build-Depends:/s/, *,/,/g' debian/control
sed -i -E 's/^Architecture: any$/Architecture: all/' debian/control
grep -q '^Depends:.*ros-jazzy-ros-workspace' debian/control ||
  sed -i -E 's/^(Depends: .*)$/\1, ros-jazzy-ros-workspace/' debian/control

# Debian's own tools and Python, never a venv's: pybuild runs the python3 it finds on PATH.
env -u VIRTUAL_ENV -u PYTHONPATH -u PYTHONHOME PATH=/usr/sbin:/usr/bin:/sbin:/bin \
  dpkg-buildpackage -b -us -uc >"$work/build.log" 2>&1 ||
  { tail -60 "$work/build.log" >&2; echo "package_deb: dpkg-buildpackage failed" >&2; exit 1; }
cp "$work/build.log" "$out/ros-jazzy-ros-isolated-test.build.log"
debs=("$work"/ros-jazzy-ros-isolated-test_*.deb)
cp "${debs[@]}" "$out/"
for deb in "${debs[@]}"; do echo "$out/$(basename "$deb")"; done

#!/usr/bin/env bash
# The runner supports Python 3.10 and newer, but the ROS wheels are built for 3.11 only:
# install the bare runner (no ROS extra) for the oldest supported Python, when this
# machine has it, and run its own test of a shell run and a ctest-style RUNNER run.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$root"
python=python3.10
if ! "$python" -c '' >/dev/null 2>&1; then
  # pyenv installs versions it does not put on PATH; look there too.
  python=$(ls -d "$(pyenv root 2>/dev/null || echo /nonexistent)"/versions/3.10*/bin/python3.10 2>/dev/null | tail -1)
  if [[ -z $python ]]; then
    echo "py310 smoke: skipped, no Python 3.10 on this machine"
    exit 0
  fi
fi
venv=.venv-py310
stamp=$venv/.installed-$(sha256sum pyproject.toml | cut -c1-16)
if [[ ! -f $stamp ]]; then
  rm -rf "$venv"
  "$python" -m venv "$venv"
  "$venv/bin/python" -m pip install -q -e . 2>&1 | { grep -v '^WARNING: Location' || true; }
  touch "$stamp"
fi
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
export ROS_ISOLATED_TEST_LOCK_DIR=$work/locks
unset ROS_DOMAIN_ID DISABLE_ROS_ISOLATION ROS_ISOLATED_TEST_DOMAINS
out=$("$venv/bin/ros-isolated-test" run --junit-xml "$work/r/pkg/shell.xml" -- sh -c 'echo "id=$ROS_DOMAIN_ID"')
grep -q '^Running with ROS_DOMAIN_ID [1-9]' <<<"$out"
grep -q 'failures="0"' "$work/r/pkg/shell.xml"
script=$("$venv/bin/ros-isolated-test" runner-path)
"$venv/bin/python" -u "$script" "$work/r/pkg/ctest.xml" --package-name pkg \
  --generate-result-on-success --command sh -c 'test -n "$ROS_DOMAIN_ID"' >/dev/null
grep -q 'errors="0"' "$work/r/pkg/ctest.xml"
echo "py310 smoke: passed on $("$venv/bin/python" --version)"

#!/usr/bin/env bash
# The runner supports Python 3.10 and newer, but the ROS wheels are built for 3.11 only:
# install the bare runner (no ROS extra) for other Pythons, when this machine has them, and
# run its own test of a shell run, a ctest-style RUNNER run and a run that waits for an ID:
#   - 3.10, the oldest supported, with the newest click, filelock and lxml;
#   - 3.12, ROS 2 Jazzy's Python on Ubuntu 24.04, with exactly the setuptools, wheel, click,
#     filelock and lxml Ubuntu 24.04 ships (scripts/ubuntu-24.04-constraints.txt), built by
#     that setuptools without build isolation, as apt's Python would build it. This venv
#     (.venv-py312) also has the test tools: scripts/ubuntu_tier.sh runs tests in it.
# In strict mode (ROS_ISOLATED_TEST_NO_SKIPS=1, as CI runs) a missing 3.12 is a failure.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$root"
constraints=scripts/ubuntu-24.04-constraints.txt

# A Python X.Y: on PATH, else the newest pyenv has (pyenv installs versions it does not put
# on PATH); nothing printed when there is none.
find_python() {
  local version=$1 found
  if "python$version" -c '' >/dev/null 2>&1; then
    command -v "python$version"
    return
  fi
  found=$(ls -d "$(pyenv root 2>/dev/null || echo /nonexistent)"/versions/"$version".*/bin/"python$version" 2>/dev/null |
    sort -V | tail -1)
  [[ -n $found ]] && echo "$found"
  return 0
}

# Make (or keep) the venv for one Python; the stamp covers everything it is made of.
make_venv() {
  local python=$1 venv=$2 mode=$3 stamp
  stamp=$venv/.installed-$(cat pyproject.toml "$constraints" "${BASH_SOURCE[0]}" | sha256sum | cut -c1-16)
  [[ -f $stamp ]] && return
  rm -rf "$venv"
  "$python" -m venv "$venv"
  local pip=("$venv/bin/python" -m pip install -q --disable-pip-version-check)
  {
    if [[ $mode == ubuntu ]]; then
      # apt's build tools and libraries first, then this project built by them (no build
      # isolation: pip must not fetch a newer setuptools), then the tools the tier runs.
      "${pip[@]}" -c "$constraints" -r "$constraints"
      "${pip[@]}" -c "$constraints" --no-build-isolation -e .
      # (upstream's domain_coordinator, pure Python, holds a port in the suite's busy machine)
      "${pip[@]}" -c "$constraints" pytest pytest-timeout pytest-xdist junitparser \
        unittest-xml-reporting ros-jazzy-domain-coordinator
    else
      "${pip[@]}" -e .
    fi
  } 2>&1 | { grep -v '^WARNING: Location' || true; }
  "$venv/bin/ros-isolated-test" --version >/dev/null
  touch "$stamp"
}

# Wait until a file matching $1 exists; fail, showing its log $3, if process $2 ends first.
appears() {
  until compgen -G "$1" >/dev/null; do
    kill -0 "$2" 2>/dev/null || { cat "$3" >&2; return 1; }
    sleep 0.05
  done
}

# The runner's own checks, in a lock directory of their own with a pool of two IDs that are
# free now (the test suite's helper picks them: other ROS work may hold any ID).
smoke() {
  local venv=$1 work pool
  work=$(mktemp -d)
  # shellcheck disable=SC2064 # the folder is fixed now
  trap "rm -rf '$work'" RETURN
  pool=$(cd tests && ../.venv/bin/python -c 'from helpers.domains import free_ids
print(*free_ids(2), sep=",")')
  (
    trap 'touch "$work/go"' EXIT # holders never outlive a failed check
    export ROS_ISOLATED_TEST_LOCK_DIR=$work/locks ROS_ISOLATED_TEST_DOMAINS=$pool
    unset ROS_DOMAIN_ID DISABLE_ROS_ISOLATION ROS_ISOLATED_TEST_HELD_DOMAIN_ID
    cli=$venv/bin/ros-isolated-test
    out=$("$cli" run --junit-xml "$work/r/pkg/shell.xml" -- sh -c 'echo "id=$ROS_DOMAIN_ID"')
    grep -q "^Running with ROS_DOMAIN_ID \(${pool/,/\\|}\)\b" <<<"$out"
    grep -q 'failures="0"' "$work/r/pkg/shell.xml"
    script=$("$cli" runner-path)
    "$venv/bin/python" -u "$script" "$work/r/pkg/ctest.xml" --package-name pkg \
      --generate-result-on-success --command sh -c 'test -n "$ROS_DOMAIN_ID"' >/dev/null
    grep -q 'errors="0"' "$work/r/pkg/ctest.xml"
    # Both IDs held until a third runner has queued: it waits, then gets one.
    for n in 1 2; do
      "$cli" run -- sh -c "touch '$work/held-$n'; while [ ! -e '$work/go' ]; do sleep 0.05; done" \
        >"$work/holder-$n.log" 2>&1 &
      appears "$work/held-$n" $! "$work/holder-$n.log"
    done
    "$cli" run --junit-xml "$work/r/pkg/waited.xml" -- true >"$work/waiter.log" 2>&1 &
    waiter=$!
    appears "$work/locks/queue*/*.ticket" $waiter "$work/waiter.log"
    touch "$work/go"
    wait "$waiter" || { cat "$work/waiter.log"; exit 1; }
    wait
    grep -q 'waiting for a free ROS_DOMAIN_ID' "$work/waiter.log" || { cat "$work/waiter.log"; exit 1; }
    grep -q 'failures="0"' "$work/r/pkg/waited.xml"
  )
}

python310=$(find_python 3.10)
if [[ -n $python310 ]]; then
  make_venv "$python310" .venv-py310 newest
  smoke .venv-py310
  echo "py310 smoke: passed on $(.venv-py310/bin/python --version)"
else
  echo "py310 smoke: skipped, no Python 3.10 on this machine"
fi

python312=$(find_python 3.12)
if [[ -z $python312 ]]; then
  if [[ ${ROS_ISOLATED_TEST_NO_SKIPS:-} == 1 ]]; then
    echo "py312 smoke: no Python 3.12 on this machine (strict mode: a failure); install it (pyenv install 3.12)" >&2
    exit 1
  fi
  echo "py312 smoke: skipped, no Python 3.12 on this machine"
  exit 0
fi
make_venv "$python312" .venv-py312 ubuntu
smoke .venv-py312
echo "py312 smoke: passed on $(.venv-py312/bin/python --version) with Ubuntu 24.04's $(
  .venv-py312/bin/python -c 'import importlib.metadata as m
print(", ".join(f"{n} {m.version(n)}" for n in ("setuptools", "click", "filelock", "lxml")))')"

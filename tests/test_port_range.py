"""The default pool keeps clear of the ephemeral port range of the runner's network namespace.

Each test runs the real runner in a network namespace of its own, whose
``net.ipv4.ip_local_port_range`` it sets (the setting is per namespace, as in a container
or on a tuned host) and reads back, so the host's own range never decides the outcome.
Lock directories are the tests' own (the ``env`` fixture).
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import CLI, HUNG
from helpers.domains import free_ids
from helpers.results import domain_of, load_result

from ros_isolated_test.domain_coordinator import POOL_ENV
from ros_isolated_test.domain_coordinator.pool import (
    LINUX_DEFAULT_PORT_RANGE,
    PORT_RANGE_FILE,
    in_port_range,
)

pytestmark = [capabilities.NETWORK_NAMESPACES.mark]

#: Sets the namespace's range, writes what the kernel then reports, runs the command.
_IN_NAMESPACE = (
    'printf "%s\\n" "$1" > ' + PORT_RANGE_FILE + " && cat " + PORT_RANGE_FILE + ' > "$2" && '
    'shift 2 && exec "$@"'
)
NOTE = "-- ros-isolated-test: "
#: Clear of 1-50: the IDs a fresh lock directory would hand out first.
LOW_IDS_IN_RANGE = (7000, 19999)
#: Linux's default: the positive control, where nothing is left out.
DEFAULT = LINUX_DEFAULT_PORT_RANGE


def _in_namespace(
    port_range: tuple[int, int],
    command: Sequence[str],
    env: dict[str, str],
    tmp_path: Path,
) -> subprocess.CompletedProcess[str]:
    """``command`` in a new network namespace whose ephemeral port range is ``port_range``.

    Fails unless the namespace reports that very range back: the proof it is in effect.
    """
    readback = tmp_path / "range-in-namespace"
    readback.unlink(missing_ok=True)
    wanted = f"{port_range[0]} {port_range[1]}"
    done = subprocess.run(
        ["unshare", "--net", "sh", "-c", _IN_NAMESPACE, "sh", wanted, str(readback), *command],
        env=env,
        capture_output=True,
        text=True,
        timeout=HUNG,
        check=False,
    )
    assert readback.read_text().split() == wanted.split(), done.stderr
    return done


def _notes(stdout: str) -> list[str]:
    return [line.removeprefix(NOTE) for line in stdout.splitlines() if line.startswith(NOTE)]


def _pool_in_namespace(
    port_range: tuple[int, int], env: dict[str, str], tmp_path: Path
) -> tuple[list[int], list[str]]:
    """The pool and notes the real settings reader gives inside such a namespace."""
    show = (
        "import json; from ros_isolated_test.runner import settings; "
        "config = settings.read(); print(json.dumps([list(config.pool), list(config.notes)]))"
    )
    done = _in_namespace(port_range, [sys.executable, "-c", show], env, tmp_path)
    assert done.returncode == 0, done.stderr
    pool, notes = json.loads(done.stdout)
    return pool, notes


def _domain_seen(stdout: str) -> int:
    seen = [int(line[3:]) for line in stdout.splitlines() if line.startswith("id=")]
    assert len(seen) == 1, stdout
    return seen[0]


ECHO_ID = ["sh", "-c", 'echo "id=$ROS_DOMAIN_ID"']


def test_ids_in_the_namespace_range_are_left_out_with_one_note(
    env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "r.xml"
    done = _in_namespace(
        LOW_IDS_IN_RANGE, [CLI, "run", "--junit-xml", str(result), "--", *ECHO_ID], env, tmp_path
    )
    assert done.returncode == 0, done.stdout + done.stderr
    domain_id = domain_of(done.stdout)
    # A fresh lock directory hands out the lowest free ID: 1-50 are left out here.
    assert 51 <= domain_id <= 101, done.stdout
    assert not in_port_range(domain_id, LOW_IDS_IN_RANGE)
    assert _domain_seen(done.stdout) == domain_id
    left_out = [note for note in _notes(done.stdout) if "left out of the default pool" in note]
    assert left_out == [
        "IDs 1-50 left out of the default pool, which is 51-101 here: their DDS ports fall in "
        "this host's ephemeral port range 7000-19999 (net.ipv4.ip_local_port_range); set "
        f"{POOL_ENV} to choose IDs yourself (clear of it: 51-232)"
    ], done.stdout
    assert load_result(result).properties["settings_notes"] == left_out[0]


def test_a_namespace_with_the_default_range_keeps_the_full_pool_silently(
    env: dict[str, str], tmp_path: Path
) -> None:
    """Positive control: the same kind of namespace, Linux's default range, nothing left out."""
    assert _pool_in_namespace(DEFAULT, env, tmp_path) == (list(range(1, 102)), [])
    result = tmp_path / "r.xml"
    done = _in_namespace(
        DEFAULT, [CLI, "run", "--junit-xml", str(result), "--", *ECHO_ID], env, tmp_path
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert 1 <= domain_of(done.stdout) <= 101
    assert not [note for note in _notes(done.stdout) if "ephemeral port range" in note]
    assert "ephemeral" not in done.stderr
    assert "settings_notes" not in load_result(result).properties


@pytest.mark.parametrize(
    ("port_range", "pool"),
    [
        ((20000, 60999), list(range(1, 51))),
        (LOW_IDS_IN_RANGE, list(range(51, 102))),
        ((32700, 60999), list(range(1, 101))),  # 101's ports end at 32723
    ],
)
def test_the_settings_read_the_namespace_range(
    port_range: tuple[int, int], pool: list[int], env: dict[str, str], tmp_path: Path
) -> None:
    found, notes = _pool_in_namespace(port_range, env, tmp_path)
    assert found == pool
    assert len(notes) == 1 and "left out of the default pool" in notes[0]


@pytest.mark.parametrize("entry", ["run", "runner"])
def test_a_range_leaving_no_default_id_is_a_one_line_error_with_a_result_file(
    entry: str, env: dict[str, str], runner_script: str, tmp_path: Path
) -> None:
    marker = tmp_path / "ran"
    result = tmp_path / "out" / "r.xml"
    if entry == "run":
        command = [CLI, "run", "--junit-xml", str(result), "--", "touch", str(marker)]
    else:
        command = [sys.executable, "-u", runner_script, str(result), "--package-name", "pkg"]
        command += ["--command", "touch", str(marker)]
    done = _in_namespace((1024, 65000), command, env, tmp_path)
    assert done.returncode == 2, done.stdout + done.stderr
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, done.stderr
    assert lines[0].startswith("ros-isolated-test: error: no ID of the default domain pool 1-101")
    assert "1024-65000 (net.ipv4.ip_local_port_range)" in lines[0]
    assert f"set {POOL_ENV} to IDs clear of it (231-232)" in lines[0]
    assert not marker.exists()
    assert "Running with ROS_DOMAIN_ID" not in done.stdout
    summary = load_result(result)
    assert summary.properties["exit"] == "not run"
    assert summary.only.outcome == "error"
    assert "no ID of the default domain pool 1-101 is usable" in summary.only.message


def test_an_explicit_pool_in_the_range_is_used_with_one_warning(
    env: dict[str, str], tmp_path: Path
) -> None:
    (chosen,) = free_ids(1, range(51, 102))  # in 20000-60999, and free now
    env[POOL_ENV] = str(chosen)
    done = _in_namespace((20000, 60999), [CLI, "run", "--", *ECHO_ID], env, tmp_path)
    assert done.returncode == 0, done.stdout + done.stderr
    assert domain_of(done.stdout) == chosen == _domain_seen(done.stdout)
    warnings = [note for note in _notes(done.stdout) if "ephemeral port range" in note]
    assert warnings == [
        f"WARNING: {POOL_ENV} names ID {chosen} whose DDS ports fall in this host's ephemeral "
        "port range 20000-60999 (net.ipv4.ip_local_port_range): another program's connection "
        "can take such a port and break discovery on that ID; used as given (IDs clear of "
        "it: 1-50, 215-232)"
    ], done.stdout


@pytest.mark.parametrize("as_json", [False, True])
def test_status_names_the_pool_it_would_use(
    as_json: bool, env: dict[str, str], tmp_path: Path
) -> None:
    args = [CLI, "status", *(["--json"] if as_json else [])]
    narrowed = _in_namespace(LOW_IDS_IN_RANGE, args, env, tmp_path)
    assert narrowed.returncode == 0, narrowed.stderr
    notes = [line for line in narrowed.stderr.splitlines() if "left out" in line]
    assert len(notes) == 1, narrowed.stderr
    assert notes[0].startswith(
        "ros-isolated-test: IDs 1-50 left out of the default pool, which is 51-101 here: "
    )
    control = _in_namespace(DEFAULT, args, env, tmp_path)
    assert control.returncode == 0, control.stderr
    assert "left out" not in control.stderr
    if as_json:  # the note stays off stdout: both still parse
        json.loads(narrowed.stdout)
        json.loads(control.stdout)

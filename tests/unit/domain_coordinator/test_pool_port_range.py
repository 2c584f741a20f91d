"""The default pool keeps clear of the ephemeral port range (``pool``'s port-range part).

DDS binds fixed UDP ports computed from the ID (7400 + 250*ID, 74 of them); the kernel
hands out ephemeral ports from ``net.ipv4.ip_local_port_range``. IDs whose ports fall in
that range are left out of the default pool with one note naming them and the fix; an
explicit pool in the range is used as given with one warning; a range that leaves no
default ID is a one-line error. First the computation, on ranges given explicitly (so
this host's never decides); then the real runner in a network namespace of its own,
whose ``net.ipv4.ip_local_port_range`` each test sets (the setting is per namespace, as
in a container or on a tuned host) and reads back. Lock directories are the tests' own
(the ``env`` fixture).
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
from helpers.coordinator import PRINT_ID, error_lines, ids_seen
from helpers.domains import free_ids
from helpers.results import domain_of, load_result

from ros_isolated_test.domain_coordinator import POOL_ENV, PoolSpecError, parse_pool
from ros_isolated_test.domain_coordinator.pool import (
    DDS_PORT_SPAN,
    HIGHEST_VALID_ID,
    LINUX_DEFAULT_PORT_RANGE,
    PORT_RANGE_FILE,
    choose_pool,
    dds_ports,
    default_pool,
    explicit_warnings,
    id_ranges,
    in_port_range,
    parse_port_range,
    read_port_range,
)
from ros_isolated_test.runner import settings

DEFAULT_POOL = tuple(range(1, 102))
#: Linux's default range, given explicitly: these tests must not depend on this host's.
LINUX = LINUX_DEFAULT_PORT_RANGE


def test_a_domain_needs_74_ports_from_7400_plus_250_per_id() -> None:
    """Multicast at +0, then +10/+11 + 2*i for the 32 participants LOCALHOST announces."""
    assert DDS_PORT_SPAN == 11 + 2 * 31
    assert dds_ports(0) == (7400, 7473)
    assert dds_ports(5) == (8650, 8723)  # measured: a participant on 5 binds 8660 and 8661
    assert dds_ports(HIGHEST_VALID_ID) == (65400, 65473)


@pytest.mark.parametrize(
    ("domain_id", "inside"),
    [(1, False), (101, False), (102, True), (150, True), (214, True), (215, False), (232, False)],
)
def test_linux_default_range_holds_102_to_214(domain_id: int, inside: bool) -> None:
    assert in_port_range(domain_id, LINUX) is inside


def test_the_default_range_leaves_the_default_pool_as_it_was() -> None:
    assert default_pool(LINUX) == (DEFAULT_POOL, ())
    assert choose_pool({}, LINUX) == (DEFAULT_POOL, ())


@pytest.mark.parametrize(
    ("port_range", "domain_id", "inside"),
    [
        ((dds_ports(50)[1], 60999), 50, True),  # the range starts at 50's last port
        ((dds_ports(50)[1] + 1, 60999), 50, False),  # one above it
        ((1024, dds_ports(51)[0]), 51, True),  # the range ends at 51's first port
        ((1024, dds_ports(51)[0] - 1), 51, False),  # one below it
        ((dds_ports(60)[0] + 5, dds_ports(60)[0] + 5), 60, True),  # a one-port range inside
        ((dds_ports(60)[0] + 5, dds_ports(60)[0] + 5), 59, False),
        ((dds_ports(60)[0] + 5, dds_ports(60)[0] + 5), 61, False),
    ],
)
def test_both_ends_of_the_range_count(
    port_range: tuple[int, int], domain_id: int, inside: bool
) -> None:
    """Linux's range is inclusive at both ends, and one shared port is a clash."""
    assert in_port_range(domain_id, port_range) is inside


def test_a_lower_range_leaves_out_51_to_101_in_one_line() -> None:
    pool, notes = default_pool((20000, 60999))
    assert pool == tuple(range(1, 51))  # 50 ends at 19973, 51 starts at 20150
    assert len(notes) == 1 and "\n" not in notes[0]
    assert notes[0].startswith("IDs 51-101 left out of the default pool, which is 1-50 here:")
    assert "20000-60999 (net.ipv4.ip_local_port_range)" in notes[0]
    assert f"set {POOL_ENV} to choose IDs yourself (clear of it: 1-50, 215-232)" in notes[0]


def test_a_range_below_the_default_leaves_out_the_lowest_ids() -> None:
    pool, notes = default_pool((7000, 19999))
    assert pool == tuple(range(51, 102))
    assert notes[0].startswith("IDs 1-50 left out of the default pool, which is 51-101 here:")


def test_one_id_left_out_is_named_alone() -> None:
    pool, notes = default_pool((dds_ports(101)[0], 60999))
    assert pool == tuple(range(1, 101))
    assert notes[0].startswith("ID 101 left out of the default pool, which is 1-100 here:")


def test_the_default_pool_never_reaches_beyond_1_to_101() -> None:
    """On a host whose range holds 1-101 but not 215-232, no ID is added: that is an error."""
    with pytest.raises(PoolSpecError) as raised:
        default_pool((1024, 61000))
    message = str(raised.value)
    assert "\n" not in message
    assert "no ID of the default domain pool 1-101 is usable" in message
    assert "1024-61000 (net.ipv4.ip_local_port_range)" in message
    assert f"set {POOL_ENV} to IDs clear of it (215-232)" in message
    assert "move or narrow the range" in message


def test_a_range_covering_every_id_is_an_error_naming_both_fixes() -> None:
    with pytest.raises(PoolSpecError) as raised:
        choose_pool({}, (1024, 65535))
    message = str(raised.value)
    assert f"set {POOL_ENV} to IDs anyway (none of 1-232 is clear)" in message
    assert "move or narrow the range" in message
    with pytest.raises(settings.SettingsError, match="no ID of the default domain pool"):
        settings.read({}, port_range=(1024, 65535))


def test_usage_errors_never_trip_on_the_port_range() -> None:
    """A usage error's result file is built from the defaults, on any host."""
    assert settings.defaults().pool == DEFAULT_POOL
    assert settings.defaults().notes == ()


@pytest.mark.parametrize(
    ("spec", "named"),
    [
        ("100-110,150,5", "IDs 102-110, 150 "),
        ("150", "ID 150 "),
        ("214,102,103,104", "IDs 102-104, 214 "),
    ],
)
def test_an_explicit_pool_is_used_as_given_with_one_warning(spec: str, named: str) -> None:
    pool, notes = choose_pool({POOL_ENV: spec}, LINUX)
    assert pool == parse_pool(spec)
    assert len(notes) == 1 and "\n" not in notes[0]
    assert notes[0].startswith(f"WARNING: {POOL_ENV} names {named}whose DDS ports fall in ")
    assert "32768-60999 (net.ipv4.ip_local_port_range)" in notes[0]
    assert "used as given" in notes[0]


@pytest.mark.parametrize("spec", ["1-101", "1-50,215-232", "101", "215"])
def test_an_explicit_pool_clear_of_the_range_says_nothing(spec: str) -> None:
    assert choose_pool({POOL_ENV: spec}, LINUX) == (parse_pool(spec), ())
    assert explicit_warnings(parse_pool(spec), LINUX) == ()


def test_settings_carry_the_notes() -> None:
    assert settings.read({}, port_range=(20000, 60999)).notes == default_pool((20000, 60999))[1]
    assert settings.read({POOL_ENV: "150"}, port_range=LINUX).notes == explicit_warnings(
        (150,), LINUX
    )
    assert settings.read({}, port_range=LINUX).notes == ()


@pytest.mark.parametrize(
    ("ids", "text"),
    [
        ([], ""),
        ([7], "7"),
        ([3, 1, 2], "1-3"),
        ([1, 2, 3, 5, 7, 8], "1-3, 5, 7-8"),
        ((150, 102, 103, 110, 104), "102-104, 110, 150"),
        ([4, 4, 5], "4-5"),
    ],
)
def test_id_ranges_compresses_consecutive_ids(ids: list[int], text: str) -> None:
    assert id_ranges(ids) == text


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("32768\t60999\n", (32768, 60999)),
        ("  20000   60999  ", (20000, 60999)),
        ("5000 5000", (5000, 5000)),
        ("", None),
        ("32768", None),
        ("32768 60999 1", None),
        ("a b", None),
        ("60999 32768", None),
        ("0 100", None),
        ("1 65536", None),
        ("-1 5", None),
        ("1_0 20", None),
    ],
)
def test_parse_port_range(text: str, expected: tuple[int, int] | None) -> None:
    assert parse_port_range(text) == expected


def test_read_port_range_reads_the_file(tmp_path: Path) -> None:
    path = tmp_path / "ip_local_port_range"
    path.write_text("20000\t60999\n")
    assert read_port_range(str(path)) == (20000, 60999)


@pytest.mark.parametrize("content", [None, "", "garbled\n", "60999 20000\n"])
def test_an_unreadable_or_garbled_range_is_linux_default(
    tmp_path: Path, content: str | None
) -> None:
    path = tmp_path / "ip_local_port_range"
    if content is not None:
        path.write_text(content)
    assert read_port_range(str(path)) == LINUX


def test_the_host_range_is_read_from_proc() -> None:
    with open(PORT_RANGE_FILE) as handle:
        low, high = map(int, handle.read().split())
    assert read_port_range() == (low, high)
    assert choose_pool({}) == default_pool((low, high))


# -- the real runner in a network namespace of its own ---------------------------------------

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
    seen = ids_seen(stdout)
    assert len(seen) == 1, stdout
    return seen[0]


ECHO_ID = ["sh", "-c", PRINT_ID]


@capabilities.NETWORK_NAMESPACES
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


@capabilities.NETWORK_NAMESPACES
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


@capabilities.NETWORK_NAMESPACES
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


@capabilities.NETWORK_NAMESPACES
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
    lines = error_lines(done.stderr)
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


@capabilities.NETWORK_NAMESPACES
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


@capabilities.NETWORK_NAMESPACES
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

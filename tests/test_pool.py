"""The domain pool: ROS_ISOLATED_TEST_DOMAINS, its default and its errors."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers.commands import run_cli
from lxml import etree

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
    pool_from_env,
    read_port_range,
)
from ros_isolated_test.runner import settings

DEFAULT_POOL = tuple(range(1, 102))
#: Linux's default range, given explicitly: these tests must not depend on this host's.
LINUX = LINUX_DEFAULT_PORT_RANGE


def test_default_pool_is_1_to_101_without_0() -> None:
    assert pool_from_env({}, LINUX) == DEFAULT_POOL
    assert 0 not in pool_from_env({}, LINUX)


@pytest.mark.parametrize("value", ["", "   ", "\t"])
def test_empty_variable_means_the_default(value: str) -> None:
    assert pool_from_env({POOL_ENV: value}, LINUX) == DEFAULT_POOL


def test_pool_from_env_reads_the_process_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    assert pool_from_env(port_range=LINUX) == DEFAULT_POOL
    monkeypatch.setenv(POOL_ENV, "7-9")
    assert pool_from_env(port_range=LINUX) == (7, 8, 9)


@pytest.mark.parametrize(
    ("spec", "expected"),
    [
        ("1-101", DEFAULT_POOL),
        ("1-50,215-232", (*range(1, 51), *range(215, 233))),
        ("7", (7,)),
        ("1", (1,)),
        ("232", (232,)),
        ("4-4", (4,)),
        ("3,9,5", (3, 9, 5)),
        (" 1 - 3 , 10 ", (1, 2, 3, 10)),
        ("\t1-2,\n5 ", (1, 2, 5)),
        ("5,5", (5,)),
        ("1-5,3-7", tuple(range(1, 8))),
        ("10,1-3,2", (10, 1, 2, 3)),
        ("215-232,1-50", (*range(215, 233), *range(1, 51))),
    ],
)
def test_valid_specs(spec: str, expected: tuple[int, ...]) -> None:
    assert parse_pool(spec) == expected
    assert pool_from_env({POOL_ENV: spec}, LINUX) == expected


@pytest.mark.parametrize(
    ("spec", "bad_part", "why"),
    [
        ("0", "'0'", "outside 1-232"),
        ("0-5", "'0-5'", "outside 1-232"),
        ("1-10,0", "'0'", "outside 1-232"),
        ("233", "'233'", "outside 1-232"),
        ("1-233", "'1-233'", "outside 1-232"),
        ("200-99999999999", "'200-99999999999'", "outside 1-232"),
        ("5-1", "'5-1'", "backwards"),
        ("1-50,60-55", "'60-55'", "backwards"),
        ("abc", "'abc'", "not an ID or a range"),
        ("1-x", "'1-x'", "not an ID or a range"),
        ("1..5", "'1..5'", "not an ID or a range"),
        ("1:5", "'1:5'", "not an ID or a range"),
        ("1-2-3", "'1-2-3'", "not an ID or a range"),
        ("-3", "'-3'", "not an ID or a range"),
        ("5-", "'5-'", "not an ID or a range"),
        ("0x10", "'0x10'", "not an ID or a range"),
        ("1 2", "'1 2'", "not an ID or a range"),
        ("1-50;215-232", "'1-50;215-232'", "not an ID or a range"),
        ("2.5", "'2.5'", "not an ID or a range"),
        ("1,,2", "'1,,2'", "empty entry"),
        ("1,", "'1,'", "empty entry"),
        (",1", "',1'", "empty entry"),
        ("1, ,2", "'1, ,2'", "empty entry"),
        (",", "','", "empty entry"),
    ],
)
def test_invalid_specs_name_the_bad_part(spec: str, bad_part: str, why: str) -> None:
    with pytest.raises(PoolSpecError) as raised:
        parse_pool(spec)
    message = str(raised.value)
    assert bad_part in message
    assert why in message
    assert "\n" not in message

    with pytest.raises(PoolSpecError) as from_env:
        pool_from_env({POOL_ENV: spec}, LINUX)
    env_message = str(from_env.value)
    assert env_message.startswith(f"{POOL_ENV}: ")
    assert bad_part in env_message
    assert why in env_message
    assert "'1-101'" in env_message  # the fix: what a valid value looks like
    assert "unset it" in env_message
    assert "\n" not in env_message


def test_parse_pool_refuses_an_empty_spec() -> None:
    with pytest.raises(PoolSpecError, match="empty entry"):
        parse_pool("")


def test_zero_is_refused_with_the_reason() -> None:
    with pytest.raises(PoolSpecError, match="0 is every un-isolated process's domain"):
        parse_pool("0-10")


def test_pool_spec_error_is_a_value_error() -> None:
    with pytest.raises(ValueError):
        parse_pool("nonsense")


@pytest.mark.parametrize("spec", ["1_0", "1-1_00", "\u0661-\u0665", "\uff11\uff10"])
def test_only_plain_ascii_decimal_digits_are_ids(spec: str) -> None:
    """Python's int() also reads '1_0' as 10 and Arabic or full-width digits as numbers.

    None of these is an ID or a range like 1-101; taking them silently hands out IDs
    nobody wrote down, where the issue asks for a clear error on any invalid spec.
    """
    with pytest.raises(PoolSpecError):
        parse_pool(spec)


# -- the ephemeral port range -------------------------------------------------------------


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


# -- the CLI with a bad ROS_ISOLATED_TEST_DOMAINS --------------------------------------------


def _error_lines(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if line.strip()]


@pytest.mark.parametrize("spec", ["0-5", "1-233", "garbage", "9-3", "1,,2"])
def test_run_with_a_bad_pool_exits_2_with_one_line(
    spec: str, env: dict[str, str], tmp_path: Path
) -> None:
    marker = tmp_path / "ran"
    env[POOL_ENV] = spec
    result = run_cli(["run", "--", "touch", str(marker)], env)
    assert result.returncode == 2, result.stdout + result.stderr
    lines = _error_lines(result.stderr)
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("ros-isolated-test: error: ")
    assert POOL_ENV in lines[0]
    assert repr(spec) in lines[0]
    assert "Running with ROS_DOMAIN_ID" not in result.stdout
    assert not marker.exists()


def test_run_with_a_bad_pool_still_writes_a_result_file(
    env: dict[str, str], tmp_path: Path
) -> None:
    marker = tmp_path / "ran"
    result_file = tmp_path / "results" / "my_test.xml"
    env[POOL_ENV] = "0-101"
    result = run_cli(["run", "--junit-xml", str(result_file), "--", "touch", str(marker)], env)
    assert result.returncode == 2, result.stdout + result.stderr
    assert len(_error_lines(result.stderr)) == 1
    assert not marker.exists()
    root = etree.parse(str(result_file)).getroot()
    suites = root.findall("testsuite")
    assert len(suites) == 1
    assert suites[0].get("errors") == "1"
    errors = root.findall("./testsuite/testcase/error")
    assert len(errors) == 1
    message = errors[0].get("message") or ""
    assert POOL_ENV in message
    assert "'0-101'" in message
    properties = {
        prop.get("name"): prop.get("value") for prop in root.iterfind("./testsuite/properties/*")
    }
    assert properties.get("exit") == "not run"
    assert "ros_domain_id" not in properties


def test_run_with_a_bad_pool_replaces_a_stale_passing_result(
    env: dict[str, str], tmp_path: Path
) -> None:
    result_file = tmp_path / "stale.xml"
    assert run_cli(["run", "--junit-xml", str(result_file), "--", "true"], env).returncode == 0
    assert not etree.parse(str(result_file)).getroot().findall(".//error")
    env[POOL_ENV] = "abc"
    result = run_cli(["run", "--junit-xml", str(result_file), "--", "true"], env)
    assert result.returncode == 2
    assert etree.parse(str(result_file)).getroot().findall(".//error")


@pytest.mark.parametrize("args", [["status"], ["status", "--json"]])
def test_status_with_a_bad_pool_exits_2(args: list[str], env: dict[str, str]) -> None:
    env[POOL_ENV] = "1-50,215-300"
    result = run_cli(args, env)
    assert result.returncode == 2, result.stdout + result.stderr
    assert POOL_ENV in result.stderr
    assert "'215-300'" in result.stderr
    assert result.stdout == ""


def test_cli_accepts_a_valid_pool_with_whitespace(env: dict[str, str]) -> None:
    env[POOL_ENV] = " 215 - 232 , 1-3 "
    result = run_cli(["run", "--", "sh", "-c", 'echo "id=$ROS_DOMAIN_ID"'], env)
    assert result.returncode == 0, result.stdout + result.stderr
    ids = [int(line[3:]) for line in result.stdout.splitlines() if line.startswith("id=")]
    assert len(ids) == 1
    assert ids[0] in (*range(215, 233), 1, 2, 3)

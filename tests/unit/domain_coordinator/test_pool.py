"""``pool``: which domain IDs may be handed out, ROS_ISOLATED_TEST_DOMAINS and its errors.

The default is 1-101 (never 0: every un-isolated process's domain); a spec names IDs
and ranges of plain ASCII digits, in order, without repeats, and any other spec is one
line naming the bad part and the fix, in-process and from the real CLI (exit 2, a result
file that says so, never the test run). The ephemeral port range's part in the default
pool: ``test_pool_port_range``.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers.commands import run_cli
from helpers.coordinator import PRINT_ID, error_lines, ids_seen
from lxml import etree

from ros_isolated_test.domain_coordinator import POOL_ENV, PoolSpecError, parse_pool
from ros_isolated_test.domain_coordinator.pool import LINUX_DEFAULT_PORT_RANGE, pool_from_env

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


# -- the CLI with a bad ROS_ISOLATED_TEST_DOMAINS --------------------------------------------


@pytest.mark.parametrize("spec", ["0-5", "1-233", "garbage", "9-3", "1,,2"])
def test_run_with_a_bad_pool_exits_2_with_one_line(
    spec: str, env: dict[str, str], tmp_path: Path
) -> None:
    marker = tmp_path / "ran"
    env[POOL_ENV] = spec
    result = run_cli(["run", "--", "touch", str(marker)], env)
    assert result.returncode == 2, result.stdout + result.stderr
    lines = error_lines(result.stderr)
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
    assert len(error_lines(result.stderr)) == 1
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
    result = run_cli(["run", "--", "sh", "-c", PRINT_ID], env)
    assert result.returncode == 0, result.stdout + result.stderr
    ids = ids_seen(result.stdout)
    assert len(ids) == 1
    assert ids[0] in (*range(215, 233), 1, 2, 3)

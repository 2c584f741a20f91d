"""``shard.spec``: ``I/N`` read one way; a bad value is one line naming where it came from."""

from __future__ import annotations

import pytest

from ros_isolated_test.shard.spec import (
    MAX_TOTAL,
    SHARD_ENV,
    ShardSettingError,
    Share,
    ShareSpecError,
    named,
    parse,
    share_from,
)


@pytest.mark.parametrize(
    ("value", "index", "total"),
    [
        ("1/1", 1, 1),
        ("2/4", 2, 4),
        ("4/4", 4, 4),
        (" 3/8\n", 3, 8),  # a CI template's edge blanks
        ("\t1/2 ", 1, 2),
        ("01/04", 1, 4),  # leading zeros are still the number
        (f"{MAX_TOTAL}/{MAX_TOTAL}", MAX_TOTAL, MAX_TOTAL),
        (f"1/{MAX_TOTAL}", 1, MAX_TOTAL),
    ],
)
def test_a_share_is_read(value: str, index: int, total: int) -> None:
    share = parse(value)
    assert share == Share(index, total)
    assert str(share) == f"{index}/{total}"


@pytest.mark.parametrize("value", [None, "", " ", "\n\t"])
def test_unset_or_blank_is_no_split(value: str | None) -> None:
    assert parse(value) is None
    assert parse("1/2") is not None  # control: a value is read


@pytest.mark.parametrize(
    ("value", "said"),
    [
        ("3", "is not I/N"),
        ("3/", "is not I/N"),
        ("/4", "is not I/N"),
        ("2/4/8", "is not I/N"),
        ("1 / 4", "is not I/N"),  # no blank inside
        ("a/b", "is not I/N"),
        ("-1/4", "is not I/N"),
        ("+1/4", "is not I/N"),
        ("1.0/4", "is not I/N"),
        ("1_0/20", "is not I/N"),  # int() would take it
        ("\u0663/4", "is not I/N"),  # an Arabic-Indic 3: int() would take it too
        ("1234567890/4", "is not I/N"),  # more digits than any share has
        ("1\\4", "is not I/N"),
        ("0/4", "shares count from 1"),
        ("0/0", "N must be from 1 to 1000"),
        ("1/0", "N must be from 1 to 1000"),
        (f"1/{MAX_TOTAL + 1}", "N must be from 1 to 1000"),
        ("5/4", "I must be from 1 to N=4"),
        ("2/1", "I must be from 1 to N=1"),
    ],
)
def test_a_bad_value_is_one_line_naming_the_variable_the_value_and_the_form(
    value: str, said: str
) -> None:
    with pytest.raises(ShareSpecError) as raised:
        parse(value)
    message = str(raised.value)
    assert message.startswith(f"{SHARD_ENV}={value!r}"), message
    assert said in message
    assert "\n" not in message
    # The fix is said: the form, or (for a 0-based index) how to count from 1.
    assert "I/N" in message or "JOB_COMPLETION_INDEX+1" in message
    assert isinstance(raised.value, ShardSettingError)


def test_a_zero_based_index_is_told_how_to_count_from_one() -> None:
    with pytest.raises(ShareSpecError, match=r"\$\(\(JOB_COMPLETION_INDEX\+1\)\)/4"):
        parse("0/4")


def test_an_option_is_named_as_an_option() -> None:
    with pytest.raises(ShareSpecError) as raised:
        parse("5/4", "--shard")
    assert str(raised.value).startswith("--shard '5/4': ")


def test_named_writes_a_variable_with_equals_and_an_option_with_a_blank() -> None:
    assert named(SHARD_ENV, "x") == f"{SHARD_ENV}=x"
    assert named("--ros-isolated-test-shard", "x") == "--ros-isolated-test-shard x"


def test_the_option_wins_and_the_variable_is_then_not_read() -> None:
    environ = {SHARD_ENV: "not a share"}
    assert share_from(environ, "2/3") == Share(2, 3)
    # Control: without the option the variable is read, and its bad value is an error.
    with pytest.raises(ShareSpecError, match=SHARD_ENV):
        share_from(environ)


def test_the_variable_is_read_when_no_option_is_given() -> None:
    assert share_from({SHARD_ENV: "3/5"}) == Share(3, 5)
    assert share_from({}) is None
    assert share_from({SHARD_ENV: ""}) is None


def test_a_bad_option_names_the_option() -> None:
    with pytest.raises(ShareSpecError, match=r"^--ros-isolated-test-shard '9/4': "):
        share_from({}, "9/4", "--ros-isolated-test-shard")


@pytest.mark.parametrize(("index", "total"), [(0, 4), (5, 4), (1, 0), (1, MAX_TOTAL + 1)])
def test_no_share_out_of_range_can_be_made(index: int, total: int) -> None:
    with pytest.raises(ValueError, match="I/N"):
        Share(index, total)


def test_shares_compare_and_hash_by_value() -> None:
    assert Share(1, 2) == Share(1, 2)
    assert Share(1, 2) != Share(2, 2)
    assert len({Share(1, 2), Share(1, 2), Share(2, 2)}) == 2
    assert repr(Share(1, 2)) == "Share(1, 2)"

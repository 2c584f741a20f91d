"""``switches``: on and off words read one way; each switch's own rule for unset and others.

DISABLE_ROS_ISOLATION, ROS_ISOLATED_TEST_GZ_PARTITION and the pytest plugin's
``ros_isolation`` ini option take the same words (README's variable table); what an
unset or blank value means and what another word does differ by design, and each caller
says it: unset never disables isolation and keeps the partition on; another word
disables isolation (upstream: "set" means disabled) but is refused as a partition switch.
"""

from __future__ import annotations

import pytest

from ros_isolated_test.runner import partition, settings
from ros_isolated_test.switches import OFF_WORDS, ON_WORDS, NotOnOff, on_off

#: Each word as a user may write it: any case, blanks around it.
ON = [*sorted(ON_WORDS), " ON ", "True", "YES\n"]
OFF = [*sorted(OFF_WORDS), " Off ", "FALSE", "No\t"]
UNSET = [None, "", "  "]
OTHER = ["2", "of", "disable", "enabled", "auto"]


def test_the_words_are_the_documented_ones() -> None:
    assert {"1", "on", "true", "yes"} == ON_WORDS
    assert {"0", "off", "false", "no"} == OFF_WORDS
    assert not ON_WORDS & OFF_WORDS


@pytest.mark.parametrize("unset", [True, False, None])
def test_unset_or_blank_means_what_the_caller_says(unset: bool | None) -> None:
    for value in UNSET:
        assert on_off(value, unset) is unset
    assert on_off("on", unset) is True  # the control: a word is read whatever unset means
    assert on_off("off", unset) is False


@pytest.mark.parametrize("value", OTHER)
def test_any_other_word_is_neither(value: str) -> None:
    with pytest.raises(NotOnOff):
        on_off(value, None)


@pytest.mark.parametrize("value", [*ON, *OFF, *UNSET, *OTHER])
def test_disable_ros_isolation_counts_set_unless_off_or_blank(value: str | None) -> None:
    """README: set (other than 0, false, no, off, empty) disables isolation."""
    blank = value is None or not value.strip()
    off = value is not None and value.strip().lower() in OFF_WORDS
    assert settings.disables_isolation(value) is not (blank or off)


@pytest.mark.parametrize("value", [*ON, *OFF, *UNSET, *OTHER])
def test_the_partition_switch_is_on_unless_off_and_refuses_other_words(
    value: str | None,
) -> None:
    """README: off (or 0, false, no) sets no partition; default on; any other value refused."""
    if value in OTHER:
        with pytest.raises(partition.PartitionSettingError, match=repr(value)):
            partition.enabled(value)
        return
    off = value is not None and value.strip().lower() in OFF_WORDS
    assert partition.enabled(value) is not off

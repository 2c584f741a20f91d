from __future__ import annotations

import pytest

from ros_isolated_test.colcon.switch import VARIABLE, state


@pytest.mark.parametrize("value", [None, "", " ", "on", "1", "YES"])
def test_unset_blank_or_on_is_on(value: str | None) -> None:
    environ = {} if value is None else {VARIABLE: value}
    assert state(environ) == (True, None)


@pytest.mark.parametrize("value", ["off", "0", " False ", "no"])
def test_an_off_word_turns_it_off(value: str) -> None:
    assert state({VARIABLE: value}) == (False, None)


def test_a_typo_stays_on_and_is_said() -> None:
    on, problem = state({VARIABLE: "of"})
    assert on
    assert problem is not None and "'of'" in problem and "off" in problem

"""On and off words: one reading for every switch a user sets by variable or ini option.

``DISABLE_ROS_ISOLATION``, ``ROS_ISOLATED_TEST_GZ_PARTITION`` and the pytest plugin's
``ros_isolation`` ini option take the same words, case and edge blanks ignored. What an
unset or blank value means, and what a word that is neither on nor off does, is each
switch's own documented rule: the caller says it, this module never guesses. Imports
nothing: the pytest plugin reads its ini option with it before it knows it is active.
"""

from __future__ import annotations

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from typing import TypeVar

    Unset = TypeVar("Unset", bound=bool | None)

ON_WORDS = frozenset({"1", "on", "true", "yes"})
OFF_WORDS = frozenset({"0", "off", "false", "no"})


class NotOnOff(ValueError):
    """A value that is neither unset nor blank nor an on or off word."""


def on_off(value: str | None, unset: Unset) -> bool | Unset:
    """True for an on word, False for an off word, ``unset`` for None or a blank value.

    Raises :class:`NotOnOff` for anything else: the caller decides whether that is an
    error (a typo must not silently flip an isolation) or counts as set.
    """
    word = "" if value is None else value.strip().lower()
    if not word:
        return unset
    if word in ON_WORDS:
        return True
    if word in OFF_WORDS:
        return False
    raise NotOnOff(value)

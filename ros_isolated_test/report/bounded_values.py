"""The values the page draws from a result file, each read within bounds where it is read.

A result file is written by arbitrary code, and another producer's units may not be
ours (a suite ``time`` in milliseconds). A value the page cannot draw (an instant before
2000 or after 2200, a wait or a duration over a week, an attempt count past any rerun
series, a number too long to read, not a number at all) is never used to compute
anything: it is drawn as unknown and named (:class:`Reading`), so the page is always
written, in time and memory bounded by the file's size.
"""

from __future__ import annotations

import datetime
import math

from ros_isolated_test.text import display_text

_UTC = datetime.timezone.utc
#: The instants a page draws: before 2000 is a placeholder (gtest writes 1970-01-01),
#: after 2200 a clock or a unit gone wrong.
EARLIEST = datetime.datetime(2000, 1, 1, tzinfo=_UTC).timestamp()
LATEST = datetime.datetime(2200, 1, 1, tzinfo=_UTC).timestamp()
#: The longest a test or a wait is drawn: a week (a suite time in milliseconds is longer).
LONGEST = 7 * 24 * 3600.0
#: The most attempts drawn for one test (the runner allows 100 reruns).
MOST_ATTEMPTS = 1000
#: Characters of a number or an instant looked at: longer ones are not read at all.
_READ_CHARS = 64
#: Characters of an odd value shown where the page names it.
SHOWN_CHARS = 80


class Reading:
    """The bounded values read from one file, and each odd one named (:attr:`odd`)."""

    def __init__(self) -> None:
        #: One line per value that could not be drawn: its name, its value, why.
        self.odd: list[str] = []

    def name(self, name: str, value: str, why: str) -> None:
        """Say that ``name`` = ``value`` was not drawn, and why."""
        line = f"{display_text(name, SHOWN_CHARS)} = '{display_text(value, SHOWN_CHARS)}': {why}"
        if line not in self.odd:  # a suite's attributes may be its file's root's too
            self.odd.append(line)

    def instant(self, name: str, value: str) -> float | None:
        """ISO 8601 as seconds since the epoch (no zone: local time); None when unusable.

        Empty is not recorded (None, not named); anything else unusable is named.
        """
        text = value.strip()
        if not text:
            return None
        if len(text) > _READ_CHARS:
            self.name(name, value, "too long for an instant")
            return None
        if text.endswith(("Z", "z")):
            text = text[:-1] + "+00:00"
        try:
            when = datetime.datetime.fromisoformat(text).timestamp()
        except (ValueError, OverflowError, OSError):
            self.name(name, value, "not an ISO 8601 instant the page can draw")
            return None
        if not EARLIEST <= when < LATEST:
            self.name(name, value, "before 2000 or after 2200: not drawn")
            return None
        return when

    def seconds(self, name: str, value: str) -> float | None:
        """A duration or a wait in seconds (``1,234.5`` read); None when unusable.

        Empty is not recorded (0, not named); negative, not finite, not a number or over
        :data:`LONGEST` is named and None.
        """
        text = value.strip().replace(",", "")
        if not text:
            return 0.0
        number = self._number(name, value, text)
        if number is None:
            return None
        if not math.isfinite(number) or number < 0:
            self.name(name, value, "not a duration (negative or not finite)")
            return None
        if number > LONGEST:
            self.name(name, value, "over a week: not drawn")
            return None
        return number

    def count(self, name: str, value: str) -> int | None:
        """An attempt count from 1 to :data:`MOST_ATTEMPTS`; None when unusable (named)."""
        text = value.strip()
        if not text:
            return None
        if not (text.isascii() and text.isdigit()) or len(text) > len(str(MOST_ATTEMPTS)):
            self.name(name, value, f"not a count from 1 to {MOST_ATTEMPTS}")
            return None
        number = int(text)
        if not 1 <= number <= MOST_ATTEMPTS:
            self.name(name, value, f"not a count from 1 to {MOST_ATTEMPTS}")
            return None
        return number

    def _number(self, name: str, value: str, text: str) -> float | None:
        if len(text) > _READ_CHARS:
            self.name(name, value, "too long for a number")
            return None
        try:
            return float(text)
        except ValueError:
            self.name(name, value, "not a number")
            return None


def drawable(seconds: float) -> bool:
    """Whether a duration already read (a case's time) is one the page shows."""
    return math.isfinite(seconds) and 0 <= seconds <= LONGEST


def seconds_shown(seconds: float) -> str:
    """A case's time as the page shows it: ``1.250 s``, or ``unknown`` past a week."""
    return f"{seconds:.3f} s" if drawable(seconds) else "unknown"


def local(when: float) -> str:
    """``when`` in local time to the second with its zone; ``unknown`` if it has none."""
    try:
        return datetime.datetime.fromtimestamp(when).astimezone().isoformat(timespec="seconds")
    except (ValueError, OverflowError, OSError):
        return "unknown"

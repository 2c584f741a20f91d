"""The placeholder's reserved room, and the stand-in that overwrites it in place.

Apart from the result file's life cycle (``result_file``) because it is the one write
that must not need the file system's help: when the final word cannot be written (a
disk that filled up while the test ran), the placeholder must not stay behind saying
the test most likely timed out. It is overwritten where it lies, in blocks it already
holds, by a short result saying the write failed and how the test ended; the
placeholder is written with room for that.

A placeholder left behind says when it was written (:data:`WRITTEN_AT`), just before
its attempt waited for an ID and started: with the files beside it, that gives a killed
test's duration at least up to the last word the test wrote (:func:`killed_seconds`),
which ``report --durations`` keeps instead of the 0 s a killed run never took.
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat

from ros_isolated_test import names
from ros_isolated_test.text import shown
from ros_isolated_test.xunit import serialise
from ros_isolated_test.xunit.kept_files import attempt_original_of
from ros_isolated_test.xunit.model import Suite
from ros_isolated_test.xunit.timeline import instant

TYPE_CHECKING = False
if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence
    from pathlib import Path

    from ros_isolated_test.xunit.model import Case

#: How the stand-in for a result that could not be written begins.
NOT_WRITTEN = "ros-isolated-test could not write this result file"
#: Bytes the placeholder holds beyond its own content, so the stand-in always fits.
RESERVE_BYTES = 1024
#: Properties the stand-in keeps while they fit: how the test ended, on which ID, and
#: where the test's own file is kept.
_STAND_IN_PROPERTIES = (
    "exit",
    "exit_code",
    "signal",
    "duration",
    "ros_domain_id",
    "original_result_file",
)


#: What the placeholder's case says happened, if it is all there is.
KILLED = "the runner was killed before the test ended"
#: The placeholder's suite property: when it was written (local ISO 8601 to the
#: microsecond, with the zone), just before its attempt waited for an ID and started.
WRITTEN_AT = names.PLACEHOLDER_WRITTEN_AT
#: How far the placeholder file's mtime may be from :data:`WRITTEN_AT` for the mtimes
#: beside it to be the run's own (a copy that did not keep them moves them all).
_SAME_INSTANT = 2.0
#: Suite property of a merged rerun series: how many attempts it holds (``attempts``).
_ATTEMPTS = names.ATTEMPTS


def stamped(properties: Mapping[str, str], when: float) -> dict[str, str]:
    """The placeholder's properties: the run's, and :data:`WRITTEN_AT` ``when``."""
    return {**properties, WRITTEN_AT: instant(when)}


def killed_seconds(path: Path, properties: Mapping[str, str]) -> float | None:
    """How long the test of a placeholder left at ``path`` ran at least; None: not known.

    From :data:`WRITTEN_AT` to the last write of the test's own file beside it (the
    attempt's ``<name>.attempt<k>.orig``): a test killed after it wrote its result ran at
    least that long (a kill at its timeout, longer). The file times count only when the
    placeholder's own mtime is the instant it says it was written: a tree copied without
    its times (most copies) says nothing of when the test wrote. No own file, or times
    that are not the run's: None, never 0, since the test did run.
    """
    from datetime import datetime

    try:
        written = datetime.fromisoformat(properties[WRITTEN_AT]).timestamp()
        number = int(properties.get(_ATTEMPTS, "1"))
        if abs(os.stat(path).st_mtime - written) > _SAME_INSTANT:
            return None
        last = os.stat(attempt_original_of(path, number)).st_mtime
    except (KeyError, ValueError, OverflowError, OSError):
        return None
    seconds = last - written
    return seconds if 0 < seconds <= 7 * 24 * 3600 else None


def with_room(data: bytes) -> bytes:
    """The placeholder's bytes: ``data`` and a comment holding ``RESERVE_BYTES`` of room."""
    note = "<!-- room for the runner to say what happened if it cannot replace this file"
    padding = f"{note}{' ' * max(RESERVE_BYTES - len(note) - 5, 0)} -->\n"
    return data + padding.encode()


def holds_exactly(path: Path, data: bytes) -> bool:
    """Whether the file still holds ``data`` (the placeholder the test did not replace).

    Opened without blocking and read only if it is a regular file: a test may leave a
    FIFO at the path, and that must not hang the runner.
    """
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError:
        return False
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return False
        held = b""
        while len(held) <= len(data) and (chunk := os.read(fd, len(data) + 1 - len(held))):
            held += chunk
        return held == data
    finally:
        os.close(fd)


class StandIn:
    """A valid result saying the final word could not be written, and how the test ended.

    ``suite`` is the runner's own suite for the test, holding its one case (an error);
    the case's message and the suite's properties are set here, cut to the room there is.
    ``failure`` is why the write failed, in the system's words; ``reason`` the full
    error; ``properties`` the run's; ``cases`` those the final word would have held.
    ``earlier``: the suites of a rerun series' earlier attempts, which the placeholder
    holds: the stand-in keeps their failures too (their properties only while they fit).
    """

    __slots__ = ("_earlier", "_message", "_properties", "_reason", "_suite", "_why")

    def __init__(
        self,
        suite: Suite,
        failure: str,
        reason: str,
        properties: dict[str, str],
        cases: Sequence[Case],
        earlier: Sequence[Suite] = (),
    ) -> None:
        ended = properties.get(names.EXIT)
        if ended == "not run":
            how = "The test did not run."
        elif ended:
            how = f"The test {ended}."
        else:
            how = "How the test ended is not known."
        failing = [case for case in cases if case.outcome.failed]
        held = f"The result would have held {len(cases)} test case(s), {len(failing)} failed"
        if failing:
            held += f"; the first: {failing[0].name}: {failing[0].message}"
        self._why = f"{NOT_WRITTEN} ({failure})"
        self._message = f"{self._why}: this short one stands in. {how} {held}."
        self._properties = {
            key: properties[key] for key in _STAND_IN_PROPERTIES if key in properties
        }
        self._properties[names.RESULT_WRITE_ERROR] = reason
        self._reason = reason
        self._suite = suite
        self._earlier = tuple(earlier)

    def render(self, room: int) -> bytes:
        """The stand-in in at most ``room`` bytes: properties dropped, then the message cut.

        The earlier attempts' cases always stay: the placeholder it replaces held them.
        """
        message = self._message
        stages = [(self._properties, self._earlier)]
        bare = tuple(_without_properties(suite) for suite in self._earlier)
        if bare:
            stages.append((self._properties, bare))
        stages.append(({"result_write_error": self._reason[:200]}, bare))
        for kept, earlier in stages:
            data = self._rendered(kept, earlier, len(message))
            if len(data) <= room:
                return data
        # The longest head of the message that fits (escaping makes bytes unpredictable).
        low, high = len(self._why), len(message)
        if len(self._rendered(kept, earlier, low)) > room:
            raise OSError(errno.ENOSPC, "no room in the placeholder for the stand-in")
        while low < high:
            middle = (low + high + 1) // 2
            if len(self._rendered(kept, earlier, middle)) <= room:
                low = middle
            else:
                high = middle - 1
        return self._rendered(kept, earlier, low)

    def _rendered(
        self, properties: dict[str, str], earlier: tuple[Suite, ...], length: int
    ) -> bytes:
        (case,) = self._suite.cases
        case.message = case.text = shown(self._message[:length])
        case.type = "ResultNotWritten"
        self._suite.properties = {name: shown(value) for name, value in properties.items()}
        if not earlier:
            return serialise.serialize(self._suite)
        from ros_isolated_test.xunit.attempts import merge_attempts

        return serialise.serialize(merge_attempts([*earlier, self._suite]))


def _without_properties(suite: Suite) -> Suite:
    """``suite`` with no properties: merged, it adds no ``attempt_<k>.<name>`` of its own."""
    return Suite(suite.name, suite.cases, suite.time, suite.timestamp, suite.hostname, {},
                 suite.system_out, suite.system_err)  # fmt: skip


def overwrite_in_place(path: Path, placeholder: bytes, stand_in: StandIn) -> bool:
    """Overwrite our placeholder where it lies (no new blocks needed); False if not ours.

    Padded to the placeholder's length, so the file is valid XML even if the
    truncation that tidies it up never happens.
    """
    if not stat.S_ISREG(os.lstat(path).st_mode):
        return False  # never opened: opening a device can act on it
    flags = os.O_RDWR | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC
    fd = os.open(path, flags)
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return False
        size = len(placeholder)
        if os.pread(fd, size + 1, 0) != placeholder:
            return False  # the test's own file: never ours to overwrite
        data = stand_in.render(size)
        padded = data + b"\n" * (size - len(data))
        done = 0
        while done < size:
            count = os.pwrite(fd, padded[done:], done)
            if count <= 0:
                raise OSError(errno.EIO, "the file took no more bytes")
            done += count
        with contextlib.suppress(OSError):
            os.ftruncate(fd, len(data))
        os.fsync(fd)
    finally:
        os.close(fd)
    return True

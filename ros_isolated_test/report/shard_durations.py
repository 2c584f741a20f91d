"""Which tests a result file holds, by identity, and how long each took: a split's inputs.

A split names tests by identity (``shard.identity``), and a result file names them in
one of two ways:

- **a runner's file** (one suite, ``<package>.<test>``, with our ``runner_version``): the
  ctest test ``<test>`` of ``<package>``, as the RUNNER decided for it; it took its
  ``duration`` property (the last attempt's run, what a rerun-free run takes), else the
  suite's time. A file that says the test was not run measured nothing. The placeholder
  a killed runner left (a ctest TIMEOUT) measured at least the time until the test's own
  file was written (``xunit.placeholder.killed_seconds``), else nothing: never the 0 s
  of its suite, which would plan the slowest tests as instant.
- **pytest's own file, written under the plugin**: each case that carries the
  ``ros_isolated_test_identity`` property is the item it names; it took the seconds of
  its ``ros_isolated_test_seconds`` property (the plugin's, to the microsecond), else
  the case's time (pytest's, to the millisecond: a quicker item reads as 0 s).

Anything else (another producer's file, a case without the property) names no test a
split places, and is left out. ``report --durations`` writes these durations
(:class:`Gathered`), ``shard --plan TREE`` shows the tests, and the merge of a split's
trees counts them.
"""

from __future__ import annotations

import math

from ros_isolated_test import names
from ros_isolated_test.report.tree import FileRead, read_file, result_files
from ros_isolated_test.shard.durations import Durations, measured, merge
from ros_isolated_test.shard.identity import SEPARATOR, IdentityError, identity, split
from ros_isolated_test.xunit.canonical import test_name_of
from ros_isolated_test.xunit.placeholder import KILLED, WRITTEN_AT, killed_seconds

TYPE_CHECKING = False
if TYPE_CHECKING:
    from pathlib import Path

    from ros_isolated_test.xunit.model import Case

#: The suite property a runner records its test's run time in (``runner.verdict``).
DURATION_PROPERTY = names.DURATION

__all__ = ["Gathered", "named_tests", "tests_in"]


def _seconds(text: str) -> float | None:
    """``text`` as a duration a file may keep, else None (it measured nothing usable)."""
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) and 0 <= value <= 7 * 24 * 3600 else None


def named_tests(item: FileRead) -> list[tuple[str, float | None]]:
    """Each test the file holds, by identity, with its seconds (None: not measured)."""
    read = item.read
    if read is None:
        return []
    suites = read.suites
    if len(suites) == 1 and names.RUNNER_VERSION in suites[0].properties:
        return _runner_test(item)
    found: list[tuple[str, float | None]] = []
    for case in read.cases:
        if not case.identity:
            continue
        try:
            split(case.identity)
        except IdentityError:
            continue  # not one a split could have placed
        seconds = _seconds(case.seconds) if case.seconds else None
        if seconds is None:
            seconds = _seconds(case.attrs.get("time", ""))
        found.append((case.identity, seconds))
    return found


def _runner_test(item: FileRead) -> list[tuple[str, float | None]]:
    """The one test of a runner's file: ``<package>.<test>``, its name from the file's."""
    assert item.read is not None
    suite = item.read.suites[0]
    test = test_name_of(item.path)
    package = suite.name.removesuffix(f".{test}")
    if package == suite.name or not package or SEPARATOR in package:
        return []
    properties = suite.properties
    seconds = None
    if properties.get(names.EXIT) == "not run":
        pass
    elif DURATION_PROPERTY in properties:
        seconds = _seconds(properties[DURATION_PROPERTY])
    elif WRITTEN_AT in properties:
        seconds = killed_seconds(item.path, properties)  # the runner was killed
    elif not _killed_before(item.cases):
        seconds = _seconds(suite.attrs.get("time", ""))
    return [(identity(package, test), seconds)]


def _killed_before(cases: list[Case]) -> bool:
    """Whether the file is the placeholder of a runner older than :data:`WRITTEN_AT`."""
    return any(KILLED in case.message for case in cases)


class Gathered:
    """The durations of the tests of one or more runs' trees, file by file.

    A test measured more than once (trees of several runs) keeps the median of its
    measurements, as :func:`~ros_isolated_test.shard.durations.merge` takes it: the
    shards of one run measure disjoint tests, so their merge is their union.
    """

    def __init__(self) -> None:
        self._samples: dict[str, list[float]] = {}
        #: Result files read, and those that named a measured test.
        self.files = 0
        self.measuring = 0

    def add(self, item: FileRead) -> None:
        """One file read: its measured tests kept."""
        self.files += 1
        measured_here = False
        for key, seconds in named_tests(item):
            if seconds is not None:
                self._samples.setdefault(key, []).append(seconds)
                measured_here = True
        self.measuring += measured_here

    def durations(self) -> Durations:
        """Every test measured: the median of its measurements, as the file keeps it."""
        rounds = max(map(len, self._samples.values()), default=0)
        runs = [
            measured({key: values[k] for key, values in self._samples.items() if len(values) > k})
            for k in range(rounds)
        ]
        return merge(runs)


def tests_in(trees: tuple[Path, ...]) -> tuple[set[str], list[OSError]]:
    """The identities of the tests named by the result files under ``trees`` (``shard --plan``).

    A runner's result file is its ctest test, an item in pytest's file under the plugin
    the node id it names (:func:`named_tests`); other files name no test and are left
    out. The folders that could not be read come back beside them, for the caller to say.
    """
    found: set[str] = set()
    unreadable: list[OSError] = []
    for path in result_files(trees):
        if isinstance(path, OSError):
            unreadable.append(path)
            continue
        item = read_file(path)
        if item is not None:
            found.update(key for key, _seconds in named_tests(item))
    return found, unreadable

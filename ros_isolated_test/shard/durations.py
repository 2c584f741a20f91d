"""The durations file: how long each test took, the one input every machine plans from.

A small JSON object, sorted and one test a line, so a committed file diffs well::

    {
      "version": 1,
      "durations": {
        "my_pkg/test/test_talker.py::test_rate": 0.45,
        "nav2_util/test_lifecycle": 12
      }
    }

Keys are test identities (:mod:`ros_isolated_test.shard.identity`), values seconds.
Measured values keep two significant figures at every size, down to the microsecond
(:func:`rounded`: 12.34 s is 12 s, 0.456 s is 0.46 s, a 0.000317 s pytest item is
0.00032 s, never 0), so every value is within 5% of what was measured, far finer than a
test's run-to-run noise, while a rerun changes only the lines of tests whose time really
moved; full precision would rewrite every line every run. A file's values are read to
the microsecond (six decimals): one written to the millisecond, as older versions wrote
them, reads as it always did.
Inside, a duration is a whole number of microseconds: sums and comparisons are exact, so
the plan cannot depend on how a machine rounds floats.

Read strictly (:func:`load`): every machine of a split must plan from the same content,
so a missing, unreadable or malformed file is an error naming the file and the fix,
never a quiet fallback to another plan (that would run some tests twice and others
never). Its :attr:`Durations.fingerprint` names the content (a hash of a canonical
serialisation: the same for the same durations however the file is spaced), so results
can say which plan ran them.

A test history database (``history``) is read as the durations file
``history durations`` would write from it (:func:`history_medians`): its first bytes say
it is an SQLite file of ours, so a split may plan from the history itself; ``sqlite3`` is
imported only then, and a JSON file is read as before.

Several runs merge (:func:`merge`) test by test into the **median** of the runs that
measured it: CI timings are noisy and now and then far off (a loaded machine, a test
that hit its timeout); the median ignores one outlier where the mean or the maximum
would carry it into every later plan, and unlike "the latest" it does not depend on the
order the runs are given in. Shards of one run measure disjoint tests, so merging them
is their union.
"""

from __future__ import annotations

import math
import os
import stat
from itertools import repeat
from operator import mul

from ros_isolated_test import atomic_file
from ros_isolated_test.shard.digest import sha256
from ros_isolated_test.shard.identity import SEPARATOR, IdentityError, split
from ros_isolated_test.shard.spec import DURATIONS_ENV, ShardSettingError, named
from ros_isolated_test.text import display_text

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    import sqlite3
    from collections.abc import Iterable, Iterator, Mapping
    from pathlib import Path

#: The file format this version writes and reads.
VERSION = 1
#: The rules ``shard.plan`` places tests by, in the plan's name: machines that would place
#: one file's tests differently (another version of ours) never share a name, so the merge
#: names them as different plans. Bump it whenever a file's placement changes.
PLACEMENT = 2
#: Microseconds in a second: the unit of every duration inside.
MICROS = 1_000_000
#: The longest duration a file may give: a week is no test's duration, but a unit slip.
MAX_SECONDS = 7 * 24 * 3600
#: The largest file read: 10,000 tests take about 600 KB.
MAX_FILE_BYTES = 64 * 1024 * 1024
#: The first bytes of every SQLite file, and where its header keeps ``application_id``.
SQLITE_MAGIC = b"SQLite format 3\x00"
_APPLICATION_ID_AT = 68
#: ``PRAGMA application_id`` of a test history database ("RITH", ``history.store``).
HISTORY_APPLICATION_ID = 0x52495448
#: The last runs of a history whose median a split plans from, as ``history durations``.
HISTORY_RUNS = 20

__all__ = [
    "DURATIONS_ENV",
    "HISTORY_RUNS",
    "MAX_SECONDS",
    "MICROS",
    "VERSION",
    "Durations",
    "DurationsError",
    "history_medians",
    "load",
    "measured",
    "merge",
    "rounded",
    "write",
]


class DurationsError(ShardSettingError):
    """A durations file that cannot be read or written: one line, the file and the fix."""


class Durations:
    """Test identity -> whole microseconds."""

    __slots__ = ("_fingerprint", "_ordered", "micros")

    def __init__(self, micros: Mapping[str, int]) -> None:
        #: Identity -> whole microseconds, in no order that matters: whatever reads it in
        #: order (the plan, the fingerprint, the file) sorts by identity.
        self.micros = dict(micros)
        self._fingerprint: str | None = None
        self._ordered: list[str] | None = None

    def __len__(self) -> int:
        return len(self.micros)

    def __contains__(self, identity: object) -> bool:
        return identity in self.micros

    def __iter__(self) -> Iterator[str]:
        return iter(self.ordered())

    def ordered(self) -> list[str]:
        """The identities in code point order (computed once: a file read is in it already)."""
        if self._ordered is None:
            self._ordered = sorted(self.micros)
        return self._ordered

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Durations):
            return NotImplemented
        return self.micros == other.micros

    def __hash__(self) -> int:
        return hash(self.fingerprint)

    def __repr__(self) -> str:
        return f"Durations({len(self.micros)} tests, {self.fingerprint})"

    @property
    def fingerprint(self) -> str:
        """16 hex digits of the SHA-256 of the canonical content: the same on every machine.

        The canonical form is compact JSON, keys sorted, ASCII only, durations in whole
        milliseconds, or in microseconds (with ``"unit":"us"``) when one is finer, and
        the placement rules (``"placement"``: :data:`PLACEMENT`): no float formatting and
        no spacing of the file reaches it, and a version of ours that would place the
        tests otherwise gives the file another name.
        """
        if self._fingerprint is None:
            import json

            ordered = self.ordered()
            values: Mapping[str, int] = self.micros
            document: dict[str, object] = {"placement": PLACEMENT, "version": VERSION}
            if any(map(int.__mod__, values.values(), repeat(1000))):
                document["unit"] = "us"
            else:
                values = {key: us // 1000 for key, us in values.items()}
            if list(values) != ordered:
                values = {key: values[key] for key in ordered}
            # As json.dumps(..., sort_keys=True) writes it, without sorting again.
            canonical = json.dumps(
                {"durations": values, **dict(sorted(document.items()))},
                separators=(",", ":"),
                ensure_ascii=True,
            )
            self._fingerprint = sha256(canonical.encode("ascii")).hex()[:16]
        return self._fingerprint

    def text(self) -> str:
        """The file's content: version first, one test a line sorted by identity, ASCII."""
        import json

        micros = self.micros
        lines = [f"    {json.dumps(key)}: {_seconds_text(micros[key])}" for key in self.ordered()]
        body = "{\n" + ",\n".join(lines) + "\n  }" if lines else "{}"
        return f'{{\n  "version": {VERSION},\n  "durations": {body}\n}}\n'


def _seconds_text(us: int) -> str:
    """Whole microseconds as seconds, no trailing zeros: ``12``, ``1.2``, ``0.00032``."""
    whole, part = divmod(us, MICROS)
    return f"{whole}.{part:06d}".rstrip("0").rstrip(".")


def _two_figures(us: int) -> int:
    """``us`` kept to two significant figures (half up); below 100 us, to the microsecond."""
    if us < 100:
        return us
    step = int(10 ** (len(str(us)) - 2))
    return (us + step // 2) // step * step


def rounded(seconds: float) -> int:
    """A measured duration as the file keeps it: whole microseconds, two significant figures.

    Raises ValueError for a value no file may hold (see :func:`load`).
    """
    problem = _bad_seconds(seconds)
    if problem is not None:
        raise ValueError(problem)
    us: int = round(seconds * MICROS)
    return _two_figures(us)


def _bad_seconds(value: object) -> str | None:
    """Why ``value`` is no duration in seconds, or None when it is one."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return f"{display_text(repr(value), 40)} is not a number of seconds"
    if not math.isfinite(value):
        return f"{value} is not a finite number of seconds"
    if value < 0:
        return f"{value} seconds is negative"
    if value > MAX_SECONDS:
        return f"{value} seconds is more than a week: no test's duration"
    return None


def measured(seconds: Mapping[str, float]) -> Durations:
    """Durations of one run's measurements (identity -> seconds), rounded as the file keeps them."""
    for key in seconds:
        split(key)
    return Durations({key: rounded(value) for key, value in seconds.items()})


def merge(runs: Iterable[Durations]) -> Durations:
    """Every test of ``runs``, each the median of the runs that measured it.

    With an even count the median is the mean of the middle two, rounded as a
    measurement is. The order of ``runs`` does not matter.
    """
    samples: dict[str, list[int]] = {}
    for run in runs:
        for key, us in run.micros.items():
            samples.setdefault(key, []).append(us)
    merged = {}
    for key, values in samples.items():
        values.sort()
        middle = len(values) // 2
        median = values[middle] if len(values) % 2 else (values[middle - 1] + values[middle]) // 2
        merged[key] = _two_figures(median)
    return Durations(merged)


class _Wrong(Exception):
    """What is wrong with the file, in words that follow its name."""


def _read_bytes(path: Path) -> bytes:
    """The file's bytes; a FIFO or device is refused without waiting on it."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as error:
        raise _Wrong(f"cannot open it: {error.strerror}") from None
    try:
        kind = os.fstat(fd).st_mode
        if stat.S_ISDIR(kind):
            raise _Wrong("it is a directory")
        if not stat.S_ISREG(kind):
            raise _Wrong("it is not a regular file")
        os.set_blocking(fd, True)
        with os.fdopen(fd, "rb", closefd=False) as handle:
            data = handle.read(len(SQLITE_MAGIC))
            if data != SQLITE_MAGIC:  # a history database is read by SQLite, not whole
                data += handle.read(MAX_FILE_BYTES + 1 - len(data))
            else:
                data += handle.read(_APPLICATION_ID_AT + 4 - len(data))
    except OSError as error:
        raise _Wrong(f"cannot read it: {error.strerror}") from None
    finally:
        os.close(fd)
    if len(data) > MAX_FILE_BYTES:
        raise _Wrong(f"it is larger than {MAX_FILE_BYTES >> 20} MiB: no durations file")
    return data


def _no_constant(name: str) -> object:
    raise ValueError(f"{name} is not a finite number of seconds")


def _pairs(pairs: list[tuple[str, object]]) -> dict[str, object]:
    """A JSON object that names no key twice (``json`` keeps the last silently)."""
    found = dict(pairs)
    if len(found) != len(pairs):
        seen: set[str] = set()
        for key, _value in pairs:
            if key in seen:
                raise ValueError(f"{display_text(key)!r} is listed twice")
            seen.add(key)
    return found


def _content(data: bytes) -> object:
    """The JSON value in ``data``."""
    import json

    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        raise _Wrong(f"it is not UTF-8 text (byte {error.start})") from None
    try:
        return json.loads(text, object_pairs_hook=_pairs, parse_constant=_no_constant)
    except json.JSONDecodeError as error:
        raise _Wrong(f"it is not JSON: {error}") from None
    except ValueError as error:  # a duplicate key, NaN, an integer of over 4300 digits
        raise _Wrong(f"it is not a durations file: {error}") from None
    except RecursionError:
        raise _Wrong("it is not a durations file: it nests too deeply") from None


def _checked(content: object) -> dict[str, int]:
    """The durations in the file's JSON value, in whole microseconds."""
    if not isinstance(content, dict):
        kind = type(content).__name__
        raise _Wrong(f"it holds a JSON {kind}, not an object with version and durations")
    extra = sorted(set(content) - {"version", "durations"})
    if extra:
        shown = display_text(extra[0])
        raise _Wrong(f"unknown key {shown!r}: a durations file holds version and durations")
    version = content.get("version")
    if version is None:
        raise _Wrong("it has no version")
    if isinstance(version, bool) or version != VERSION or not isinstance(version, int):
        raise _Wrong(
            f"format version {display_text(repr(version), 40)} is not {VERSION}, the one this "
            "ros-isolated-test reads (upgrade it, or write the file again with this one)"
        )
    tests = content.get("durations")
    if not isinstance(tests, dict):
        raise _Wrong("its durations are not an object of test identity to seconds")
    # Every runner of a split reads the whole file: checked at C speed first (10,000
    # tests in a few milliseconds), test by test only to say which one is wrong.
    values = tests.values()
    if tests and not (
        set(map(type, values)) <= {int, float}
        and min(values) >= 0
        and max(values) <= MAX_SECONDS
        and min(map(str.find, tests, repeat(SEPARATOR))) > 0  # a package before a "/"
        and not any(map(str.endswith, tests, repeat(SEPARATOR)))  # a name after it
    ):
        _first_wrong(tests)  # (or, rarely, a name that ends in "/": then none is wrong)
    return dict(zip(tests, map(round, map(mul, values, repeat(MICROS))), strict=True))


def _first_wrong(tests: dict[str, object]) -> None:
    """Raise what is wrong with the first test of ``tests`` that is wrong."""
    for key, value in tests.items():
        try:
            split(key)
        except IdentityError as error:
            raise _Wrong(f"test {error}") from None
        problem = _bad_seconds(value)
        if problem is not None:
            raise _Wrong(f"test {display_text(key)!r}: {problem}")


def history_medians(connection: sqlite3.Connection, runs: int = HISTORY_RUNS) -> dict[str, float]:
    """Each test's median last-attempt seconds over the last ``runs`` runs of a history.

    The one reading of durations from a history database (``history durations`` and a
    split planning from the database both call it). Skipped and not-run attempts, and
    attempts with no duration, are left out; a name kept as UTF-8 bytes (it had lone
    surrogates) is decoded back as ``history.store`` keeps it.
    """
    import statistics

    samples: dict[str, list[float]] = {}
    rows = connection.execute(
        "SELECT t.name, a.seconds FROM attempts a JOIN tests t ON t.id = a.test"
        " WHERE a.run IN (SELECT id FROM runs ORDER BY started DESC, id DESC LIMIT ?)"
        " AND a.seconds IS NOT NULL AND a.outcome NOT IN ('not run', 'skipped')"
        " AND a.attempt = (SELECT max(b.attempt) FROM attempts b"
        " WHERE b.run = a.run AND b.test = a.test)",
        (runs,),
    )
    for name, seconds in rows:
        key = name.decode("utf-8", "surrogatepass") if isinstance(name, bytes) else name
        samples.setdefault(key, []).append(seconds)
    return {name: statistics.median(values) for name, values in samples.items()}


def _from_history(path: Path, head: bytes) -> Durations:
    """The durations a history database gives, as ``history durations`` would write them."""
    found = int.from_bytes(head[_APPLICATION_ID_AT : _APPLICATION_ID_AT + 4], "big")
    if found != HISTORY_APPLICATION_ID:
        raise _Wrong("it is an SQLite file of another program, not a test history")
    import sqlite3

    try:
        connection = sqlite3.connect(f"{path.absolute().as_uri()}?mode=ro", uri=True, timeout=60)
    except sqlite3.Error as error:
        raise _Wrong(f"cannot open the test history in it: {error}") from None
    try:
        medians = history_medians(connection)
    except sqlite3.Error as error:
        raise _Wrong(f"cannot read the test history in it: {error}") from None
    finally:
        connection.close()
    try:
        return measured(medians)
    except (IdentityError, ValueError) as error:
        raise _Wrong(f"its history holds no durations a split can use: {error}") from None


def load(path: Path, origin: str = DURATIONS_ENV) -> Durations:
    """The durations in ``path``, read strictly; :class:`DurationsError` says what is wrong.

    ``path`` is a durations file or a test history database (the durations ``history
    durations`` writes from it). ``origin`` is the variable or option that named the
    file, said in the error.
    """
    try:
        data = _read_bytes(path)
        if data.startswith(SQLITE_MAGIC):
            return _from_history(path, data)
        return Durations(_checked(_content(data)))
    except _Wrong as wrong:
        raise DurationsError(
            f"{named(origin, display_text(str(path)))}: {wrong}; name a durations file written "
            f"by ros-isolated-test (format version {VERSION}), or leave out {origin} to split "
            "by count"
        ) from None


def write(path: Path, durations: Durations, origin: str = "--durations") -> None:
    """Replace ``path`` with ``durations`` whole: a reader never sees half a file."""
    try:
        atomic_file.write_atomically(path, durations.text().encode("ascii"))
    except OSError as error:
        why, fix = error.strerror or str(error), "choose a writable file path"
        if isinstance(error, atomic_file.NotReplaceableError):
            fix = "name a regular file instead"
        in_the_way = _not_a_folder(path)
        if in_the_way is not None:
            # mkdir says "File exists" (or "Not a directory"): name what is in the way.
            shown = display_text(str(in_the_way))
            why, fix = f"{shown} is a file, not a folder", "name a path in a folder instead"
        raise DurationsError(
            f"{named(origin, display_text(str(path)))}: cannot write it: {why}; {fix}"
        ) from None


def _not_a_folder(path: Path) -> Path | None:
    """The nearest existing folder of ``path`` that is no folder at all (a file), if any."""
    for parent in path.parents:
        try:
            mode = os.stat(parent).st_mode
        except (FileNotFoundError, NotADirectoryError):
            continue  # missing, or a file further up: the loop meets it
        except OSError:
            return None
        return None if stat.S_ISDIR(mode) else parent
    return None

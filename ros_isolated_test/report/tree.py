"""The result files of a tree: found in a stable order, each read once, one at a time.

Canonical and raw producer files alike are read through the same reader and normaliser
the runner uses, so the counts are the ones a canonical file of it would carry. A
folder that cannot be read is an error, never a quiet gap. Each file is handed on
(:func:`read_tree`) and forgotten before the next is read: what a reader keeps of it is
its own business, so a tree of any size costs what its largest file costs. The same
walk finds the records a split's machines leave (``shard.record``), for the merge.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator
from pathlib import Path

from ros_isolated_test.report.counts import FileReport, counted
from ros_isolated_test.shard.record import is_record
from ros_isolated_test.shard.selection import SHARD_PROPERTY
from ros_isolated_test.text import display_text
from ros_isolated_test.xunit import normalise, raw, reader
from ros_isolated_test.xunit.canonical import test_name_of
from ros_isolated_test.xunit.model import Case, Outcome
from ros_isolated_test.xunit.normalise import NO_CASES_TYPE


class FileRead:
    """One result file as read: its counts, its canonical cases and the raw reading.

    ``read`` is None for a folder that could not be listed (its one error case).
    """

    __slots__ = ("cases", "read", "report")

    def __init__(self, report: FileReport, cases: list[Case], read: raw.ReadResult | None) -> None:
        self.report = report
        self.cases = cases
        self.read = read

    @property
    def path(self) -> Path:
        return self.report.path


def read_tree(paths: Iterable[Path], records: list[Path] | None = None) -> Iterator[FileRead]:
    """Each result file under ``paths`` read, and each folder it could not read, in order.

    ``records``: where the split records found on the way are put (:func:`result_files`).
    """
    for item in result_files(paths, records):
        if isinstance(item, OSError):
            yield unreadable_folder(item)
        elif (found := read_file(item)) is not None:
            yield found


def result_files(
    paths: Iterable[Path], records: list[Path] | None = None
) -> Iterator[Path | OSError]:
    """``*.xml`` under each path, in a stable order; hidden folders skipped, as colcon does.

    A folder that cannot be listed (no read or search permission) comes as its error,
    where its files would have come: what it holds may be the one failure. The records
    of a split's machines (``ros_isolated_test_shard-<I>-of-<N>.json``) met on the way
    are appended to ``records``, when it is given.
    """
    for path in paths:
        if path.is_file():
            if not is_record(path.name):
                yield path
            elif records is not None:
                records.append(path)
            continue
        errors: list[OSError] = []
        for folder, dirs, files in os.walk(path, onerror=errors.append):
            yield from _taken(errors)
            dirs[:] = sorted(name for name in dirs if not name.startswith("."))
            for name in sorted(files):
                if name.endswith(".xml"):
                    yield Path(folder) / name
                elif records is not None and is_record(name):
                    records.append(Path(folder) / name)
        yield from _taken(errors)


def _taken(errors: list[OSError]) -> Iterator[OSError]:
    """The walk's errors so far, emptied; a folder gone since it was listed held nothing."""
    found = [error for error in errors if not isinstance(error, FileNotFoundError)]
    errors.clear()
    return iter(found)


def unreadable_folder(error: OSError) -> FileRead:
    """A folder ``report`` cannot list, as one error case naming it and how to fix it."""
    path = Path(error.filename)
    text = str(path)
    message = (
        f"Cannot read the result folder {display_text(text, len(text))}: {error.strerror}; "
        "the result files in it are not counted. Let this user read and enter it "
        "(chmod a+rx), or run report as one who may."
    )
    cases = [Case.saying(path.name or str(path), "result folder", Outcome.ERROR, message)]
    return FileRead(counted(path, cases), cases, None)


def read_file(path: Path) -> FileRead | None:
    """One file read and counted; None for XML that is not a test result (a ctest Test.xml).

    A file of no test cases counts as one skip saying nothing was tested, unless it is
    a split's share that held none of that package's tests (pytest's file of a session
    whose items all went to other shares): that share ran nothing there, by design.
    """
    read = reader.read(path)
    if read.root_tag is not None and not read.is_xunit:
        return None
    cases = normalise.cases_from(read, None, test_name_of(path))
    if (
        not read.cases
        and len(cases) == 1
        and cases[0].type == NO_CASES_TYPE
        and any(SHARD_PROPERTY in suite.properties for suite in read.suites)
    ):
        cases = []
    return FileRead(counted(path, cases), cases, read)

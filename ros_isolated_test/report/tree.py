"""The result files of a tree: found in a stable order, each read as ``report`` counts it.

Canonical and raw producer files alike are read through the same reader and normaliser
the runner uses, so the counts are the ones a canonical file of it would carry. A
folder that cannot be read is an error, never a quiet gap.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator
from pathlib import Path

from ros_isolated_test.report.counts import FileReport, counted
from ros_isolated_test.text import display_text
from ros_isolated_test.xunit import normalise, reader
from ros_isolated_test.xunit.canonical import test_name_of
from ros_isolated_test.xunit.model import Case, Outcome


def reports(paths: Iterable[Path]) -> list[FileReport]:
    """A report of each result file under ``paths``, and of each folder it could not read."""
    found: list[FileReport] = []
    for item in result_files(paths):
        if isinstance(item, OSError):
            found.append(unreadable_folder(item))
        elif (report := report_file(item)) is not None:
            found.append(report)
    return found


def result_files(paths: Iterable[Path]) -> Iterator[Path | OSError]:
    """``*.xml`` under each path, in a stable order; hidden folders skipped, as colcon does.

    A folder that cannot be listed (no read or search permission) comes as its error,
    where its files would have come: what it holds may be the one failure.
    """
    for path in paths:
        if path.is_file():
            yield path
            continue
        errors: list[OSError] = []
        for folder, dirs, files in os.walk(path, onerror=errors.append):
            yield from _taken(errors)
            dirs[:] = sorted(name for name in dirs if not name.startswith("."))
            for name in sorted(files):
                if name.endswith(".xml"):
                    yield Path(folder) / name
        yield from _taken(errors)


def _taken(errors: list[OSError]) -> Iterator[OSError]:
    """The walk's errors so far, emptied; a folder gone since it was listed held nothing."""
    found = [error for error in errors if not isinstance(error, FileNotFoundError)]
    errors.clear()
    return iter(found)


def unreadable_folder(error: OSError) -> FileReport:
    """A folder ``report`` cannot list, as one error case naming it and how to fix it."""
    path = Path(error.filename)
    text = str(path)
    message = (
        f"Cannot read the result folder {display_text(text, len(text))}: {error.strerror}; "
        "the result files in it are not counted. Let this user read and enter it "
        "(chmod a+rx), or run report as one who may."
    )
    case = Case.saying(path.name or str(path), "result folder", Outcome.ERROR, message)
    return FileReport(path=path, tests=1, errors=1, failed_cases=[case])


def report_file(path: Path) -> FileReport | None:
    """Counts for one file; None for XML that is not a test result (a ctest Test.xml)."""
    read = reader.read(path)
    if read.root_tag is not None and not read.is_xunit:
        return None
    return counted(path, normalise.cases_from(read, None, test_name_of(path)))

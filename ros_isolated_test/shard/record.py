"""The record a machine of a split leaves beside its results: which share it ran, and how.

A share whose machine ran nothing (the others drew every test) leaves no result file,
and neither does a machine that never reported: the merge must tell them apart. So
every runner of a split, whether it runs its test or not, and the pytest plugin beside
its ``--junit-xml`` file, leave ``ros_isolated_test_shard-<I>-of-<N>.json`` in the
result folder: the share, the plan (the durations file's fingerprint, or ``count``),
the host and the version. Every runner of one machine writes the same bytes, replacing
the file whole (``atomic_file``), so any number at once leave one whole record; a
runner that finds it already there as it would write it writes nothing. Not ``.xml``:
no reader of results (``colcon test-result``, a CI's ``**/*.xml``) takes it for one.

A record speaks only for the run that left it. A folder holds one machine's results
(a build folder restored from a cache, or reused by the next share's run, holds the
last run's), so a writer removes every other share's or plan's record there, as the
runners remove the other shares' stale results: an old record can never stand for a
share whose results are gone. The pytest plugin writes its record ``started`` when the
session starts and rewrites it complete once ``--junit-xml`` is written: a session that
died in between (SIGKILL, SIGSEGV, OOM) leaves a started record and no results, which
the merge names. A record without ``state`` (every RUNNER's) is complete.

Written by hand, as ASCII JSON: a runner loads no ``json`` for it. Read back (by the
report's merge) strictly: a record that is not one is named, never guessed at.
"""

from __future__ import annotations

import contextlib
import os

from ros_isolated_test import atomic_file
from ros_isolated_test.shard.spec import Share
from ros_isolated_test.text import display_text, json_string

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from pathlib import Path

    from ros_isolated_test.shard.selection import Selection

PREFIX = "ros_isolated_test_shard-"
SUFFIX = ".json"

#: The state of a record written before its results (the plugin's, at a session's start).
STARTED = "started"

__all__ = ["PREFIX", "STARTED", "SUFFIX", "Record", "file_name", "is_record", "leave", "read"]


class Record:
    """One machine's record: its share, its plan, the host and version that wrote it."""

    __slots__ = ("host", "path", "plan", "share", "started", "version")

    def __init__(
        self, share: Share, plan: str, host: str, version: str, path: Path, started: bool = False
    ) -> None:
        self.share = share
        self.plan = plan
        self.host = host
        self.version = version
        self.path = path
        #: Written before its results, and never completed: they may never have come.
        self.started = started

    def __repr__(self) -> str:
        return f"Record({self.share}, {self.plan!r}, {self.host!r})"


def file_name(share: Share) -> str:
    """``ros_isolated_test_shard-2-of-4.json`` for share 2 of 4."""
    return f"{PREFIX}{share.index}-of-{share.total}{SUFFIX}"


def is_record(name: str) -> bool:
    """Whether a file's name is that of a record (any share)."""
    if not (name.startswith(PREFIX) and name.endswith(SUFFIX)):
        return False
    index, of, total = name[len(PREFIX) : -len(SUFFIX)].partition("-of-")
    return bool(of) and index.isascii() and index.isdigit() and total.isascii() and total.isdigit()


def content(selection: Selection, host: str, version: str, started: bool = False) -> bytes:
    """The record's bytes: the same from every runner of one machine; ``started``: a state."""
    share = selection.share
    fields = [
        ("shard", json_string(str(share), True)),
        ("index", str(share.index)),
        ("total", str(share.total)),
        ("plan", json_string(selection.plan_name, True)),
        ("host", json_string(host, True)),
        ("version", json_string(version, True)),
    ]
    if started:
        fields.append(("state", json_string(STARTED, True)))
    body = ",\n".join(f'  "{name}": {value}' for name, value in fields)
    return f"{{\n{body}\n}}\n".encode("ascii")


def leave(
    folder: Path, selection: Selection, host: str, version: str, started: bool = False
) -> None:
    """Leave the machine's record in ``folder`` (made if missing); raises OSError.

    Nothing is written when the record is there already as it would be written: on a
    machine of many tests, only the first runner writes. Any other record there (another
    share's, or another plan's: an earlier run's) is removed, written or not.
    """
    data = content(selection, host, version, started)
    name = file_name(selection.share)
    path = folder / name
    try:
        with open(path, "rb") as handle:
            same = handle.read(len(data) + 1) == data
    except OSError:
        same = False  # none yet (or unreadable): written below, or the write says why not
    if not same:
        atomic_file.write_atomically(path, data)
    _remove_others(folder, name)


def _remove_others(folder: Path, kept: str) -> None:
    """Remove the records in ``folder`` but ``kept``: an earlier run's, of another share."""
    for other in os.listdir(folder):
        if other != kept and is_record(other):
            with contextlib.suppress(FileNotFoundError):  # another runner's removal came first
                os.unlink(folder / other)


def read(path: Path) -> Record | str:
    """The record at ``path``, or what is wrong with it (one phrase, after its name)."""
    import json

    try:
        found = json.loads(path.read_bytes()[: 64 * 1024].decode("utf-8"))
    except OSError as error:
        return f"cannot be read: {error.strerror or error}"
    except ValueError:
        return "is not a record of ros-isolated-test (not JSON)"
    if not isinstance(found, dict):
        return "is not a record of ros-isolated-test (not a JSON object)"
    index, total = found.get("index"), found.get("total")
    plan, host, version = found.get("plan"), found.get("host", ""), found.get("version", "")
    state = found.get("state", "complete")
    if state not in ("complete", STARTED):
        return f"is not a record of ros-isolated-test (state {display_text(str(state))!r})"
    if not (
        type(index) is int
        and type(total) is int
        and 1 <= index <= total
        and isinstance(plan, str)
        and plan
        and isinstance(host, str)
        and isinstance(version, str)
    ):
        return "is not a record of ros-isolated-test (no share I/N and plan in it)"
    try:
        share = Share(index, total)
    except ValueError as error:
        return f"names no share: {error}"
    if file_name(share) != os.path.basename(path):
        return f"says shard {share}, which its name does not"
    return Record(share, plan, host, version, path, started=state == STARTED)

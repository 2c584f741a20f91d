"""A split's step of the run: a test of another share is not run here, this share's is recorded.

Decided first, before anything is reserved or written (``ROS_ISOLATED_TEST_SHARD``, read
by ``settings.split`` into ``RunRequest.shard``). A test of another share leaves no result
file, so the merge of the machines' trees counts it once, where it ran: a stale one of
an earlier run here (a build folder restored from a cache) is removed. It says so in
one line and exits with the test's own skip code (``--skip-return-code N``; ``0`` with
``--skip-test``, where ament sets ctest's SKIP_RETURN_CODE to 0), else
:data:`~ros_isolated_test.runner.exit_codes.NOT_HERE` (77), the SKIP_RETURN_CODE the
CMake include and macros give every test they register: ctest shows it skipped, never
passed. Either way the machine's record (``shard.record``) is left beside the result
path, so the merge knows the share reported even when it ran nothing; a test it runs
records its share and plan among its result's properties.

Because ctest reads 77 as "skipped" for every test the include registered, a test that
RUNS and ends with 77, having no skip code of its own, would be shown skipped: in RUNNER
mode the runner exits 1 instead (:func:`exit_code`), its result file keeping the real code.
"""

from __future__ import annotations

import contextlib

from ros_isolated_test import __version__
from ros_isolated_test.runner import exit_codes, streams
from ros_isolated_test.runner.request import Mode

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from typing import BinaryIO

    from ros_isolated_test.runner.request import RunRequest
    from ros_isolated_test.shard.selection import Selection
    from ros_isolated_test.xunit.result_file import ResultFile

__all__ = ["decide", "exit_code"]


def decide(request: RunRequest, result: ResultFile, console: BinaryIO) -> int | None:
    """The exit code of a test of another share (not run, no result file); None: run it."""
    selection = request.shard
    if selection is None:
        return None
    package, name = request.package, request.test_name
    if selection.runs(package, name):
        result.properties.update(selection.properties())
        _leave_record(result, selection, console)
        return None
    try:
        result.prepare()  # an earlier run's result of it here goes: this share has none
    except OSError as error:
        streams.error(
            console,
            f"cannot remove the result file {request.result_file} of an earlier run "
            f"({error.strerror}): this test is not in shard {selection.share}, so no result "
            "of it may stay here; remove it",
        )
        return exit_codes.USAGE
    _leave_record(result, selection, console)
    _say(console, selection.not_here(package, name))
    if request.skip_test:
        return exit_codes.PASSED  # ament's SKIP_RETURN_CODE for --skip-test
    if request.skip_return_code is not None:
        return request.skip_return_code
    return exit_codes.NOT_HERE


def exit_code(request: RunRequest, code: int, console: BinaryIO) -> int:
    """``code``, but a test that ran and ended with 77 (no skip code of its own) fails: 1.

    In RUNNER mode only: ctest reads 77 as skipped for every test the CMake include and
    macros registered. The shell's ``run`` keeps the command's own code, as ever.
    """
    if (
        code != exit_codes.NOT_HERE
        or request.mode is not Mode.AMENT
        or request.skip_return_code is not None
        or request.skip_test
    ):
        return code
    _say(
        console,
        f"the test exited {code}, which ctest reads as skipped (SKIP_RETURN_CODE "
        f"{exit_codes.NOT_HERE}, set by ros-isolated-test); it ran, so the runner exits "
        f"{exit_codes.FAILED} (the result file keeps {code}); give the test "
        "SKIP_RETURN_CODE to mean a skip",
    )
    return exit_codes.FAILED


def _leave_record(result: ResultFile, selection: Selection, console: BinaryIO) -> None:
    """Leave the machine's record beside the result path; a failure is said, never fatal."""
    if result.path is None:
        return
    # Only in a split: a test's path without a share loads neither.
    from ros_isolated_test.shard import record
    from ros_isolated_test.xunit.validate import hostname

    try:
        record.leave(result.path.parent, selection, hostname(), __version__)
    except OSError as error:
        streams.error(
            console,
            f"cannot leave the shard record {record.file_name(selection.share)} in "
            f"{result.path.parent} ({error.strerror or error}): a merge of the machines' "
            "results may not know this share reported; make the folder writable",
        )


def _say(console: BinaryIO, line: str) -> None:
    """One line on the console (ctest's log), after what was printed before."""
    with contextlib.suppress(OSError, ValueError):
        console.write(f"ros-isolated-test: {line}\n".encode("utf-8", "backslashreplace"))
        console.flush()

"""One test's result file through its life: stale file gone, placeholder, final word.

The final word is always a canonical file at the result path: the test's own file
normalised (the original kept beside it as ``<name>.orig``), or one written for a
test that wrote none.
"""

from __future__ import annotations

import contextlib
import errno
import os
import shlex
import sys
import time
from pathlib import Path

from ros_isolated_test.atomic_file import write_atomically
from ros_isolated_test.xunit import validate
from ros_isolated_test.xunit.model import Case, Outcome, Suite

TYPE_CHECKING = False
if TYPE_CHECKING:
    from ros_isolated_test.runner.request import RunRequest
    from ros_isolated_test.xunit import reader

NO_RESULT = "The test did not generate a result file."
ORIGINAL_SUFFIX = ".orig"


class ResultFile:
    """The request's result file; every method is a no-op when none was asked for."""

    def __init__(self, request: RunRequest) -> None:
        self.request = request
        self.path = request.result_file
        self.started = time.time()
        self.properties: dict[str, str] = {"command": shlex.join(request.command)}
        self.placeholder: bytes | None = None
        #: What was wrong with the test's own file, for the console.
        self.problems: list[str] = []
        #: Why the result file could not be written, if it could not.
        self.write_error: str | None = None

    @property
    def original(self) -> Path | None:
        """Where the test's own file is kept once its canonical form replaces it."""
        return None if self.path is None else self.path.with_name(self.path.name + ORIGINAL_SUFFIX)

    def prepare(self) -> None:
        """Drop stale files of an earlier run (colcon never clears them), make the folder."""
        if self.path is None:
            return
        if self.path.is_dir():
            raise IsADirectoryError(errno.EISDIR, "it is a directory", str(self.path))
        for stale in (self.path, self.original):
            assert stale is not None
            with contextlib.suppress(FileNotFoundError):
                if stale.is_dir() and not stale.is_symlink():
                    import shutil

                    shutil.rmtree(stale)
                else:
                    stale.unlink()
        self.path.parent.mkdir(parents=True, exist_ok=True)

    def case(self, outcome: Outcome, message: str = "", duration: float = 0.0) -> Case:
        """The test as one case, for a test that wrote no result of its own."""
        case = Case.saying(self.suite_name, self.request.test_name, outcome, message)
        case.time = duration
        return case

    @property
    def suite_name(self) -> str:
        """``<package>.<test name>``: unique across a build, as CI reports need."""
        return f"{self.request.package}.{self.request.test_name}"

    def write(
        self, cases: list[Case], duration: float = 0.0, output: str = "", checked: bool = False
    ) -> validate.Rendered | None:
        """Write the canonical file holding ``cases``; None when no file was asked for.

        ``checked`` when the cases came from the test's own file: the runner's own
        results have a fixed shape, checked against the schema by the test suite.
        """
        if self.path is None:
            return None
        suite = Suite(
            name=self.suite_name,
            cases=cases,
            time=duration,
            timestamp=validate.timestamp(self.started),
            hostname=validate.hostname(),
            properties=dict(self.properties),
            system_out=output,
        )
        rendered = validate.render(suite, checked)
        try:
            write_atomically(self.path, rendered.data)
        except OSError as error:
            self.write_error = f"cannot write result file {self.path}: {error.strerror or error}"
            with contextlib.suppress(OSError, ValueError):
                print(f"ros-isolated-test: error: {self.write_error}", file=sys.stderr, flush=True)
            return None
        return rendered

    def write_placeholder(self) -> None:
        """What ctest leaves behind if it kills the runner: the test did not finish."""
        message = (
            f"{NO_RESULT} If this is all there is, the runner was killed before the test "
            "ended, as a ctest TIMEOUT does (SIGKILL, no chance to write anything else): "
            "the test most likely timed out."
        )
        rendered = self.write([self.case(Outcome.ERROR, message)])
        self.placeholder = rendered.data if rendered is not None else None

    def untouched(self) -> bool:
        """Whether the test left our placeholder (or nothing) in place."""
        if self.path is None:
            return True
        if self.placeholder is not None and validate.holds_exactly(self.path, self.placeholder):
            return True
        return not os.path.lexists(self.path)

    def adopt(self) -> list[Case]:
        """The test's own file as canonical cases; the original is moved aside, not lost."""
        assert self.path is not None and self.original is not None
        cases, read = read_cases(self.path, self.request.package, self.request.test_name)
        self.problems = read.problems + read.repairs
        if read.repairs:
            self.properties["result_file_repairs"] = "; ".join(read.repairs)
        if os.path.lexists(self.path):
            os.replace(self.path, self.original)
            self.properties["original_result_file"] = self.original.name
        return cases


def read_cases(
    path: Path, package: str | None, test_name: str
) -> tuple[list[Case], reader.ReadResult]:
    """The canonical cases of any result file, and what reading it found."""
    from ros_isolated_test.xunit import normalise, reader

    read = reader.read(path)
    return normalise.cases_from(read, package, test_name), read


def normalise_file(path: Path, package: str, test_name: str) -> tuple[bytes, bool]:
    """A producer's result file as canonical bytes, and whether anything in it failed."""
    cases, read = read_cases(path, package, test_name)
    properties = {"original_result_file": path.name}
    if read.repairs:
        properties["result_file_repairs"] = "; ".join(read.repairs)
    suite = Suite(
        name=f"{package}.{test_name}",
        cases=cases,
        time=sum(case.time for case in cases),
        timestamp=validate.timestamp(),
        hostname=validate.hostname(),
        properties=properties,
    )
    rendered = validate.render(suite)
    return rendered.data, rendered.failed

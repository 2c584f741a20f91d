"""One test's result file through its life: stale file gone, placeholder, final word.

The runner's session drives it through named steps and it never calls back: ``prepare``
(clear what an earlier run left), ``write_placeholder`` (what a killed runner leaves),
then the final word, ``write`` (a result of the runner's own, or the test's own file
once ``adopt`` made it canonical). A run with reruns adds ``end_attempt`` after each
attempt's word, ``next_attempt`` before the next one, and ``write_attempts`` for the
file that holds them all; ``rewrite`` says the final word again with what came since.

The test writes its own file beside the result path (``own_file``), never over the
placeholder: only the runner, once the test has ended, puts a word of the test's at the
result path, so a runner killed at any instant never leaves "passed" there unless it
concluded so. A command that names no argument as the result path writes it itself
(``in_place``), as before: said in the result.

The final word is always a canonical file at the result path: the test's own file
normalised (the original kept beside it as ``<name>.orig``, linked or moved there before
the canonical file replaces it in one rename, so a kill at any instant leaves a file at
the path), or one written for a test that wrote none. When the final word cannot be
written, the placeholder is overwritten in place by a stand-in saying so (``placeholder``).
"""

from __future__ import annotations

import contextlib
import errno
import os
import sys
import time
from pathlib import Path

from ros_isolated_test import names
from ros_isolated_test.atomic_file import (
    SPECIAL_FIX,
    NotReplaceableError,
    discards,
    special_kind,
    write_atomically,
)
from ros_isolated_test.text import shell_join, shown
from ros_isolated_test.xunit import placeholder, serialise, validate
from ros_isolated_test.xunit.canonical import read_cases
from ros_isolated_test.xunit.kept_files import (
    attempt_original_of,
    keep_aside,
    original_of,
    remove,
)
from ros_isolated_test.xunit.model import Case, Outcome, Suite

TYPE_CHECKING = False
if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

NO_RESULT = "The test did not generate a result file."
#: The suite property of a test that wrote the result path itself (``in_place``).
IN_PLACE_PROPERTY = names.RESULT_FILE_IN_PLACE
_SPACE_ERRORS = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)


class ResultFile:
    """A test's result file at ``path``; every method is a no-op when none was asked for.

    ``package`` and ``test_name`` name the suite (``<package>.<test name>``); the
    ``command`` is recorded among its properties.
    """

    def __init__(
        self, path: Path | None, command: Sequence[str], package: str, test_name: str
    ) -> None:
        self.path = path
        self.package = package
        self.test_name = test_name
        self.started = time.time()
        self.properties: dict[str, str] = {"command": shell_join(command)}
        self.placeholder: bytes | None = None
        #: What was wrong with the test's own file, for the console.
        self.problems: list[str] = []
        #: Why the result file could not be written, if it could not.
        self.write_error: str | None = None
        #: The properties the last final word written holds.
        self.written: dict[str, str] = {}
        #: The suite of that final word: one attempt's result, when a test runs again.
        self.last_suite: Suite | None = None
        # How that final word is built from the properties, whether it is checked, and
        # the earlier attempts it was written beside, to write it again.
        self._last: _Word | None = None
        # A rerun series: the suites of the attempts whose final word was written (none
        # until end_attempt), put beside each later word so the file on disk never shows
        # an attempt without the failures before it; the last one kept (end_attempt).
        self._attempts: list[Suite] = []
        self._kept_last: Suite | None = None
        # Whether adopt() kept the test's own file aside at ``original``; whether it took
        # it from ``own`` (the result path then holds our placeholder, not the test's file);
        # the node kept there, the one special file (a FIFO the test left) a write may replace.
        self._adopted = False
        self._beside = False
        self._kept: os.stat_result | None = None
        #: Where the current attempt writes its own file (own_file).
        self.own: Path | None = None
        #: The command names no argument as the result path: the test writes it itself.
        self.in_place = False
        # Why the last write failed, in the system's words (No space left on device).
        self._failure = "the write failed"

    @property
    def original(self) -> Path | None:
        """Where the test's own file is kept once its canonical form replaces it."""
        return None if self.path is None else original_of(self.path)

    @property
    def attempts_written(self) -> int:
        """How many attempts of a rerun series have a final word kept (``end_attempt``)."""
        return len(self._attempts)

    def prepare(self) -> None:
        """Drop stale files of an earlier run (colcon never clears them), make the folder.

        The null device discards the result: nothing is written, as if none was asked
        for (``pytest --junit-xml=/dev/null`` keeps nothing either). Any other device
        node, FIFO or socket (or a symlink to one) would be replaced by the first write:
        :class:`NotReplaceableError`, and nothing is touched.
        """
        if self.path is None:
            return
        if discards(self.path):
            self.path = None
            return
        kind = special_kind(self.path)
        if kind is not None:
            raise NotReplaceableError(self.path, kind)
        if self.path.is_dir():
            raise IsADirectoryError(errno.EISDIR, "it is a directory", str(self.path))
        for stale in (self.path, self.original):
            assert stale is not None
            with contextlib.suppress(FileNotFoundError):
                remove(stale)
        number = 1
        # Earlier attempts' own files of a run with reruns: one lstat when there are none.
        while os.path.lexists(stale := self.attempt_original(number)):
            remove(stale)
            number += 1
        self.path.parent.mkdir(parents=True, exist_ok=True)

    def attempt_original(self, number: int) -> Path:
        """Where the test's own file of attempt ``number`` is kept once a rerun follows."""
        assert self.path is not None
        return attempt_original_of(self.path, number)

    def own_file(self, number: int) -> Path | None:
        """Where attempt ``number`` writes its own file: beside the result path.

        Never the result path itself: there the placeholder (in a rerun series, the
        record so far: the earlier attempts and a case saying this one did not finish)
        must stay until the runner adopts this attempt, or a kill after a passing test
        wrote its file would leave "passed". Not ``*.xml``, so no glob of results reads
        it. None (the result path, the old way) when the name cannot be cleared.
        """
        self.own, self.in_place = None, False
        if self.path is None:
            return None
        own = self.attempt_original(number)
        try:
            remove(own)  # the test's own leftover: this name is the runner's
        except OSError as error:
            _say(
                f"cannot clear {own} ({_reason(error)}), so attempt {number} writes its own "
                f"result file to {self.path} itself; remove what is in the way there"
            )
            return None
        self.own = own
        return own

    def writes_in_place(self) -> None:
        """The command names no argument as the result path: if the test writes it, there."""
        self.own, self.in_place = None, True

    def end_attempt(self) -> None:
        """The attempt's final word, if it was written, joins those the series merges."""
        from ros_isolated_test.xunit.attempts import ATTEMPTS_PROPERTY

        self._kept_last, self.last_suite = self.last_suite, None
        if self._kept_last is not None:
            # The merge counts the attempts itself; attempt 1's own count would be kept
            # as a difference (attempt_1.attempts).
            self._kept_last.properties.pop(ATTEMPTS_PROPERTY, None)
            self._attempts.append(self._kept_last)

    def next_attempt(self, finished: int, properties: dict[str, str]) -> bool:
        """Make ready for the test to run again after attempt ``finished``.

        The properties start again from ``properties``; the test's own file of the
        attempt (``.orig``) is kept as ``.attempt<N>.orig``; the placeholder goes back in
        place, so a file the rerun writes is told from one it does not, now beside the
        attempts so far. False when it cannot be written.
        """
        self.properties = dict(properties)
        self.problems = []
        if self.path is None:
            return True
        assert self.original is not None
        self._beside, self._kept = False, None
        if self._adopted:
            self._adopted = False
            kept = self.attempt_original(finished)
            try:
                os.replace(self.original, kept)
            except OSError as error:
                _say(
                    f"cannot keep the test's own file of attempt {finished} as {kept} "
                    f"({_reason(error)}), so the next attempt may overwrite it; remove what "
                    "is in the way there and make its folder writable"
                )
            else:
                # Written again (a rerun that gets no ID) or merged, it names the file kept.
                for said in (self.written, self._kept_last and self._kept_last.properties):
                    if said and said.get("original_result_file") == self.original.name:
                        said["original_result_file"] = kept.name
        return self.write_placeholder()

    def case(self, outcome: Outcome, message: str = "", duration: float = 0.0) -> Case:
        """The test as one case, for a test that wrote no result of its own."""
        case = Case.saying(self.suite_name, shown(self.test_name), outcome, shown(message))
        case.time = duration
        return case

    @property
    def suite_name(self) -> str:
        """``<package>.<test name>``: unique across a build, as CI reports need."""
        return shown(f"{self.package}.{self.test_name}")

    def _suite(
        self, cases: list[Case], duration: float, properties: dict[str, str], output: str = ""
    ) -> Suite:
        return Suite(
            name=self.suite_name,
            cases=cases,
            time=duration,
            timestamp=validate.timestamp(self.started),
            hostname=validate.hostname(),
            properties={name: shown(value) for name, value in properties.items()},
            system_out=output,
        )

    def write(
        self, cases: list[Case], duration: float = 0.0, output: str = "", checked: bool = False
    ) -> validate.Rendered | None:
        """Write the canonical file holding ``cases``; None when no file was asked for.

        ``checked`` when the cases came from the test's own file: the runner's own
        results have a fixed shape, checked against the schema by the test suite. When
        the write fails, ``write_error`` says why (on stderr too), and the file left
        behind says the result could not be written rather than what the placeholder said.
        """
        if self.path is None:
            return None

        def build(properties: dict[str, str]) -> Suite:
            return self._suite(cases, duration, properties, output)

        return self._final(build, checked)

    def write_attempts(self, domain_ids: Sequence[str]) -> validate.Rendered | None:
        """Write the suite of every attempt kept, each on its ID, checked (merge_attempts).

        Properties added since (why a rerun did not run, a late signal) join its own.
        """
        if self.path is None:
            return None
        from ros_isolated_test.xunit.attempts import merge_attempts

        # Taken whole: what is written from now on stands beside no earlier attempt.
        merged, self._attempts = merge_attempts(self._attempts), []
        merged.properties[names.ROS_DOMAIN_IDS] = ", ".join(domain_ids)

        def build(properties: dict[str, str]) -> Suite:
            for name, value in properties.items():
                merged.properties.setdefault(name, shown(value))
            return merged

        return self._final(build, checked=True)

    def _beside_earlier(self, suite: Suite, earlier: tuple[Suite, ...] | None) -> Suite:
        """``suite`` after the earlier attempts of a series (None: no series); no copies.

        merge_attempts builds new cases and never changes the suites it is given.
        """
        if earlier is None:
            return suite
        from ros_isolated_test.xunit.attempts import merge_attempts

        return merge_attempts([*earlier, suite])

    def _final(
        self, build: Callable[[dict[str, str]], Suite], checked: bool
    ) -> validate.Rendered | None:
        """Write ``build``'s suite (beside the earlier attempts, in a rerun).

        Returns this attempt's own rendering: whether *it* failed decides its exit code.
        """
        properties = dict(self.properties)
        suite = build(properties)
        rendered = validate.render(suite, checked)
        earlier = tuple(self._attempts) or None
        data = (
            rendered.data
            if earlier is None
            else validate.render(self._beside_earlier(suite, earlier)).data
        )
        if self._write(data):
            self.written, self._last, self.last_suite = properties, (build, checked, earlier), suite
            return rendered
        self._leave_word(suite.cases, suite.time)
        return None

    def rewrite(self) -> None:
        """The last final word again, with the properties added since (a late signal).

        Should this write fail, the file already written stands: it is complete.
        """
        if self.path is None or self._last is None:
            return
        build, checked, earlier = self._last
        properties = dict(self.properties)
        suite = build(properties)
        if earlier is not None:
            suite, checked = self._beside_earlier(suite, earlier), True
        try:
            write_atomically(self.path, validate.render(suite, checked).data, replacing=self._kept)
        except OSError as error:
            _say(f"the result file {self.path} does not note a late signal: {_reason(error)}")
            return
        self.written = properties

    def write_placeholder(self) -> bool:
        """What ctest leaves behind if it kills the runner: the test did not finish.

        It ends in a comment holding room for a stand-in: should the final write fail,
        the stand-in overwrites it in place, in blocks already allocated. False when it
        could not be written (the error is on stderr, ``write_error`` says it). In a
        rerun series it stands after the attempts so far.
        """
        if self.path is None:
            return True
        message = (
            f"{NO_RESULT} If this is all there is, {placeholder.KILLED}, as a ctest "
            "TIMEOUT does (SIGKILL, no chance to write anything else): the test most likely "
            "timed out."
        )
        # When it was written: a killed test's duration counts from here (placeholder).
        properties = placeholder.stamped(self.properties, time.time())
        suite = self._suite([self.case(Outcome.ERROR, message)], 0.0, properties)
        suite = self._beside_earlier(suite, tuple(self._attempts) or None)
        data = placeholder.with_room(serialise.serialize(suite))
        if not self._write(data):
            return False
        self.placeholder = data
        return True

    def _write(self, data: bytes) -> bool:
        assert self.path is not None
        try:
            write_atomically(self.path, data, replacing=self._kept)
        except OSError as error:
            self._failure = _reason(error)
            self.write_error = f"cannot write result file {self.path}: {self._failure}"
            _say(f"error: {self.write_error}; {_fix(error)}")
            return False
        return True

    def _leave_word(self, cases: list[Case], duration: float) -> None:
        """After a failed final write: leave a file behind that says what happened.

        The test's own file, if kept aside, is still at the path (a directory moved
        aside goes back): its word is the best one left. Else our placeholder, if still
        there, is overwritten by the stand-in, beside the earlier attempts it holds.
        """
        assert self.path is not None and self.original is not None
        if self._adopted and not self._beside:
            if not os.path.lexists(self.path):  # a directory, moved aside whole
                try:
                    os.replace(self.original, self.path)
                except OSError as error:
                    _say(f"error: cannot put the test's own result file back: {_reason(error)}")
                    return
            _say(f"the test's own result file is left at {self.path}, as the test wrote it")
            return
        if self.placeholder is None:
            return
        stand_in = placeholder.StandIn(
            self._suite([self.case(Outcome.ERROR, "", duration)], duration, {}),
            self._failure,
            self.write_error or self._failure,
            self.properties,
            cases,
            self._attempts,  # those the placeholder stands beside, in a rerun series
        )
        try:
            left = placeholder.overwrite_in_place(self.path, self.placeholder, stand_in)
        except OSError as error:
            _say(f"error: cannot replace the placeholder at {self.path} either: {_reason(error)}")
            return
        if left:
            _say(f"a result saying it could not be written is left at {self.path}")

    def untouched(self) -> bool:
        """Whether the test left our placeholder (or nothing) in place."""
        if self.path is None:
            return True
        if self.own is not None and os.path.lexists(self.own):
            return False
        if self.placeholder is not None and placeholder.holds_exactly(self.path, self.placeholder):
            return True
        return not os.path.lexists(self.path)

    def adopt(self) -> list[Case]:
        """The test's own file as canonical cases; the original is kept aside, never lost.

        The original is linked (or copied) to ``original`` and stays at the path until
        :meth:`write` renames the canonical file over it: whenever the runner is killed,
        a file is at the path. A directory in its place can only be moved aside whole.
        A file written to ``own`` is moved to ``original``: the path holds the
        placeholder (or the record so far) meanwhile.
        """
        assert self.path is not None and self.original is not None
        beside = self.own is not None and os.path.lexists(self.own)
        source = self.own if beside and self.own is not None else self.path
        # Named as the result path, which the test was told it writes (not as ``own``).
        cases, read = read_cases(source, self.package, self.test_name, self.path)
        self.problems = read.problems + read.repairs
        if read.repairs:
            self.properties[names.RESULT_FILE_REPAIRS] = "; ".join(read.repairs)
        if os.path.lexists(source):
            try:
                if beside:
                    remove(self.original)
                    os.rename(source, self.original)
                else:
                    keep_aside(self.path, self.original)
                    self._kept = os.lstat(self.original)
            except OSError as error:
                problem = f"cannot keep the test's own file as {self.original}: {_reason(error)}"
                self.problems.append(problem)
                self.properties[names.ORIGINAL_RESULT_FILE_ERROR] = problem
            else:
                self._adopted, self._beside = True, beside
                self.properties[names.ORIGINAL_RESULT_FILE] = self.original.name
        if self.in_place and not beside:
            said = (
                f"no argument of the command names {self.path.name}, so the test wrote it "
                "itself: a runner killed after that write leaves the test's own word there"
            )
            self.properties[IN_PLACE_PROPERTY] = said
            self.problems.append(f"{said} (see docs/faults.md)")
        return cases


if TYPE_CHECKING:
    #: A final word: how it is built from the properties, whether it is checked, and the
    #: earlier attempts of its series (None: none).
    _Word = tuple[Callable[[dict[str, str]], Suite], bool, tuple[Suite, ...] | None]


def _reason(error: OSError) -> str:
    return error.strerror or str(error)


def _fix(error: OSError) -> str:
    """The fix a user can make, for the one-line error."""
    if isinstance(error, NotReplaceableError):
        return SPECIAL_FIX
    if error.errno in _SPACE_ERRORS:
        return "free space on its file system, or choose a result path on another one"
    return "choose a writable file path"


def _say(text: str) -> None:
    """One line on stderr; a reader that went away loses nothing the exit code keeps."""
    with contextlib.suppress(OSError, ValueError):
        print(f"ros-isolated-test: {text}", file=sys.stderr, flush=True)

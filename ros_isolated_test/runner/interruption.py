"""A signal to the runner (ctest's SIGTERM, a Ctrl-C): what it means depends on when it comes.

Before the test starts (a runner queued for an ID; PID 1, which has no default action)
it ends the run cleanly, with a result saying the test never ran (:class:`Interrupted`).
While the test runs, the supervisor's own handlers pass it on. After that (the ID being
released, the result file being written) it is only noted: the run's outcome stands.
"""

from __future__ import annotations

import contextlib

from ros_isolated_test import names
from ros_isolated_test.process import signals
from ros_isolated_test.runner import exit_codes

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from collections.abc import Iterator
    from types import FrameType

    from ros_isolated_test.xunit.result_file import ResultFile


class Interrupted(Exception):
    """A signal ended the run before the test started (while waiting for an ID)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


class Guard:
    """Whether the test has started: a signal after that must not say it never ran."""

    def __init__(self) -> None:
        self.test_started = False
        #: The run is writing its final word (a "not run" result): signals only noted.
        self.concluding = False
        self.late: int | None = None
        #: Where a late signal is noted, once the test has ended.
        self.result: ResultFile | None = None

    def start(self) -> None:
        """Called by the supervisor once the test exists, while its own handlers are in place.

        Not before: a signal until then finds the test not started and ends the run
        cleanly, saying it never ran, rather than being noted while the test runs in full.
        """
        self.test_started = True

    def next_attempt(self) -> None:
        """A rerun is about to start: a signal ends it at once (one queued for an ID too)."""
        self.test_started = self.concluding = False
        if self.late is not None:
            raise Interrupted(self.late)

    def note_late(self) -> None:
        """The test had ended: the run's outcome stands, the signal is only noted."""
        if self.late is not None and self.result is not None:
            self.result.properties[names.SIGNAL_AFTER_TEST] = exit_codes.signal_name(self.late)


@contextlib.contextmanager
def interruptible(guard: Guard) -> Iterator[None]:
    """Until the final result is written, SIGINT/SIGTERM/SIGHUP never end the runner abruptly.

    See the module's docstring for what each does and when. Outside the main thread (an
    embedding program) handlers cannot be set: the program's own stay.
    """

    def stop(signum: int, _frame: FrameType | None) -> None:
        if guard.test_started or guard.concluding:
            if guard.late is None:
                guard.late = signum
                guard.note_late()
            return
        guard.concluding = True
        raise Interrupted(signum)

    previous = signals.set_handlers(stop)
    try:
        yield
    finally:
        signals.restore_handlers(previous)

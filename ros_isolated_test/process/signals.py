"""The signals that end a run: the runner's handlers for them, and passing them on to the test.

Apart from the supervisor because the pytest plugin and the runner's session install the
same handlers around their own work (``set_handlers``/``restore_handlers``), while only
a running test needs :class:`Signals`, which forwards each signal through the test's tree.
"""

from __future__ import annotations

import contextlib
import os
import signal
import time
from collections.abc import Callable

from ros_isolated_test.process import tree

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from types import FrameType

    Handler = Callable[[int, FrameType | None], object] | int | signal.Handlers | None

#: Signals that end a run: passed on to the test, then the same cleanup as a timeout.
FORWARDED_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def set_handlers(handler: Callable[[int, FrameType | None], object]) -> dict[int, Handler]:
    """Handle every forwarded signal with ``handler``; the previous handlers, to restore.

    Outside the main thread (a program embedding the runner) none can be set, and the
    program's own handlers stay: returns an empty dict.
    """
    previous: dict[int, Handler] = {}
    try:
        for signum in FORWARDED_SIGNALS:
            previous[signum] = signal.signal(signum, handler)
    except ValueError:
        restore_handlers(previous)
        return {}
    return previous


def restore_handlers(previous: dict[int, Handler]) -> None:
    """Put back what :func:`set_handlers` replaced."""
    for signum, handler in previous.items():
        signal.signal(signum, handler)


class Signals:
    """Signal handlers for the test's lifetime: pass the signal on, remember it."""

    def __init__(self, others: frozenset[tuple[int, int]]) -> None:
        self.received: int | None = None
        self.at: float | None = None
        self._previous: dict[int, Handler] = {}
        self._others = others

    def __enter__(self) -> Signals:
        self._previous = set_handlers(self._forward)
        return self

    def __exit__(self, *_exc: object) -> None:
        restore_handlers(self._previous)

    def _forward(self, signum: int, _frame: FrameType | None) -> None:
        if self.received is None:
            self.received, self.at = signum, time.monotonic()
        targets = tree.descendants(os.getpid(), skip=self._others)
        if signum == signal.SIGINT and _from_terminal():
            # The terminal already sent it to our process group: only processes that
            # left the group (setsid daemons) still need it, and only once.
            group = os.getpgrp()
            targets = [target for target in targets if target.pgid != group]
        tree.signal_all(targets, signum)


def _from_terminal() -> bool:
    """Whether our group is a terminal's foreground group (so Ctrl-C reached all of it)."""
    for fd in (0, 1, 2):
        with contextlib.suppress(OSError):
            return os.tcgetpgrp(fd) == os.getpgrp()
    return False

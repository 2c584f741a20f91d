"""Process supervision: start the test, pump its output, end its whole tree, report how it ended.

The test stays in the runner's process group, as a shell's foreground job does, so it
may read a terminal's stdin without being stopped by SIGTTIN and a terminal's Ctrl-C
reaches it directly. The runner is a child subreaper: every process the test starts
stays in its tree, and none outlives the run. When the test's main process ends, for
any reason, what is left of the tree gets SIGTERM and a grace period to exit; then the
tree is frozen (SIGSTOP until no process of it runs: a stopped process cannot fork)
and SIGKILLed until it is empty. Only then does the caller release the domain ID, and
a process that outlives even that (one we may not signal, one stuck in the kernel) is
reported as a survivor, for the caller to keep the ID blocked while it lives.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import select
import signal
import time
from collections.abc import Callable, Iterator, Mapping, Sequence

from ros_isolated_test.process import proc, reaper, tree
from ros_isolated_test.process.capture import OutputCapture

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from types import FrameType

    Handler = Callable[[int, FrameType | None], object] | int | signal.Handlers | None

CHUNK_BYTES = 64 * 1024
#: How long to keep draining output after the test exited, while bytes keep coming.
DRAIN_IDLE_SECONDS = 0.2
#: At most this long after the test exited, however much its leftovers keep writing.
DRAIN_LIMIT_SECONDS = 1.0
POLL_SECONDS = 0.2
#: Signals that end a run: passed on to the test, then the same cleanup as a timeout.
FORWARDED_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
#: Seconds a test (and what it left running) gets to exit on SIGTERM before SIGKILL.
KILL_GRACE = 5.0
#: The exit code a test gets when its status was reaped by someone else: a failure.
STATUS_LOST = 255
#: Reset to their default in the test: Python ignores SIGPIPE, and so would the test.
_DEFAULT_IN_TEST = (signal.SIGPIPE, signal.SIGXFSZ)
#: How often the tree is looked at while leftovers have their grace period.
TERM_POLL_SECONDS = 0.05
#: SIGSTOP sweeps give up on processes that do not stop within this (stuck in the
#: kernel): the SIGKILL passes that follow still reach them.
FREEZE_LIMIT_SECONDS = 2.0
#: SIGKILL passes stop once the tree has not shrunk for this long: what is left cannot
#: be killed by us, and must not hang the runner.
KILL_STALL_SECONDS = 2.0
#: At most this many leftovers are named one by one (a forking daemon makes hundreds).
NAMED_LIMIT = 100


class Outcome:
    """How the test ended. Exactly one of ``returncode`` / ``start_error`` is set."""

    __slots__ = (
        "duration",
        "leftovers",
        "received_signal",
        "returncode",
        "start_error",
        "survivors",
        "timed_out",
    )

    def __init__(
        self,
        returncode: int | None,
        duration: float,
        timed_out: bool = False,
        start_error: OSError | None = None,
        received_signal: int | None = None,
        leftovers: tuple[str, ...] = (),
        survivors: tuple[proc.Stat, ...] = (),
    ) -> None:
        self.returncode = returncode
        self.duration = duration
        self.timed_out = timed_out
        self.start_error = start_error
        #: A signal the runner received and passed on (Ctrl-C, SIGTERM from a container stop).
        self.received_signal = received_signal
        #: Processes of the test still alive after its main process ended, then stopped.
        self.leftovers = leftovers
        #: Processes of the test that even SIGKILL did not end (not ours to signal, stuck
        #: in the kernel): alive after the run, so the caller keeps the ID blocked.
        self.survivors = survivors

    @property
    def signal(self) -> int | None:
        """The signal that killed the test, if one did."""
        if self.returncode is not None and self.returncode < 0:
            return -self.returncode
        return None


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


class _Signals:
    """Signal handlers for the test's lifetime: pass the signal on, remember it."""

    def __init__(self, others: frozenset[tuple[int, int]]) -> None:
        self.received: int | None = None
        self.at: float | None = None
        self._previous: dict[int, Handler] = {}
        self._others = others

    def __enter__(self) -> _Signals:
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


class _Test:
    """The test's main process and the read end of its output pipe.

    Started with ``posix_spawn``, not ``subprocess``: the one call the runner needs
    does not pay for importing subprocess (and threading, selectors) on every test.
    It is started as Popen would start it: found on the test's own PATH, with
    SIGPIPE at its default, without the runner's other descriptors.
    """

    def __init__(
        self, command: Sequence[str], env: Mapping[str, str], namespaces: bool = False
    ) -> None:
        read_fd, write_fd = _pipe_above_stdio()
        try:
            with _inherited_fds_closed_on_exec():
                self.pid = _spawn(command, env, write_fd, namespaces)
        except BaseException:
            os.close(read_fd)
            raise
        finally:
            os.close(write_fd)
        self.stdout = read_fd
        self.returncode: int | None = None
        #: The status was reaped elsewhere (SIGCHLD ignored in an embedding thread).
        self.status_lost = False

    def poll(self) -> int | None:
        """The exit code (negative: killed by that signal), or None while it runs."""
        if self.returncode is None:
            try:
                pid, status = os.waitpid(self.pid, os.WNOHANG)
            except ChildProcessError:
                # Reaped elsewhere: never wait forever, and never call it a pass.
                self.status_lost = True
                self.returncode = STATUS_LOST
                return STATUS_LOST
            if pid:
                self.returncode = os.waitstatus_to_exitcode(status)
        return self.returncode

    def wait(self, timeout: float | None = None) -> int | None:
        """Wait for the exit code; None if ``timeout`` seconds pass first."""
        deadline = None if timeout is None else time.monotonic() + timeout
        delay = 0.0005
        while self.poll() is None:
            if deadline is None:
                with contextlib.suppress(ChildProcessError):
                    _pid, status = os.waitpid(self.pid, 0)
                    self.returncode = os.waitstatus_to_exitcode(status)
                continue
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return None
            time.sleep(min(delay, remaining))
            delay = min(delay * 2, 0.05)
        return self.returncode


def _spawn(
    command: Sequence[str], env: Mapping[str, str], output_fd: int, namespaces: bool = False
) -> int:
    """Start ``command`` with ``output_fd`` as its stdout and stderr; its PID.

    Each match on the test's PATH is tried in turn, as execvp does: a script whose
    interpreter is missing (ENOENT) gives way to the next match. With ``namespaces`` the
    test starts in namespaces of its own (``namespace.spawn``: a fork, as posix_spawn
    cannot unshare), with the same descriptors and signals.
    """
    name = command[0]
    if os.sep in name:
        candidates = [name]
    else:
        folders = os.get_exec_path(dict(env))
        candidates = [
            path for folder in folders if os.path.exists(path := os.path.join(folder, name))
        ]
    if namespaces:
        from ros_isolated_test.process import namespace

        return namespace.spawn(name, candidates, command, env, output_fd, _DEFAULT_IN_TEST)
    kept: OSError | None = None
    last: OSError | None = None
    for path in candidates:
        try:
            return os.posix_spawn(
                path,
                list(command),
                dict(env),
                file_actions=[
                    (os.POSIX_SPAWN_DUP2, output_fd, 1),
                    (os.POSIX_SPAWN_DUP2, output_fd, 2),
                ],
                setsigdef=_DEFAULT_IN_TEST,
            )
        except OSError as error:
            # Named as given, not as found; the first error other than "missing" is kept.
            last = type(error)(error.errno, error.strerror, name)
            if kept is None and error.errno not in (errno.ENOENT, errno.ENOTDIR):
                kept = last
    raise kept or last or FileNotFoundError(errno.ENOENT, os.strerror(errno.ENOENT), name)


def _pipe_above_stdio() -> tuple[int, int]:
    """A pipe whose ends are above 0-2: never one of the test's standard streams.

    A runner started with stdin, stdout or stderr closed gets the lowest numbers.
    """
    ends = list(os.pipe())
    try:
        for index, fd in enumerate(ends):
            if fd <= 2:
                ends[index] = fcntl.fcntl(fd, fcntl.F_DUPFD_CLOEXEC, 3)
                os.close(fd)
    except BaseException:
        for fd in set(ends):
            with contextlib.suppress(OSError):
                os.close(fd)
        raise
    return ends[0], ends[1]


@contextlib.contextmanager
def _inherited_fds_closed_on_exec() -> Iterator[None]:
    """Descriptors the runner inherited (a jobserver, a parent's pipes) stay out of the test.

    Marked close-on-exec for the spawn only, then put back: a program embedding the
    runner keeps its descriptors as they were.
    """
    marked: list[int] = []
    with contextlib.suppress(OSError):
        for name in os.listdir("/proc/self/fd"):
            fd = int(name)
            with contextlib.suppress(OSError):
                if fd > 2 and os.get_inheritable(fd):
                    os.set_inheritable(fd, False)
                    marked.append(fd)
    try:
        yield
    finally:
        for fd in marked:
            with contextlib.suppress(OSError):
                os.set_inheritable(fd, True)


@contextlib.contextmanager
def _child_statuses_kept() -> Iterator[None]:
    """SIGCHLD at its default while the test runs.

    Ignored (a launcher may pass that on), the kernel would reap the test by itself and
    its exit status would be lost.
    """
    try:
        previous = signal.signal(signal.SIGCHLD, signal.SIG_DFL)
    except ValueError:  # not the main thread: the embedding program decides
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGCHLD, previous)


def _from_terminal() -> bool:
    """Whether our group is a terminal's foreground group (so Ctrl-C reached all of it)."""
    for fd in (0, 1, 2):
        with contextlib.suppress(OSError):
            return os.tcgetpgrp(fd) == os.getpgrp()
    return False


def run(
    command: Sequence[str],
    env: Mapping[str, str],
    capture: OutputCapture,
    timeout: float | None = None,
    kill_grace: float = KILL_GRACE,
    on_start: Callable[[], None] | None = None,
    namespaces: bool = False,
) -> Outcome:
    """Run ``command`` to its end and its tree's end, streaming its output into ``capture``.

    ``on_start`` is called once the test exists, while this function's signal handlers
    are in place: the caller learns the test started with no window for a signal between.
    ``namespaces``: start it in user, network, mount and IPC namespaces of its own
    (``namespace``); its processes stay in the runner's PID namespace and tree, so they
    are ended exactly as in domain mode.
    """
    reaper.become_subreaper()
    start = time.monotonic()
    others = existing_children()
    # Handlers before the test exists: a signal arriving as it starts must reach it too.
    with _child_statuses_kept(), _Signals(others) as signals:
        try:
            test = _Test(command, env, namespaces)
        except OSError as error:
            return Outcome(returncode=None, duration=time.monotonic() - start, start_error=error)
        if on_start is not None:
            on_start()
        try:
            if signals.received is not None:
                # It came while the test was being started, before it could be passed on.
                tree.signal_tree(test.pid, signals.received)
            try:
                timed_out = _pump(test, capture, start, timeout, kill_grace, signals)
            except BaseException:
                # Whatever went wrong in the runner, the test must not outlive it unseen.
                tree.signal_tree(test.pid, signal.SIGKILL)
                test.wait()
                end_leftovers(0.0, others)
                raise
            returncode = test.wait()
            leftovers, survived = end_leftovers(kill_grace, others)
            _drain(test, capture)
            if test.status_lost:
                capture.note(
                    f"the test's exit status was lost (reaped elsewhere: SIGCHLD ignored?);"
                    f" counted as exit code {STATUS_LOST}"
                )
        finally:
            os.close(test.stdout)
    assert returncode is not None
    return Outcome(
        returncode=returncode,
        duration=time.monotonic() - start,
        timed_out=timed_out,
        received_signal=signals.received,
        leftovers=leftovers,
        survivors=survived,
    )


def _pump(
    test: _Test,
    capture: OutputCapture,
    start: float,
    timeout: float | None,
    kill_grace: float,
    signals: _Signals,
) -> bool:
    """Copy output until the test exited and its output is done; enforce the timeout.

    Output is done when the pipe closes, or when the test has exited and the pipe has
    gone quiet: a leftover background process holding the pipe must not hold the runner.
    A timeout (or a signal the runner passed on) gives the test ``kill_grace`` seconds
    after SIGTERM before SIGKILL.
    """
    fd = test.stdout
    os.set_blocking(fd, False)
    deadline = start + timeout if timeout is not None else None
    kill_at: float | None = None
    timed_out = False
    pipe_open = True
    drain_until: float | None = None
    poller = select.poll()
    poller.register(fd, select.POLLIN)
    while True:
        now = time.monotonic()
        if deadline is not None and not timed_out and now >= deadline:
            timed_out = True
            _signal(test, signal.SIGTERM)
            kill_at = now + kill_grace
        if signals.at is not None and kill_at is None and not timed_out:
            kill_at = signals.at + kill_grace
        if kill_at is not None and now >= kill_at:
            _signal(test, signal.SIGKILL)
        reaper.reap_orphans(keep=test.pid)
        exited = test.poll() is not None
        if exited and drain_until is None:
            drain_until = now + DRAIN_LIMIT_SECONDS
        if exited and (not pipe_open or now >= (drain_until or now)):
            # A leftover that keeps printing must not hold the runner: it is stopped
            # next, and what it wrote by then is drained.
            break
        wait = DRAIN_IDLE_SECONDS if exited else POLL_SECONDS
        for limit in (None if timed_out else deadline, kill_at):
            if limit is not None:
                wait = min(wait, max(0.0, limit - now))
        if not pipe_open:
            test.wait(wait)
            continue
        if not poller.poll(wait * 1000):
            if exited:
                break
            continue
        try:
            chunk = os.read(fd, CHUNK_BYTES)
        except BlockingIOError:
            continue
        if chunk:
            capture.feed(chunk)
        else:
            pipe_open = False
            poller.unregister(fd)
    return timed_out


def _signal(test: _Test, signum: int) -> None:
    """Signal the test and everything it started, while the test is still there."""
    if test.poll() is None:
        tree.signal_tree(test.pid, signum)


def existing_children() -> frozenset[tuple[int, int]]:
    """Processes in our tree before the test starts: a program embedding the runner's own.

    They are not the test's, and are never signalled. A runner started from a shell has
    no child yet: one system call, no /proc scan.
    """
    if not reaper.has_children():
        return frozenset()
    return frozenset(process.key for process in tree.descendants(os.getpid()))


def survivors() -> list[proc.Stat]:
    """Living processes in this runner's tree, scanned afresh: what even SIGKILL did not end.

    Only for a run that :func:`run` never returned from (an error in the runner); when it
    returns, :attr:`Outcome.survivors` is the list to use, which, unlike this scan, leaves
    out what an embedding program started itself. One system call when nothing is left.
    """
    reaper.reap_orphans()
    if not reaper.has_children():
        return []
    return tree.descendants(os.getpid())


class _Sweep:
    """The test's tree as the final sweep sees it, pass after pass, and all it has seen."""

    def __init__(self, others: frozenset[tuple[int, int]]) -> None:
        self.me = os.getpid()
        self.others = others
        #: Every process met, by (pid, start time): the leftovers to name.
        self.seen: dict[tuple[int, int], proc.Stat] = {}

    def look(self) -> tuple[list[proc.Stat], list[proc.Stat]]:
        """Reap, then the living tree and the processes in it not met before."""
        reaper.reap_orphans()
        if not reaper.has_children():
            # Every living descendant has a living child of ours above it (orphans are
            # re-parented to us, the subreaper): none at all means nothing is left.
            return [], []
        current = tree.descendants(self.me, skip=self.others)
        new = [process for process in current if process.key not in self.seen]
        for process in new:
            self.seen[process.key] = process
        return current, new

    def empty(self, current: list[proc.Stat]) -> bool:
        """Whether the tree is gone for sure, not only missing from one racy pass."""
        if current:
            return False
        reaper.reap_orphans()
        return not reaper.has_children() or not _children_left(self.me, self.others)

    def terminate(self, grace: float) -> list[proc.Stat]:
        """SIGTERM every process (SIGCONT too, so a stopped one can act on it), for ``grace``.

        Processes forked meanwhile get the same. Returns what is still alive after it.
        """
        current, new = self.look()
        deadline = time.monotonic() + grace
        while True:
            tree.signal_all(new, signal.SIGTERM)
            tree.signal_all(new, signal.SIGCONT)
            remaining = deadline - time.monotonic()
            if self.empty(current) or remaining <= 0:
                return current
            time.sleep(min(TERM_POLL_SECONDS, remaining))
            current, new = self.look()

    def freeze(self) -> None:
        """SIGSTOP the tree until a pass finds none of it running.

        A stopped process cannot fork, so the SIGKILL passes that follow are no race
        against children born meanwhile. Processes we may not signal, and ones that do
        not stop within :data:`FREEZE_LIMIT_SECONDS`, are left to those passes.
        """
        refused: set[tuple[int, int]] = set()
        give_up = time.monotonic() + FREEZE_LIMIT_SECONDS
        delay = 0.001
        while True:
            current, _new = self.look()
            running = [
                process
                for process in current
                if process.state not in proc.STOPPED_STATES and process.key not in refused
            ]
            if not running or time.monotonic() >= give_up:
                return
            refused.update(process.key for process in tree.signal_all(running, signal.SIGSTOP))
            time.sleep(delay)
            delay = min(delay * 2, TERM_POLL_SECONDS)

    def kill(self) -> list[proc.Stat]:
        """SIGKILL the tree, pass after pass, reaping as it goes, until it is empty.

        Ends when :data:`KILL_STALL_SECONDS` pass without the tree shrinking: what is
        left then cannot be killed by us. Returns it.
        """
        fewest: int | None = None
        progress_at = time.monotonic()
        delay = 0.001
        while True:
            current, _new = self.look()
            if self.empty(current):
                return []
            if fewest is None or len(current) < fewest:
                fewest, progress_at = len(current), time.monotonic()
            elif time.monotonic() - progress_at >= KILL_STALL_SECONDS:
                return current
            tree.signal_all(current, signal.SIGKILL)
            time.sleep(delay)
            delay = min(delay * 2, TERM_POLL_SECONDS)


def _children_left(me: int, others: frozenset[tuple[int, int]]) -> bool:
    """Whether a child of ours, other than the embedding program's, still exists."""
    return any(process.ppid == me and process.key not in others for process in tree.processes())


def end_leftovers(
    grace: float, others: frozenset[tuple[int, int]] = frozenset()
) -> tuple[tuple[str, ...], tuple[proc.Stat, ...]]:
    """End what is left of the test's tree; name what had to be ended, and what survived.

    SIGTERM first, and ``grace`` seconds to exit cleanly (a well-behaved daemon gets its
    chance); then freeze and SIGKILL until the tree is empty, or nothing more dies.
    """
    sweep = _Sweep(others)
    remaining = sweep.terminate(grace)
    if not sweep.seen:
        return (), ()
    left: list[proc.Stat] = []
    if not sweep.empty(remaining):
        sweep.freeze()
        left = sweep.kill()
    reaper.reap_orphans()
    alive = {process.key for process in left}
    ended = [process for key, process in sweep.seen.items() if key not in alive]
    named = [process.describe() for process in ended[:NAMED_LIMIT]]
    if len(ended) > NAMED_LIMIT:
        named.append(f"... and {len(ended) - NAMED_LIMIT} more")
    return tuple(named), tuple(left)


def _drain(test: _Test, capture: OutputCapture) -> None:
    """Take what the stopped leftovers wrote, without waiting."""
    with contextlib.suppress(OSError, ValueError):
        while chunk := os.read(test.stdout, CHUNK_BYTES):
            capture.feed(chunk)

"""Starting the test's main process and waiting for its exit status.

Apart from the supervisor's run loop because how a process is started (its PATH, its
descriptors, its signal dispositions, a pipe above stdio) and how its status is kept
from being lost are details the loop never needs to read.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import signal
import time
from collections.abc import Iterator, Mapping, Sequence

from ros_isolated_test.process import fork_exec

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from ros_isolated_test.process.fork_exec import Spawner

#: The exit code a test gets when its status was reaped by someone else: a failure.
STATUS_LOST = 255
#: Reset to their default in the test: Python ignores SIGPIPE, and so would the test.
_DEFAULT_IN_TEST = (signal.SIGPIPE, signal.SIGXFSZ)


class Test:
    """The test's main process and the read end of its output pipe.

    Started by a fork and an exec (``fork_exec``), or ``posix_spawn``, not ``subprocess``:
    the runner does not pay for importing subprocess (and threading, selectors) on every
    test. It is started as Popen would start it: found on the test's own PATH, with
    SIGPIPE at its default, without the runner's other descriptors; and it dies with the
    runner.
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
    interpreter is missing (ENOENT) gives way to the next match. The test is tethered to
    the runner (``fork_exec``: it dies when the runner dies), which posix_spawn cannot
    do; only a runner that runs threads uses posix_spawn. With ``namespaces`` the test
    starts in namespaces of its own (``namespace.spawn``), with the same descriptors and
    signals: both are a ``fork_exec.Spawner``, one contract.
    """
    name = command[0]
    if os.sep in name:
        candidates = [name]
    else:
        folders = os.get_exec_path(dict(env))
        candidates = [
            path for folder in folders if os.path.exists(path := os.path.join(folder, name))
        ]
    tethered: Spawner | None = None
    if namespaces:
        from ros_isolated_test.process import namespace

        tethered = namespace.spawn
    elif fork_exec.threads() == 1:
        tethered = fork_exec.start
    if tethered is not None:
        return tethered(name, candidates, command, env, output_fd, _DEFAULT_IN_TEST)
    # Other threads run (a program embedding the runner): a fork could deadlock the child.
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
def child_statuses_kept() -> Iterator[None]:
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

"""Starting the test by fork and exec, so that it dies with its runner.

posix_spawn cannot run a step between the fork and the exec; this does, for two steps:
``PR_SET_PDEATHSIG`` (the kernel sends the test SIGKILL the moment the runner dies,
whatever kills it), and, in namespace mode, entering the test's namespaces (``namespace``
forks its child here and adds its own steps before the exec).

Why the runner's death must reach the test: a runner SIGKILLed on its own (a user's
``kill -9``, an out-of-memory kill) orphans the test, which would run on unsupervised on
its domain ID, writing files nobody reads. The signal is set in the child before the
exec, and then the child checks that its parent is still the runner: one that died
before the signal was set would never send it.

The test's own children get no such signal (the kernel clears it on fork): a kill of
the runner's whole group (ctest's TIMEOUT kills the tree) ends them; after a kill of the
runner alone they live on, under the next subreaper, and their ID stays blocked by the
escaped-process scan (docs/reuse.md). A fork while other threads run could deadlock the
child, so a process that runs threads (a program embedding the runner) starts the test
with posix_spawn, without the signal (:func:`threads`).
"""

from __future__ import annotations

import contextlib
import errno
import os
import signal

from ros_isolated_test import libc

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from collections.abc import Callable, Iterable, Mapping, Sequence
    from typing import NoReturn, Protocol

    #: A signal mask, as pthread_sigmask gives it.
    Mask = set[int | signal.Signals]

    class Spawner(Protocol):
        """How a test is started tethered to its runner: :func:`start`, ``namespace.spawn``.

        One contract, so ``spawn`` may pick either: like posix_spawn as the supervisor
        calls it, ``output_fd`` becomes stdout and stderr, ``defaults`` get their default
        action, each of ``candidates`` is tried in turn (as execvp would), and an exec
        error is raised as that OSError, named ``name``; the signals the runner passes on
        (:data:`HELD_BACK`) wait in the child until it execs, then act as they would on
        the test. Returns the test's PID, the runner's child; the test gets
        :data:`PARENT_DEATH_SIGNAL` when the runner dies. Only typed (no typing import on
        a test's path).
        """

        def __call__(
            self,
            name: str,
            candidates: Sequence[str],
            argv: Sequence[str],
            env: Mapping[str, str],
            output_fd: int,
            defaults: Iterable[int],
        ) -> int: ...


_PR_SET_PDEATHSIG = 1
#: What the test gets when its runner dies: no handler can keep it alive, as ctest's
#: TIMEOUT gives none either.
PARENT_DEATH_SIGNAL = signal.SIGKILL
#: Held back in a forked child until it execs (or exits): the signals the runner passes
#: on, whose Python handlers the child inherits and must never run.
HELD_BACK = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
#: How a child that found its runner already dead exits (nobody reads it).
ORPHANED = 125


def prctl() -> Callable[..., int]:
    """The C library's prctl, bound before a fork: the child only calls it."""
    function = libc.prctl()
    if function is None:  # no Linux C library lacks it
        raise OSError(errno.ENOSYS, "the C library has no prctl")
    return function


def threads() -> int:
    """How many threads this process runs (1 where /proc cannot say)."""
    try:
        with open("/proc/self/status", encoding="ascii", errors="replace") as handle:
            for line in handle:
                if line.startswith("Threads:"):
                    return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    return 1


class Exec:
    """What the child execs: ``execve`` on each candidate, as execvp would.

    ``parent``: the runner's PID, whose death kills the test (``PR_SET_PDEATHSIG``).
    """

    __slots__ = ("argv", "candidates", "defaults", "env", "mask", "output_fd", "parent", "prctl")

    def __init__(
        self,
        candidates: Sequence[str],
        argv: Sequence[str],
        env: Mapping[str, str],
        output_fd: int,
        defaults: Iterable[int],
    ) -> None:
        self.candidates = list(candidates)
        self.argv = list(argv)
        self.env = dict(env)
        self.output_fd = output_fd
        self.defaults = tuple(defaults)
        self.mask: Mask = set()
        self.parent = os.getpid()
        self.prctl = prctl()

    def run(self) -> NoReturn:
        """Never returns: execs the test, or raises the error posix_spawn would have.

        Tethered first: set after any change of credentials (the namespaces' user
        namespace), which would clear it; checked after, as the runner may be gone.
        """
        self.prctl(_PR_SET_PDEATHSIG, PARENT_DEATH_SIGNAL, 0)
        if os.getppid() != self.parent:
            os._exit(ORPHANED)  # the runner died before it could tell us: never run
        os.dup2(self.output_fd, 1)
        os.dup2(self.output_fd, 2)
        for signum in self.defaults:
            signal.signal(signum, signal.SIG_DFL)
        # Unblocked only now, with default actions: a signal the runner passed on while
        # the child was being set up ends it as it would end the test.
        signal.pthread_sigmask(signal.SIG_SETMASK, self.mask)
        kept: OSError | None = None
        last: OSError | None = None
        for path in self.candidates:
            try:
                os.execve(path, self.argv, self.env)
            except OSError as error:
                last = error
                if kept is None and error.errno not in (errno.ENOENT, errno.ENOTDIR):
                    kept = error
        raise kept or last or FileNotFoundError(errno.ENOENT, os.strerror(errno.ENOENT))


def plan_for(
    candidates: Sequence[str],
    argv: Sequence[str],
    env: Mapping[str, str],
    output_fd: int,
    defaults: Iterable[int],
) -> Exec:
    """The child's exec for a :class:`Spawner`'s arguments: :data:`HELD_BACK` at default too."""
    return Exec(candidates, argv, env, output_fd, (*defaults, *HELD_BACK))


def report(fd: int, error: BaseException) -> None:
    """A failed step, as the child tells it: ``<step> <errno>``."""
    step = getattr(error, "step", "exec")
    number = getattr(error, "errno", None) or errno.EPERM
    with contextlib.suppress(OSError):
        os.write(fd, f"{step} {number}\n".encode("ascii"))


def read_all(fd: int) -> bytes:
    data = b""
    while chunk := os.read(fd, 4096):
        data += chunk
    return data


def reap(pid: int) -> int:
    """The child's wait status, once it has ended (EINTR retried by os.waitpid)."""
    try:
        return os.waitpid(pid, 0)[1]
    except ChildProcessError:
        return 0  # reaped by an embedding program's handler: its report says enough


def fork(child: Callable[[Mask], NoReturn]) -> int:
    """Fork with :data:`HELD_BACK` blocked; the child runs ``child(mask)``, never returns.

    ``mask`` is the signal mask to restore before the exec.
    """
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, HELD_BACK)
    try:
        pid = os.fork()
    except BaseException:
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        raise
    if pid == 0:  # pragma: no cover (the child: never returns)
        try:
            child(mask)
        finally:
            os._exit(127)
    signal.pthread_sigmask(signal.SIG_SETMASK, mask)
    return pid


def start(
    name: str,
    candidates: Sequence[str],
    argv: Sequence[str],
    env: Mapping[str, str],
    output_fd: int,
    defaults: Iterable[int],
) -> int:
    """Start the test tethered to this process: the plain :class:`Spawner`."""
    plan = plan_for(candidates, argv, env, output_fd, defaults)
    report_r, report_w = os.pipe()  # close-on-exec: an exec that works closes it

    def child(mask: Mask) -> NoReturn:
        try:
            os.close(report_r)
            plan.mask = mask
            plan.run()
        except BaseException as error:  # never back into the runner's code
            report(report_w, error)
        os._exit(127)

    try:
        try:
            pid = fork(child)
        finally:
            os.close(report_w)
        said = read_all(report_r)
    finally:
        os.close(report_r)
    if not said:
        return pid
    reap(pid)
    words = said.split()
    try:
        number = int(words[1])
    except (IndexError, ValueError):
        number = errno.EIO
    raise OSError(number, os.strerror(number), name)


if TYPE_CHECKING:
    _START: Spawner = start  # checked against the one contract

__all__ = ["HELD_BACK", "PARENT_DEATH_SIGNAL", "Exec", "fork", "plan_for", "start", "threads"]

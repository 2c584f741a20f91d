"""SIGTERM and SIGHUP end a pytest session as Ctrl-C does, so its leftovers are still ended.

Without this pytest dies at once on SIGTERM (ctest's or colcon's timeout, a CI cancel):
no unconfigure, so what the tests left running is never ended (a plain fork even inherits
the lock) and the ID stays held. Once the release began, a signal is only noted: a second
Ctrl-C must not cut the sweep short. With xdist the workers hold the IDs: the controller
passes each signal on to them (else they learn of its end only from execnet, 5 s later,
and are killed mid-sweep 10 s later), then waits for them. A test that catches the
interrupt does not keep the session going: the next test is not started. Apart from
holding.py, which decides and reserves: this knows signals, processes and xdist's
workers, nothing of IDs.
"""

from __future__ import annotations

import contextlib
import os
import sys
from typing import Any


class Interrupts:
    """How a signal ends this pytest process, and the xdist workers it passes signals to."""

    def __init__(self) -> None:
        #: The release began: a signal now must not cut the sweep short.
        self.closing = False
        #: A signal ended the session (an xdist process: later ones only noted).
        self.interrupted = False
        #: The xdist controller: each local worker (its WorkerController) and PID.
        self.workers: list[tuple[Any, int]] = []
        #: The xdist controller, interrupted: a second signal stops its wait for the workers.
        self.hurry = False

    def catch(self, stack: contextlib.ExitStack, once: bool = False) -> None:
        """SIGINT, SIGTERM, SIGHUP raise KeyboardInterrupt until ``stack`` closes.

        In an xdist process a signal may come twice (from the process group and passed
        on): with ``once`` only the first interrupts. Outside the main thread (an
        embedding program) its own handlers stay.
        """
        from ros_isolated_test.process import signals

        def stop(signum: int, _frame: object) -> None:
            passed_on = self._pass_on(signum)
            if self.closing:
                note(f"signal {signum} ignored: ending what the tests left running first")
            elif once and self.interrupted:
                if passed_on:
                    self.hurry = True  # the controller: no longer waits for its workers
                what = "passed on to the xdist workers" if passed_on else "ignored"
                note(f"signal {signum} {what}: the session is already ending")
            else:
                self.interrupted = True
                raise KeyboardInterrupt(f"signal {signum}")

        previous = signals.set_handlers(stop)
        stack.callback(signals.restore_handlers, previous)

    def stop_if_interrupted(self) -> None:
        """A signal a test swallowed still ends the session: no further test runs (exit 2).

        A test may catch the KeyboardInterrupt; launch_pytest's wait for its launch turns
        it into an AttributeError.
        """
        if self.interrupted and not self.closing:
            raise KeyboardInterrupt("a signal ended the session; a test had caught it")

    def add_worker(self, node: Any) -> None:
        """The xdist controller: a local worker's PID, to pass a signal on to it."""
        spec = node.gateway.spec
        if not spec.popen or spec.via:
            return  # a process of another host: nothing to pass on
        try:
            pid = int(node.gateway._rinfo().pid)  # asked by xdist just before: no round trip
        except Exception:  # an execnet without it: the worker learns of the end from execnet
            return
        self.workers.append((node, pid))

    def _pass_on(self, signum: int) -> bool:
        """The xdist controller: ``signum`` to each local worker still running; any sent?"""
        from ros_isolated_test.process import proc

        sent = False
        for _node, pid in self.workers:
            stat = proc.read_stat(pid)
            # Still our child, so its PID names no later process (it is not reaped yet).
            if stat is None or not stat.alive or stat.ppid != os.getpid():
                continue
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signum)
                sent = True
        return sent

    def wait_for_workers(self) -> None:
        """The interrupted xdist controller: until each worker has ended its leftovers.

        That is, until its pytest ended (its channel closed), its ID released; a second
        signal stops the wait. xdist's teardown, which follows, kills a worker still
        running 10 s after it began. Each is also told to run no further test, as xdist
        does when it stops (a test may have swallowed the interrupt).
        """
        for node, _pid in self.workers:
            with contextlib.suppress(Exception):  # gone already: nothing to tell
                node.shutdown()
        for node, _pid in self.workers:
            channel = getattr(node, "channel", None)
            while channel is not None and not self.hurry and not _closed(channel):
                pass


def _closed(channel: Any) -> bool:
    """An execnet channel closed within 0.1 s (a signal's handler runs meanwhile)."""
    try:
        channel.waitclose(0.1)
    except channel.TimeoutError:
        return False
    except Exception:  # closed with the worker's error, which xdist reports
        return True
    return True


def note(line: str) -> None:
    """Said on stderr, which pytest does not capture here: waiting, processes ended."""
    print(f"ros-isolated-test: {line}", file=sys.stderr, flush=True)

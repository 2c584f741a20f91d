"""``fork_exec``: the test dies with its runner, whatever kills the runner.

A runner SIGKILLed alone (no handler runs) must not leave its test running on,
unsupervised: the test is started by a fork and an exec with ``PR_SET_PDEATHSIG`` set
between them, so the kernel kills it the moment the runner dies. A child whose runner
died before the signal was set never runs the test. The control: a runner that runs
threads starts the test with posix_spawn, and that test outlives it. Real processes: a
runner of its own (``spawn.Test`` in a Python child), killed with SIGKILL; what happens
after is read by events (a pidfd, a signal the orphan answers), never by a clock.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.orphans import ANSWERS_USR1, lives_on, ready, wait_ended, watch
from helpers.processes import DEADLINE, Children

from ros_isolated_test.process import fork_exec

#: A runner of its own: starts the test (argv: its answer file) as the supervisor does,
#: prints the test's PID and waits to be killed. With "threads", a second thread runs;
#: with "namespaces", the test starts in namespaces of its own.
RUNNER = """
import os, sys, threading
from ros_isolated_test.process import spawn
if sys.argv[1] == "threads":
    threading.Thread(target=sys.stdin.read, daemon=True).start()
namespaces = sys.argv[1] == "namespaces"
test = spawn.Test(["sh", "-c", sys.argv[2], sys.argv[3]], dict(os.environ), namespaces)
print(test.pid, flush=True)
sys.stdin.read()
"""


@pytest.mark.parametrize(
    "mode", ["alone", pytest.param("namespaces", marks=capabilities.UNSHARE.mark), "threads"]
)
def test_a_test_dies_with_its_runner_killed_alone(
    mode: str, children: Children, tmp_path: Path
) -> None:
    """SIGKILL to the runner only: its tethered test ends, in namespaces of its own too;
    posix_spawn's (a runner running threads) lives on: the control."""
    answer = tmp_path / "answer"
    runner = children.python(RUNNER, mode, ANSWERS_USR1, answer)
    pid = int(children.first_line(runner))
    pidfd = watch(pid)
    ready(answer)
    runner.kill()
    runner.wait(timeout=DEADLINE)
    if mode != "threads":
        wait_ended(pidfd, pid, "the test of a runner killed alone")
        assert not answer.exists()
    else:
        os.close(pidfd)
        lives_on(pid, answer)  # the control: untethered, it answers after its runner died


#: A "runner" forks a child that runs the tethered exec (whose command writes the marker,
#: argv[1]) at once, or, as "orphan", only once the runner has died. The runner prints the
#: child's PID and goes on when its stdin closes: it exits, or reaps the child and says how
#: it ended.
ORPHANED_FIRST = """
import os, sys, time
from ros_isolated_test.process import fork_exec
marker, case = sys.argv[1], sys.argv[2]
plan = fork_exec.Exec(["/bin/sh"], ["sh", "-c", ': > "$0"', marker], dict(os.environ), 2, ())
died_r, died_w = os.pipe()
pid = os.fork()
if pid == 0:
    os.close(died_w)
    if case == "orphan":
        os.read(died_r, 1)  # end of file: the runner is dying; then orphaned, once it is dead
        while os.getppid() == plan.parent:
            time.sleep(0.001)
    plan.run()
print(pid, flush=True)
sys.stdin.read()
if case != "orphan":
    print(os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]), flush=True)
"""


@pytest.mark.parametrize("case", ["orphan", "runner alive"])
def test_a_child_whose_runner_died_before_the_tether_never_runs_the_test(
    case: str, children: Children, tmp_path: Path
) -> None:
    """The check after PR_SET_PDEATHSIG: a runner dead already would never send it.

    The control: with its runner alive, the same plan runs the command.
    """
    marker = tmp_path / "ran"
    runner = children.python(ORPHANED_FIRST, marker, case)
    pid = int(children.first_line(runner))
    pidfd = watch(pid)
    assert children.finish(runner) == 0
    wait_ended(pidfd, pid, "the forked child")
    if case == "orphan":
        assert not marker.exists(), "the test ran though its runner was dead"
    else:
        assert runner.stdout is not None
        assert runner.stdout.read().strip() == "0"
        assert marker.exists()


def test_an_exec_error_is_raised_as_posix_spawn_raises_it(tmp_path: Path) -> None:
    script = tmp_path / "not-executable"
    script.write_text("#!/bin/sh\n")
    with pytest.raises(PermissionError) as raised:
        fork_exec.start("named", [str(script)], ["named"], dict(os.environ), 1, ())
    assert raised.value.filename == "named"

"""The signals that end a run reach the test's whole tree, and the runner's handlers go back.

``set_handlers``/``restore_handlers`` put the runner's handler on SIGINT, SIGTERM and
SIGHUP and then exactly what was there before (the pytest plugin and the session use
them around their own work; an embedding program keeps its handlers). ``Signals``, in
place while a test runs, passes each signal on to every process of the test's tree,
not to what an embedding program had started before, and remembers the first. Through
the runner: a signal to it reaches the test and is reported, Ctrl-C to the whole group
leaves nothing, and as PID 1 of a container (which ignores a signal it has no handler
for) SIGTERM still ends the run with its test. Real signals, real processes.
"""

from __future__ import annotations

import os
import signal
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from types import FrameType

import pytest
from helpers.commands import CLI
from helpers.process_tree import (
    Launcher,
    alive,
    assert_interrupted_by,
    assert_no_survivors,
    children_of,
    describe,
    finish,
    in_child,
    in_pid_namespace,
    start_trapping_test,
    wait_for,
    wait_for_pid,
)

from ros_isolated_test.process import signals
from ros_isolated_test.process.signals import FORWARDED_SIGNALS, set_handlers

# --- set_handlers and restore_handlers --------------------------------------------------


Handler = Callable[[int, FrameType | None], object] | signal.Handlers


@pytest.fixture
def own_handlers() -> Iterator[dict[int, Handler]]:
    """A handler of this test's own on each forwarded signal (one ignored); put back after."""

    def first(_signum: int, _frame: FrameType | None) -> None:
        pass

    def second(_signum: int, _frame: FrameType | None) -> None:
        pass

    handlers: tuple[Handler, ...] = (first, second, signal.SIG_IGN)
    mine = {
        int(signum): handler for signum, handler in zip(FORWARDED_SIGNALS, handlers, strict=True)
    }
    before = {signum: signal.getsignal(signum) for signum in FORWARDED_SIGNALS}
    try:
        for signum, handler in mine.items():
            signal.signal(signum, handler)
        yield dict(mine)
    finally:
        for signum, previous in before.items():
            signal.signal(signum, previous)


def test_set_handlers_then_restore_handlers_put_back_exactly_the_previous_ones(
    own_handlers: dict[int, Handler],
) -> None:
    caught: list[int] = []

    def runner(signum: int, _frame: FrameType | None) -> None:
        caught.append(signum)

    previous = set_handlers(runner)
    try:
        assert previous == own_handlers, "the handlers replaced are returned, each as it was"
        assert all(signal.getsignal(signum) is runner for signum in FORWARDED_SIGNALS)
        os.kill(os.getpid(), signal.SIGHUP)  # ignored before: now the runner's handler runs
        assert caught == [signal.SIGHUP]
    finally:
        signals.restore_handlers(previous)
    assert {signum: signal.getsignal(signum) for signum in FORWARDED_SIGNALS} == own_handlers


def test_outside_the_main_thread_no_handler_is_set_and_the_programs_stay(
    own_handlers: dict[int, Handler],
) -> None:
    """An embedding program's thread: nothing set, nothing to restore, its handlers kept."""
    returned: list[dict[int, object]] = []

    def in_thread() -> None:
        returned.append(dict(set_handlers(lambda _signum, _frame: None)))

    thread = threading.Thread(target=in_thread)
    thread.start()
    thread.join()
    assert returned == [{}]
    assert {signum: signal.getsignal(signum) for signum in FORWARDED_SIGNALS} == own_handlers


# --- Signals: a real SIGTERM passed on through a test's tree ----------------------------

#: A runner-to-be with a child of its own from before (``sleep TAG``), then a test whose
#: shell and its child each trap SIGTERM into a file of FOLDER. SIGTERM to the runner
#: itself, under ``Signals``. argv: folder, tag. Prints what was received and who heard it.
FORWARD = """
import json, os, pathlib, signal, subprocess, sys, time
from ros_isolated_test.process import signals, sweep
folder, tag = pathlib.Path(sys.argv[1]), sys.argv[2]
own = subprocess.Popen(["sleep", tag])
others = sweep.existing_children()
inner = "trap 'echo > grandchild; exit 7' TERM; echo > ready; while :; do sleep 0.1; done"
outer = f"trap 'echo > child; exit 7' TERM; sh -c \\"{inner}\\" & wait"
test = subprocess.Popen(["sh", "-c", outer], cwd=folder)
while not (folder / "ready").exists():
    time.sleep(0.01)
with signals.Signals(others) as forwarding:
    os.kill(os.getpid(), signal.SIGTERM)
    code = test.wait()
    while not (folder / "grandchild").exists():
        time.sleep(0.01)
after = signal.getsignal(signal.SIGTERM)
found = {
    "received": forwarding.received, "at": forwarding.at is not None, "code": code,
    "heard": sorted(path.name for path in folder.iterdir()), "own_alive": own.poll() is None,
    "restored": after == signal.SIG_DFL,
}
own.kill()
own.wait()
print(json.dumps(found))
"""


def test_signals_passes_a_real_sigterm_on_to_the_tests_tree_and_remembers_it(
    tmp_path: Path, tags: Callable[[], str]
) -> None:
    found = in_child(FORWARD, tmp_path, tags())
    assert found["heard"] == ["child", "grandchild", "ready"], found
    assert found["code"] == 7, "the test ended on the SIGTERM it trapped"
    assert (found["received"], found["at"]) == (signal.SIGTERM, True), found
    # The control: the embedding program's own child was in the tree too, and not signalled.
    assert found["own_alive"], found
    assert found["restored"], "the handler before Signals is back"


# --- through the runner -----------------------------------------------------------------


@pytest.mark.parametrize(
    "signum", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP], ids=lambda signum: signum.name
)
def test_signal_to_the_runner_reaches_the_test_and_is_reported(
    signum: signal.Signals, tree_env: dict[str, str], launcher: Launcher, tag: str, tmp_path: Path
) -> None:
    result = tmp_path / "result.xml"
    args = [CLI, "run", "--junit-xml", str(result), "--", "sh", "-c"]
    runner, log = start_trapping_test(launcher, args, tree_env, tmp_path)
    os.kill(runner.pid, signum)
    code = finish(runner, 15, log)

    received = tmp_path / "received"
    assert received.exists(), f"the test never got {signum.name}:\n{log.read_text()}"
    assert received.read_text().strip() == signum.name[3:], log.read_text()
    assert code == 128 + signum, log.read_text()
    assert_interrupted_by(result, signum)
    assert_no_survivors(tag)


def test_sigint_to_the_whole_process_group_leaves_nothing(
    tree_env: dict[str, str], launcher: Launcher, tag: str, tmp_path: Path
) -> None:
    """Ctrl-C under colcon: the group gets SIGINT, background jobs of sh ignore it."""
    script = (
        "sleep 60 & echo $! > background.pid; setsid sleep 60 & echo $! > session.pid; "
        "echo ready > ready; wait"
    )
    result = tmp_path / "result.xml"
    args = [CLI, "run", "--kill-grace", "2", "--junit-xml", str(result), "--", "sh", "-c", script]
    log = tmp_path / "runner.log"
    runner = launcher.start(args, tree_env, log, cwd=tmp_path, start_new_session=True)
    wait_for((tmp_path / "ready").exists, 30, "the test to start", runner, log)
    leftovers = [wait_for_pid(tmp_path / "background.pid"), wait_for_pid(tmp_path / "session.pid")]
    os.killpg(runner.pid, signal.SIGINT)
    code = finish(runner, 20, log)

    assert code == 128 + signal.SIGINT, log.read_text()
    assert not any(alive(pid) for pid in leftovers), describe(leftovers)
    assert_no_survivors(tag)
    assert_interrupted_by(result, signal.SIGINT)


@pytest.mark.usefixtures("pid_namespaces")
def test_pid_1_passes_sigterm_on_and_ends_within_the_grace(
    tree_env: dict[str, str], launcher: Launcher, tag: str, tmp_path: Path
) -> None:
    # Far longer than the test takes to end on SIGTERM: a PID 1 that sat out the grace
    # (instead of ending with its test) would still run when finish() gives up.
    grace = 300.0
    result = tmp_path / "result.xml"
    args = in_pid_namespace(
        "run", "--kill-grace", f"{grace:g}", "--junit-xml", str(result), "--", "sh", "-c"
    )
    unshare, log = start_trapping_test(launcher, args, tree_env, tmp_path)
    (runner,) = children_of(unshare.pid)
    assert alive(runner)
    os.kill(runner, signal.SIGTERM)
    code = finish(unshare, 60, log)

    assert (tmp_path / "received").read_text().strip() == "TERM", log.read_text()
    assert code == 128 + signal.SIGTERM, log.read_text()
    assert_no_survivors(tag)
    assert_interrupted_by(result, signal.SIGTERM)

"""``interruption``: a signal to the runner means what its moment makes it mean.

Before the test starts (a runner queued for an ID; PID 1, which has no default action)
SIGINT, SIGTERM or SIGHUP ends the run cleanly, as :class:`Interrupted`, so the result
says the test never ran. After it started, and while the final word is written (ctest's
SIGTERM, a Ctrl-C), it is only noted: the run's outcome stands and the result is never
lost. Real signals to this process, each test with a stand-in handler of its own in
place (so a signal the runner failed to take is seen, never ends the suite), then real
RUNNER processes signalled while they write a big result.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from types import FrameType

import pytest
from helpers.commands import HUNG, ament
from helpers.results import load_result

from ros_isolated_test.runner.interruption import Guard, Interrupted, interruptible
from ros_isolated_test.xunit.result_file import ResultFile

SIGNALS = [signal.SIGTERM, signal.SIGINT, signal.SIGHUP]


class StandIn:
    """This process's own handler for the runner's signals, as an embedding program has."""

    def __init__(self) -> None:
        self.caught: list[int] = []

    def __call__(self, signum: int, _frame: FrameType | None) -> None:
        self.caught.append(signum)

    def in_place(self) -> bool:
        return all(signal.getsignal(signum) is self for signum in SIGNALS)


@pytest.fixture
def stand_in() -> Iterator[StandIn]:
    handler = StandIn()
    previous = {signum: signal.signal(signum, handler) for signum in SIGNALS}
    try:
        yield handler
    finally:
        for signum, before in previous.items():
            signal.signal(signum, before)


# --- in process: before and after the test starts --------------------------------------------


@pytest.mark.parametrize("signum", SIGNALS, ids=[s.name for s in SIGNALS])
def test_a_signal_before_the_test_starts_ends_the_run_as_never_run(
    stand_in: StandIn, signum: signal.Signals
) -> None:
    guard = Guard()
    with pytest.raises(Interrupted) as interrupted, interruptible(guard):
        assert not stand_in.in_place()  # the runner's handlers, for the block
        signal.raise_signal(signum)
        pytest.fail("the run went on after the signal")
    assert interrupted.value.signum == signum
    assert guard.concluding and guard.late is None  # the final word is being written now
    assert stand_in.caught == [] and stand_in.in_place()  # given back as they were


def test_a_signal_after_the_test_started_is_only_noted_and_the_first_stands(
    stand_in: StandIn, tmp_path: Path
) -> None:
    guard = Guard()
    result = ResultFile(tmp_path / "t.xml", ("t",), "pkg", "t")
    with interruptible(guard):
        guard.start()
        signal.raise_signal(signal.SIGTERM)
        signal.raise_signal(signal.SIGINT)
        assert guard.late == signal.SIGTERM
        guard.result = result  # the test ended: where a late signal is noted
        guard.note_late()
        signal.raise_signal(signal.SIGHUP)
    assert result.properties["signal_after_test"] == "SIGTERM"
    assert stand_in.caught == [] and stand_in.in_place()


def test_a_signal_while_the_final_word_is_written_is_noted_in_it(
    stand_in: StandIn, tmp_path: Path
) -> None:
    """The test never ran, and its "not run" result is being written: noted, not raised."""
    guard = Guard()
    guard.result = ResultFile(tmp_path / "t.xml", ("t",), "pkg", "t")
    with pytest.raises(Interrupted), interruptible(guard):
        signal.raise_signal(signal.SIGINT)
    assert guard.concluding
    with interruptible(guard):
        signal.raise_signal(signal.SIGTERM)  # no Interrupted raised this time
    assert guard.late == signal.SIGTERM
    assert guard.result.properties["signal_after_test"] == "SIGTERM"


def test_a_rerun_that_is_about_to_start_ends_on_a_signal_that_came_before() -> None:
    late = Guard()
    late.start()
    late.late = signal.SIGTERM
    with pytest.raises(Interrupted) as interrupted:
        late.next_attempt()
    assert interrupted.value.signum == signal.SIGTERM
    # The control: no signal came; the rerun starts as a test not started yet.
    calm = Guard()
    calm.start()
    calm.next_attempt()
    assert not calm.test_started and not calm.concluding


def test_outside_the_main_thread_the_programs_own_handlers_stay(stand_in: StandIn) -> None:
    """An embedding program running the runner in a thread keeps its handlers."""
    seen: list[object] = []

    def in_a_thread() -> None:
        with interruptible(Guard()):
            seen.append(signal.getsignal(signal.SIGTERM))

    thread = threading.Thread(target=in_a_thread)
    thread.start()
    thread.join()
    assert seen == [stand_in]
    # The control: in the main thread the runner's handler takes its place for the block.
    with interruptible(Guard()):
        assert signal.getsignal(signal.SIGTERM) is not stand_in
    assert stand_in.in_place()


# --- real runners: a signal after the test ended, while its result is being written ----------


#: Writes a result file of ``$2`` passing cases at ``$1``: big enough that normalising it
#: takes a while, so a signal can arrive in the middle.
BIG_RESULT = """
import sys
count = int(sys.argv[2])
with open(sys.argv[1], "w") as out:
    out.write('<?xml version="1.0"?>\\n<testsuite name="big" tests="%d">\\n' % count)
    for index in range(count):
        out.write('<testcase classname="c" name="t%d" time="0.001"/>\\n' % index)
    out.write("</testsuite>\\n")
"""


def _signalled_while_concluding(
    runner_script: str, env: dict[str, str], tmp_path: Path, signum: int
) -> tuple[subprocess.Popen[bytes], Path]:
    """A runner whose test wrote a big result, signalled once it starts adopting that file."""
    result = tmp_path / "pkg" / "big.xml"
    original = result.with_name(result.name + ".orig")
    script = tmp_path / "big.py"
    script.write_text(BIG_RESULT)
    argv = [sys.executable, "-u", runner_script, str(result), "--package-name", "pkg"]
    argv += ["--command", sys.executable, str(script), str(result), "100000"]
    runner = subprocess.Popen(
        argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, cwd=tmp_path
    )
    try:
        while not os.path.lexists(original):
            assert runner.poll() is None, "the runner ended before it adopted the result"
            time.sleep(0.001)
        os.kill(runner.pid, signum)
        runner.wait(timeout=HUNG)
    finally:
        if runner.poll() is None:
            runner.kill()
            runner.wait()
    return runner, result


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT, signal.SIGHUP])
def test_a_signal_while_the_result_is_written_is_noted_and_the_result_is_kept(
    runner_script: str, env: dict[str, str], tmp_path: Path, signum: int
) -> None:
    runner, result = _signalled_while_concluding(runner_script, env, tmp_path, signum)
    assert runner.stderr is not None
    stderr = runner.stderr.read().decode(errors="replace")
    assert runner.returncode == 0, stderr  # the test passed: the run's outcome stands
    assert "Traceback" not in stderr
    summary = load_result(result)
    assert summary.properties["signal_after_test"] == signal.Signals(signum).name
    assert len(summary.cases) == 100_000
    assert all(case.outcome == "passed" for case in summary.cases)
    assert result.with_name("big.xml.orig").is_file()


def test_control_without_a_signal_the_result_notes_none(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "pkg" / "big.xml"
    script = tmp_path / "big.py"
    script.write_text(BIG_RESULT)
    command = [sys.executable, str(script), str(result), "100"]
    proc = ament(runner_script, result, command, env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    summary = load_result(result)
    assert "signal_after_test" not in summary.properties
    assert len(summary.cases) == 100

"""The final sweep ends what the test left running, its whole tree, and names it.

When the test's main process ends, what is left of its tree gets SIGTERM and a grace
period, then is frozen and SIGKILLed until none of it is left (``sweep.end_leftovers``).
Real processes and real signals: a daemon that ignores SIGTERM and forks continually
(each child through ``env -i``, so no squatter scan sees it), a well-behaved daemon that
must still get its SIGTERM, and a program embedding the runner whose own children are
not the test's. Every process a test starts carries a tag of its own in its command
line: "nothing survived" is checked across the whole machine, and teardown kills
whatever carries the tag, whatever went wrong. What the sweep cannot end is in
``test_sweep_survivors.py``; a real rclpy daemon gone before its ID is handed on, in
``test_sweep_talker.py``.
"""

from __future__ import annotations

import io
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from helpers.commands import HUNG, ament, run_cli
from helpers.process_tree import in_child
from helpers.results import load_result
from helpers.survivors import alive_with

from ros_isolated_test.process import supervisor
from ros_isolated_test.process.capture import OutputCapture

#: The red team's daemon. argv: env path, tag, seconds between children. The test's
#: main process returns once the daemon runs; the daemon ignores SIGTERM (so do its
#: children: an ignored signal stays ignored across fork and exec) and starts one
#: ``env -i sleep <tag>`` after another for ever. The tag is a number sleep accepts.
FORKING_DAEMON = """
import os, signal, sys, time
env, tag, period = sys.argv[1], sys.argv[2], float(sys.argv[3])
signal.signal(signal.SIGTERM, signal.SIG_IGN)
if os.fork():
    time.sleep(0.3)
    os._exit(0)
while True:
    os.posix_spawn(env, [env, "-i", "sleep", tag], {})
    time.sleep(period)
"""

#: A daemon that logs what happens to it. argv: events file, exits on SIGTERM (1/0), tag.
#: On SIGTERM it logs "term", and if it exits on it, takes a moment to shut down cleanly
#: (a SIGKILL sent too early would cut that short) and logs "exit".
LOGGING_DAEMON = """
import os, signal, sys, time
events, exits = sys.argv[1], sys.argv[2] == "1"
def log(what):
    with open(events, "a") as handle:
        handle.write(what + "\\n")
def on_term(signum, frame):
    log("term")
    if exits:
        time.sleep(0.3)
        log("exit")
        os._exit(0)
signal.signal(signal.SIGTERM, on_term)
read, write = os.pipe()
if os.fork():
    os.read(read, 1)
    os._exit(0)
log(f"started {os.getpid()}")
os.write(write, b"x")
while True:
    time.sleep(0.05)
"""


# -- the red team's case: a daemon that ignores SIGTERM and forks through env -i ---------------


def _forking_daemon(tmp_path: Path, tag: str, period: float) -> list[str]:
    script = tmp_path / "forking_daemon.py"
    script.write_text(FORKING_DAEMON)
    env_tool = shutil.which("env")
    assert env_tool is not None
    return [sys.executable, str(script), env_tool, tag, str(period)]


@pytest.mark.parametrize("attempt", range(4))
def test_a_forking_daemon_that_ignores_sigterm_leaves_nothing_behind(
    attempt: int, one_id: dict[str, str], tmp_path: Path, tags: Callable[[], str]
) -> None:
    """Through ``run``: once the runner exits, no process of the test lives, every time."""
    del attempt  # repeated: the old sweep lost the race in most runs, not all
    tag = tags()
    result = tmp_path / "result.xml"
    command = _forking_daemon(tmp_path, tag, 0.002)
    done = run_cli(
        ["run", "--kill-grace", "0.5", "--junit-xml", str(result), "--", *command],
        one_id,
        cwd=tmp_path,
    )
    survivors = alive_with(tag)
    assert done.returncode == 0, done.stdout + done.stderr
    assert survivors == [], f"still alive after the runner exited: {survivors}\n{done.stdout}"
    assert "stopped process" in done.stdout
    assert "could not be ended" not in done.stdout
    properties = load_result(result).properties
    assert "(sleep)" in properties["leftover_processes"]
    assert "surviving_processes" not in properties


def test_a_forking_daemon_leaves_nothing_behind_the_ctest_runner(
    one_id: dict[str, str], tmp_path: Path, tags: Callable[[], str], runner_script: str
) -> None:
    """The same through the RUNNER script, with ctest's default grace of 5 s."""
    tag = tags()
    result = tmp_path / "pkg" / "result.xml"
    command = _forking_daemon(tmp_path, tag, 0.01)
    done = ament(
        runner_script, result, command, one_id, "--generate-result-on-success", cwd=tmp_path
    )
    survivors = alive_with(tag)
    assert done.returncode == 0, done.stdout + done.stderr
    assert survivors == [], f"still alive after the runner exited: {survivors}\n{done.stdout}"
    assert "stopped process" in done.stdout


# -- a well-behaved daemon still gets its SIGTERM, and its chance ------------------------------


@pytest.mark.parametrize("exits_on_term", [True, False], ids=["exits-on-term", "ignores-term"])
def test_a_daemon_gets_sigterm_and_its_grace_before_any_sigkill(
    exits_on_term: bool, one_id: dict[str, str], tmp_path: Path, tags: Callable[[], str]
) -> None:
    """Exiting on SIGTERM, it shuts down cleanly; ignoring it (the control), it is killed.

    The order of events in its own log says which: a SIGKILL (or a SIGSTOP) sent before
    it finished shutting down would leave no "exit".
    """
    tag = tags()
    events = tmp_path / "events"
    script = tmp_path / "logging_daemon.py"
    script.write_text(LOGGING_DAEMON)
    grace = "60" if exits_on_term else "0.5"
    command = [sys.executable, str(script), str(events), "1" if exits_on_term else "0", tag]
    started = time.monotonic()
    done = run_cli(["run", "--kill-grace", grace, "--", *command], one_id, cwd=tmp_path)
    took = time.monotonic() - started
    assert done.returncode == 0, done.stdout + done.stderr
    assert alive_with(tag) == []
    log = events.read_text().split("\n")
    pid = int(log[0].split()[1])
    assert f"stopped process {pid} (python" in done.stdout
    if exits_on_term:
        assert log[1:] == ["term", "exit", ""]
        # It ended the grace period by exiting: the runner did not sit out the 60 s.
        assert took < 60
    else:
        assert log[1:] == ["term", ""]


# -- a program embedding the supervisor keeps its own children --------------------------------


def test_processes_started_before_the_test_are_not_the_tests(tags: Callable[[], str]) -> None:
    """Only the test's tree is swept: a child the embedding program had already is left alone."""
    tag = tags()
    own = subprocess.Popen(["sleep", tag])
    try:
        console = io.BytesIO()
        command = ["sh", "-c", f"sleep {tag} & exit 0"]
        outcome = supervisor.run(command, dict(os.environ), OutputCapture(console), None, 0.5)
        assert outcome.returncode == 0
        assert [name.endswith("(sleep)") for name in outcome.leftovers] == [True]
        assert str(own.pid) not in outcome.leftovers[0]
        assert own.poll() is None, "the embedding program's own child was signalled"
        assert alive_with(tag) == [own.pid]
    finally:
        own.kill()
        own.wait(HUNG)


# -- end_leftovers itself, in an interpreter of its own (a subreaper, as the runner is) -------

#: A runner-to-be with a child of its own from before (``sleep TAG``), then a "test" that
#: double-forks a daemon (``sleep TAG``) and exits. argv: tag, whether to pass ``others``.
#: Prints what end_leftovers said and who is left.
DOUBLE_FORK = """
import json, os, subprocess, sys
from ros_isolated_test.process import proc, reaper, sweep
tag, keep_others = sys.argv[1], sys.argv[2] == "1"
assert reaper.become_subreaper()
own = subprocess.Popen(["sleep", tag])
others = sweep.existing_children()
script = f'sh -c "sleep {tag} >/dev/null 2>&1 & echo \\\\$!"'
daemon = int(subprocess.run(["sh", "-c", script], capture_output=True, check=True).stdout)
adopted = proc.read_stat(daemon).ppid == os.getpid()
named, survived = sweep.end_leftovers(0.5, others if keep_others else frozenset())
found = {
    "own": own.pid, "daemon": daemon, "adopted": adopted, "own_was_there": bool(others),
    "named": list(named), "survived": [stat.pid for stat in survived],
    "daemon_alive": proc.read_stat(daemon) is not None, "own_alive": own.poll() is None,
}
own.kill()
own.wait()
print(json.dumps(found))
"""


def test_end_leftovers_ends_a_double_forked_daemon_and_names_it(tags: Callable[[], str]) -> None:
    """Its parent gone, the daemon is the subreaper's: found, ended, named; nothing survives."""
    found = in_child(DOUBLE_FORK, tags(), 1)
    assert found["adopted"], "the orphaned daemon was not adopted by the subreaper"
    assert found["named"] == [f"{found['daemon']} (sleep)"], found
    assert found["survived"] == [] and not found["daemon_alive"], found


def test_processes_that_were_children_before_are_left_alone(tags: Callable[[], str]) -> None:
    """``existing_children`` keeps the embedding program's child out; without it, it is ended."""
    kept = in_child(DOUBLE_FORK, tags(), 1)
    assert kept["own_was_there"] and kept["own_alive"], kept
    assert str(kept["own"]) not in " ".join(kept["named"]), kept
    # The control: the same sweep told of no earlier children ends that child too.
    swept = in_child(DOUBLE_FORK, tags(), 0)
    assert not swept["own_alive"], swept
    assert f"{swept['own']} (sleep)" in swept["named"], swept


#: A leftover that ignores SIGTERM (``sleep TAG`` under ``trap '' TERM``); prints the
#: living tree before, what end_leftovers said, and what ``survivors`` finds after.
STUBBORN = """
import json, os, subprocess, sys
from ros_isolated_test.process import reaper, sweep
tag = sys.argv[1]
assert reaper.become_subreaper()
before = [stat.pid for stat in sweep.survivors()]
nothing = sweep.end_leftovers(0.2)
script = f"trap '' TERM; exec sleep {tag}"
stubborn = subprocess.Popen(["sh", "-c", script])
# comm, not cmdline: exec shows the new arguments a moment before the new name.
while open(f"/proc/{stubborn.pid}/comm").read().strip() != "sleep":
    pass
during = [stat.pid for stat in sweep.survivors()]
named, survived = sweep.end_leftovers(0.2)
print(json.dumps({
    "before": before, "nothing": [list(part) for part in nothing], "stubborn": stubborn.pid,
    "during": during, "named": list(named), "survived": [stat.pid for stat in survived],
    "after": [stat.pid for stat in sweep.survivors()],
}))
"""


def test_a_leftover_ignoring_sigterm_is_killed_after_the_grace_and_survivors_sees_it_go(
    tags: Callable[[], str],
) -> None:
    found = in_child(STUBBORN, tags())
    assert found["before"] == [] and found["nothing"] == [[], []], "an empty tree: nothing"
    assert found["during"] == [found["stubborn"]], found
    assert found["named"] == [f"{found['stubborn']} (sleep)"] and found["survived"] == [], found
    assert found["after"] == [], found


#: A program embedding the sweep (as the pytest plugin does): its own children, one that
#: exited before the work and one that exits during it, not waited for yet; the work's
#: leftover; then the sweep. Prints the exit codes its own children report afterwards.
EMBEDDING = r"""
import json, os, subprocess, sys, time
from ros_isolated_test.process import proc, reaper, sweep

def exited(child):
    while (stat := proc.read_stat(child.pid)) is None or stat.alive:
        time.sleep(0.01)

reaper.become_subreaper()
before = subprocess.Popen([sys.executable, "-c", "raise SystemExit(3)"])
waits = "import sys; sys.stdin.read(); raise SystemExit(4)"
running = subprocess.Popen([sys.executable, "-c", waits], stdin=subprocess.PIPE)
exited(before)
others = sweep.existing_children() if sys.argv[1] == "spared" else frozenset()
leftover = subprocess.Popen(["sleep", "600"])
running.stdin.close()
exited(running)
named, survivors = sweep.end_leftovers(1.0, others)
print(json.dumps({"before": before.wait(), "running": running.wait(), "named": list(named)}))
"""


def test_the_embedding_programs_children_keep_their_exit_status() -> None:
    """Its exited children are never reaped by the sweep: their status stays for it to wait.

    The control: the same sweep told nothing of them reaps them (their status is lost,
    Popen then says 0) and ends the one still running, as it must for the work's own.
    """
    spared = in_child(EMBEDDING, "spared")
    assert (spared["before"], spared["running"]) == (3, 4), spared
    assert len(spared["named"]) == 1 and "sleep" in spared["named"][0], spared
    control = in_child(EMBEDDING, "not spared")
    assert (control["before"], control["running"]) == (0, 0), control

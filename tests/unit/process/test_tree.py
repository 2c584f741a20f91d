"""The test's process tree, found through /proc parent links, and signalled whole.

Signalling only the test's main process would leave its children running, on a domain
ID the coordinator is about to hand to the next test; signalling a process outside the
tree would hit what is not the test's. So ``tree.descendants`` must find every living
descendant (parents first, zombies out, an embedding program's processes skipped with
their own), and ``signal_tree`` reach them all and nothing else. Real processes, real
signals; a process of another user shows what may not be signalled.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.process_tree import AWKWARD_NAME, alive, awkward_sleeper
from helpers.processes import DEADLINE, poll_until, stat_of, user_keywords

from ros_isolated_test.process import proc, tree

#: A test's main process: leaves one zombie child unreaped, starts ``sh`` with a ``sleep``
#: child and a ``sleep`` of its own, prints ``zombie sh grandchild sleep`` and waits.
TREE = """
import os, subprocess, sys, time
zombie = os.fork()
if zombie == 0:
    os._exit(0)
shell = subprocess.Popen(["sh", "-c", "sleep 600 & echo $!; wait"], stdout=subprocess.PIPE)
grandchild = int(shell.stdout.readline())
sleeper = subprocess.Popen(["sleep", "600"])
print(zombie, shell.pid, grandchild, sleeper.pid, flush=True)
time.sleep(600)
"""


class Tree:
    """:data:`TREE` running: its main process and the PIDs it printed."""

    def __init__(self) -> None:
        self.main = subprocess.Popen([sys.executable, "-c", TREE], stdout=subprocess.PIPE)
        assert self.main.stdout is not None
        line = self.main.stdout.readline().split()
        assert len(line) == 4, f"the tree did not start: {line!r}"
        self.zombie, self.shell, self.grandchild, self.sleeper = map(int, line)
        poll_until(lambda: _state(self.zombie) == "Z", "the zombie")

    def stop(self) -> None:
        for pid in (self.grandchild, self.sleeper, self.shell):
            if alive(pid):
                os.kill(pid, signal.SIGKILL)
        self.main.kill()
        self.main.wait(DEADLINE)
        assert self.main.stdout is not None
        self.main.stdout.close()


def _state(pid: int) -> str | None:
    found = proc.read_stat(pid)
    return None if found is None else found.state


def _stopped(pid: int) -> bool:
    return _state(pid) in proc.STOPPED_STATES


@pytest.fixture
def started_tree() -> Iterator[Tree]:
    running = Tree()
    try:
        yield running
    finally:
        running.stop()


@pytest.fixture
def sleeper(tmp_path: Path) -> Iterator[subprocess.Popen[bytes]]:
    """A child whose executable (so whose kernel name) is :data:`AWKWARD_NAME`."""
    with awkward_sleeper(tmp_path) as child:
        yield child


def test_the_tree_uses_the_same_reader(sleeper: subprocess.Popen[bytes]) -> None:
    """tree.descendants finds the child by its parent link, under its awkward name."""
    found = {process.pid: process for process in tree.descendants(os.getpid())}
    assert found[sleeper.pid].name == AWKWARD_NAME
    stat = proc.read_stat(sleeper.pid)
    assert stat is not None
    skipped = tree.descendants(os.getpid(), skip={stat.key})
    assert sleeper.pid not in {process.pid for process in skipped}


def test_descendants_are_every_living_one_parents_first_zombies_left_out(
    started_tree: Tree,
) -> None:
    found = [process.pid for process in tree.descendants(started_tree.main.pid)]
    living = [started_tree.shell, started_tree.grandchild, started_tree.sleeper]
    assert sorted(found) == sorted(living)
    assert found.index(started_tree.shell) < found.index(started_tree.grandchild)
    # The zombie is there, a child of the main process: left out because it runs no more.
    zombie = proc.read_stat(started_tree.zombie)
    assert zombie is not None and zombie.ppid == started_tree.main.pid and not zombie.alive
    assert started_tree.main.pid not in found, "a process is not its own descendant"


def test_a_skipped_process_is_left_out_with_its_own_descendants(started_tree: Tree) -> None:
    shell = stat_of(started_tree.shell)
    found = [process.pid for process in tree.descendants(started_tree.main.pid, skip={shell.key})]
    assert found == [started_tree.sleeper]
    # The control: a key of another process (the same PID, another start) skips nothing.
    stale = (shell.pid, shell.start + 1)
    kept = {process.pid for process in tree.descendants(started_tree.main.pid, skip={stale})}
    assert started_tree.grandchild in kept and started_tree.shell in kept


def test_processes_sees_this_process_and_its_children(started_tree: Tree) -> None:
    seen = {process.pid: process for process in tree.processes()}
    assert seen[os.getpid()].alive
    assert seen[started_tree.main.pid].ppid == os.getpid()
    assert seen[started_tree.zombie].state == "Z"


def test_signal_tree_reaches_every_descendant_and_nothing_else(started_tree: Tree) -> None:
    """SIGSTOP, which ends nobody: each process of the tree stops, a bystander does not."""
    bystander = subprocess.Popen(["sleep", "600"])
    everyone = [started_tree.main.pid, started_tree.shell, started_tree.grandchild]
    everyone.append(started_tree.sleeper)
    try:
        tree.signal_tree(started_tree.main.pid, signal.SIGSTOP)
        poll_until(lambda: all(map(_stopped, everyone)), "the whole tree to stop")
        assert not _stopped(bystander.pid), "a bystander was signalled"
        tree.signal_tree(started_tree.main.pid, signal.SIGCONT)
        poll_until(lambda: not any(map(_stopped, everyone)), "the whole tree to go on")
    finally:
        bystander.kill()
        bystander.wait(DEADLINE)


def test_signal_tree_kills_every_descendant_though_the_first_dies_at_once(
    started_tree: Tree,
) -> None:
    """SIGKILL ends the main process at once; its children are found before, never missed.

    Orphaned, they would leave its tree for init's before a scan made after the signal.
    """
    orphans = [started_tree.shell, started_tree.grandchild, started_tree.sleeper]
    tree.signal_tree(started_tree.main.pid, signal.SIGKILL)
    started_tree.main.wait(DEADLINE)
    poll_until(lambda: not any(map(alive, orphans)), "every process of the tree to die")


def test_descendants_with_zombies_has_the_exited_ones_too(started_tree: Tree) -> None:
    """An exited child whose parent has yet to collect it: kept for that parent's sake."""
    found = [process.pid for process in tree.descendants(started_tree.main.pid, zombies=True)]
    assert started_tree.zombie in found
    assert started_tree.zombie not in [p.pid for p in tree.descendants(started_tree.main.pid)]


def test_signal_all_skips_processes_already_gone() -> None:
    child = subprocess.Popen(["sleep", "600"])
    gone = stat_of(child.pid)
    child.kill()
    child.wait(DEADLINE)
    assert tree.signal_all([gone], signal.SIGTERM) == []


#: As another user: SIGTERM to ``PID`` (root's) and to a child of its own; prints the
#: refused PIDs.
SIGNAL_AS_OTHER_USER = """
import subprocess, sys
from ros_isolated_test.process import proc, tree
own = subprocess.Popen(["sleep", "600"])
targets = [proc.read_stat(int(sys.argv[1])), proc.read_stat(own.pid)]
refused = tree.signal_all(targets, 15)
own.wait()
print(*[target.pid for target in refused], own.returncode)
"""


@capabilities.OTHER_USERS.mark
def test_signal_all_returns_the_processes_it_may_not_signal() -> None:
    """EPERM is no error: the caller learns which processes were refused (survivors)."""
    roots = subprocess.Popen(["sleep", "600"])
    try:
        done = subprocess.run(
            [sys.executable, "-c", SIGNAL_AS_OTHER_USER, str(roots.pid)],
            capture_output=True,
            text=True,
            timeout=DEADLINE,
            check=False,
            **user_keywords(65534),
        )
        assert done.returncode == 0, done.stderr
        refused, own_code = done.stdout.split()
        assert int(refused) == roots.pid
        assert roots.poll() is None, "root's process was signalled"
        # The control: its own child was signalled, and ended by it.
        assert int(own_code) == -signal.SIGTERM
    finally:
        roots.kill()
        roots.wait(DEADLINE)

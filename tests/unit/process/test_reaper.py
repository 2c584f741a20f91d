"""The runner adopts every orphan of the test's tree, and reaps what dies in it.

As a child subreaper (Linux), the runner becomes the parent of every orphan in the
test's tree: a double-forked daemon stays its descendant, where the sweep finds it. An
embedding program gets its process back as it was (``stop_subreaper``). Reaping keeps
the test's own exit status for the supervisor (``reap_orphans(keep=...)``), and as PID 1
of a container the runner reaps every orphan, or zombies pile up. Each check runs in
an interpreter of its own (a subreaper for good, its children reaped), with real
processes; each has its control.
"""

from __future__ import annotations

import subprocess
from collections.abc import Callable
from pathlib import Path

import pytest
from helpers.process_tree import in_child, in_pid_namespace, interruption

#: Adopting: each orphan is ``sleep TAG`` whose shell exited at once. argv: tag. Prints
#: the subreaper flag and the orphans' parents before, while and after being one.
ADOPTION = """
import json, os, subprocess, sys
from ros_isolated_test.process import proc, reaper
tag = sys.argv[1]

def orphan():
    script = f"sleep {tag} >/dev/null 2>&1 & echo $!"
    pid = int(subprocess.run(["sh", "-c", script], capture_output=True, check=True).stdout)
    return proc.read_stat(pid).ppid == os.getpid()

found = {"flag_before": reaper.is_subreaper(), "adopted_before": orphan()}
found["became"] = reaper.become_subreaper()
found["flag_while"] = reaper.is_subreaper()
found["adopted_while"] = orphan()
found["stopped"] = reaper.stop_subreaper()
found["flag_after"] = reaper.is_subreaper()
found["adopted_after"] = orphan()
print(json.dumps(found))
"""


def test_a_subreaper_adopts_an_orphaned_grandchild_and_stop_subreaper_gives_it_back(
    tags: Callable[[], str],
) -> None:
    found = in_child(ADOPTION, tags())
    assert found["became"] and found["flag_while"], found
    assert found["adopted_while"], "the orphan went past the subreaper"
    # The controls: before and after, an orphan goes to an ancestor further up.
    assert not found["flag_before"] and not found["adopted_before"], found
    assert found["stopped"] and not found["flag_after"], found
    assert not found["adopted_after"], "an embedding program did not get its process back"


#: Reaping: the test (``true``) exits; an adopted orphan is killed. Prints what
#: reap_orphans reaped, with and without ``keep``, and what waitpid still finds.
REAPING = """
import json, os, signal, subprocess, sys
from ros_isolated_test.process import proc, reaper
tag = sys.argv[1]
reaper.become_subreaper()
found = {"children_at_first": reaper.has_children()}
test = subprocess.Popen(["true"])
while proc.read_stat(test.pid).state != "Z":
    pass
found["children_with_a_zombie"] = reaper.has_children()
found["reaped_keeping_the_test"] = reaper.reap_orphans(keep=test.pid)
found["test_status"] = os.waitstatus_to_exitcode(os.waitpid(test.pid, 0)[1])
script = f"sleep {tag} >/dev/null 2>&1 & echo $!"
orphan = int(subprocess.run(["sh", "-c", script], capture_output=True, check=True).stdout)
found["children_with_an_orphan"] = reaper.has_children()
os.kill(orphan, signal.SIGKILL)
while proc.read_stat(orphan).state != "Z":
    pass
found["reaped"] = reaper.reap_orphans()
found["orphan_gone"] = proc.read_stat(orphan) is None
found["children_at_last"] = reaper.has_children()
found["reaped_of_none"] = reaper.reap_orphans()
print(json.dumps(found))
"""


def test_reap_orphans_reaps_every_exited_child_but_the_test(tags: Callable[[], str]) -> None:
    found = in_child(REAPING, tags())
    assert found["reaped_keeping_the_test"] == 0, "the test's status was taken"
    assert found["test_status"] == 0, "the supervisor still collects the test's own status"
    # The control: an orphan that died is reaped, and no zombie is left.
    assert found["reaped"] == 1 and found["orphan_gone"], found
    assert found["reaped_of_none"] == 0, found


def test_has_children_sees_a_living_child_and_a_zombie_and_nothing_else(
    tags: Callable[[], str],
) -> None:
    found = in_child(REAPING, tags())
    assert not found["children_at_first"] and not found["children_at_last"], found
    assert found["children_with_a_zombie"] and found["children_with_an_orphan"], found


# --- PID 1 of a container ---------------------------------------------------------------


@pytest.mark.usefixtures("pid_namespaces")
def test_pid_1_reaps_orphaned_grandchildren(tree_env: dict[str, str], tmp_path: Path) -> None:
    script = (
        # Orphans that live until told to go: their parents have exited, so they are
        # PID 1's now; once gone (kill -0 fails for a reaped one, not for a zombie), no
        # zombie may be left. Order of events only: no sleep decides anything.
        "for i in 1 2 3 4 5; do sh -c 'while [ ! -e go ]; do sleep 0.05; done & "
        "echo $! >> orphans'; done; "
        "adopted=0; for p in $(cat orphans); do "
        '[ "$(ps -o ppid= -p $p | tr -d " ")" = 1 ] && adopted=$((adopted+1)); done; '
        "echo adopted=$adopted; touch go; "
        "n=0; for p in $(cat orphans); do "
        "while kill -0 $p 2>/dev/null && [ $n -lt 600 ]; do sleep 0.1; n=$((n+1)); done; done; "
        "echo zombies=$(ps -eo stat= | grep -c '^Z'); exit 42"
    )
    result = tmp_path / "result.xml"
    proc = subprocess.run(
        in_pid_namespace("run", "--junit-xml", str(result), "--", "sh", "-c", script),
        env=tree_env,
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    output = proc.stdout + proc.stderr
    assert "adopted=5" in proc.stdout, f"the orphans were not the runner's to reap:\n{output}"
    assert "zombies=0" in proc.stdout, output
    assert proc.returncode == 42, output
    assert "exited with code 42" in interruption(result)

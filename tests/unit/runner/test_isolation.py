"""``isolation``: holding an ID (and resources) for as long as the work lives, then letting go.

The part around the work that the runner's attempts and the pytest plugin share: the ID
is held for the block and free again after it; whatever of the work survives keeps the
ID (and the resources held with it) blocked until it is gone, and the note says so;
work that ran in this very process has what it left ended and named, while processes
that were there before are not the work's and stay; in namespace mode no ID is waited
for. What blocks an ID is the supervisor's list of survivors, never a process an
embedding program started itself. Against a private lock directory and IDs free now,
each hold beside the control that shows it let go.
"""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import pytest
from helpers.commands import HUNG, run_process
from helpers.domains import free_ids
from helpers.holding import free_now, one_id_policy
from helpers.processes import stat_of
from helpers.results import load_result

from ros_isolated_test.domain_coordinator import resource_holds
from ros_isolated_test.domain_coordinator.block import blocking_survivors
from ros_isolated_test.domain_coordinator.reservation import DomainCoordinator
from ros_isolated_test.process import proc
from ros_isolated_test.runner import environment, isolation, settings

# --- held, and released ----------------------------------------------------------------------


def test_the_id_is_held_for_the_block_and_free_after_it(lock_dir: Path) -> None:
    (domain_id,) = free_ids(1)
    policy, config = one_id_policy(lock_dir, domain_id)
    coordinator = DomainCoordinator(lock_dir, [domain_id])
    notes: list[str] = []
    with isolation.isolation(policy, config, ["work"], notes.append) as held:
        assert held is not None
        assert (held.domain_id, held.reserved, held.resources) == (domain_id, True, {})
        assert not free_now(coordinator), "another runner took the held ID"
        held.survivors = []  # the supervisor's word, as an attempt gives it: none
    assert free_now(coordinator)  # the control: released
    assert notes == []


def test_a_survivor_keeps_the_id_blocked_until_it_is_gone(lock_dir: Path) -> None:
    (domain_id,) = free_ids(1)
    policy, config = one_id_policy(lock_dir, domain_id)
    coordinator = DomainCoordinator(lock_dir, [domain_id])
    survivor = subprocess.Popen(["sleep", "600"])
    notes: list[str] = []
    try:
        with isolation.isolation(policy, config, ["work"], notes.append) as held:
            assert held is not None
            stat = stat_of(survivor.pid)
            held.survivors = [stat]
        (note,) = notes
        assert note.startswith(f"ROS_DOMAIN_ID {domain_id} stays blocked while {stat.describe()}")
        assert note.endswith("; see ros-isolated-test status"), note
        assert [found.pid for found in blocking_survivors(lock_dir, domain_id)] == [survivor.pid]
        assert not free_now(coordinator), "the ID was handed out while the survivor lives"
    finally:
        survivor.kill()
        survivor.wait()
    # The control: with the survivor gone, the ID is free again.
    assert blocking_survivors(lock_dir, domain_id) == []
    assert free_now(coordinator)


def test_with_isolation_disabled_and_no_resources_nothing_is_held(lock_dir: Path) -> None:
    (domain_id,) = free_ids(1)
    policy, config = one_id_policy(lock_dir, domain_id, DISABLE_ROS_ISOLATION="1")
    with isolation.isolation(policy, config, ["work"], print) as held:
        assert held is None
        assert free_now(DomainCoordinator(lock_dir, [domain_id]))


def test_in_namespaces_no_id_is_waited_for_and_one_free_is_held(lock_dir: Path) -> None:
    """A test in a network of its own runs at once: on the pool's first ID, unreserved."""
    (domain_id,) = free_ids(1)
    policy, config = one_id_policy(lock_dir, domain_id, ROS_ISOLATED_TEST_ISOLATION="namespace")
    assert policy.namespaces
    coordinator = DomainCoordinator(lock_dir, [domain_id])
    holder = coordinator.reserve(["the holder of the only ID"])
    with holder, isolation.isolation(policy, config, ["work"], print) as held:
        assert held is not None and (held.domain_id, held.reserved) == (domain_id, False)
        held.survivors = []
    # The control: the ID free, it is held (reserved) for the block.
    with isolation.isolation(policy, config, ["work"], print) as held:
        assert held is not None and (held.domain_id, held.reserved) == (domain_id, True)
        assert not free_now(coordinator)
        held.survivors = []
    assert free_now(coordinator)


def test_work_in_this_process_has_what_it_left_ended_and_named(lock_dir: Path) -> None:
    """The pytest plugin's case: its tests ran here; children from before the block stay."""
    (domain_id,) = free_ids(1)
    policy, config = one_id_policy(lock_dir, domain_id)
    started = [subprocess.Popen(["sleep", "600"])]
    notes: list[str] = []
    try:
        with isolation.isolation(policy, config, ["work"], notes.append, sweep_grace=HUNG):
            started.append(subprocess.Popen(["sleep", "600"]))  # the work's, left running
        before, left = started
        found = proc.read_stat(left.pid)
        assert found is None or not found.alive, "what the work left still runs"
        assert notes == [f"stopped process {left.pid} (sleep), left running by the test"]
        assert stat_of(before.pid).alive  # the control: not the work's, so it stays
    finally:
        for child in started:
            if child.poll() is None:
                child.send_signal(signal.SIGKILL)
            child.wait()
    assert free_now(DomainCoordinator(lock_dir, [domain_id]))


# --- what blocks an ID: the survivors the result names, never a process of an embedder -------

#: A program embedding the runner, with a child of its own running throughout: two runs
#: in a row on a pool of one ID, then what a fresh scan of its process tree finds.
EMBEDDER = """
import subprocess, sys
from pathlib import Path
from ros_isolated_test.process import sweep
from ros_isolated_test.runner import session, settings
from ros_isolated_test.runner.request import Mode, RunRequest

own = subprocess.Popen(["sleep", "600"])
try:
    codes = []
    for name in ("first.xml", "second.xml"):
        request = RunRequest(
            ("true",), Mode.SHELL, settings.read(), result_file=Path(name),
            generate_result_on_success=True,
        )
        codes.append(session.run(request))
    scanned = [process.pid for process in sweep.survivors()]
finally:
    own.kill()
    own.wait()
print("codes", *codes)
print("own", own.pid, "scanned", *scanned)
"""


def test_an_embedding_programs_own_child_never_blocks_the_id(
    env: dict[str, str], tmp_path: Path
) -> None:
    (domain_id,) = free_ids(1)
    env.update(ROS_ISOLATED_TEST_DOMAINS=str(domain_id), ROS_ISOLATED_TEST_WAIT_TIMEOUT="0")
    done = run_process([sys.executable, "-c", EMBEDDER], env, cwd=tmp_path)
    assert done.returncode == 0, done.stdout + done.stderr
    lines = done.stdout.splitlines()
    own, scanned = lines[-1].split(" scanned")
    # The control: a fresh scan of the runner's tree does find the embedder's child.
    assert own.split()[1] in scanned.split(), done.stdout
    assert lines[-2] == "codes 0 0", done.stdout + done.stderr  # the second run got the ID
    assert "stays blocked" not in done.stdout
    assert "surviving_processes" not in load_result(tmp_path / "first.xml").properties


@pytest.mark.parametrize("disabled", [False, True], ids=["isolated", "isolation-disabled"])
def test_survivors_keep_the_resources_held_with_the_id_and_say_so(
    lock_dir: Path, disabled: bool
) -> None:
    """A survivor of the work keeps the ID and the GPU: the note names both, status shows it."""
    ids = free_ids(1)
    environ = {
        "ROS_ISOLATED_TEST_LOCK_DIR": str(lock_dir),
        "ROS_ISOLATED_TEST_DOMAINS": str(ids[0]),
        "ROS_ISOLATED_TEST_CAPACITY": "gpu=1",
        **({"DISABLE_ROS_ISOLATION": "1"} if disabled else {}),
    }
    config = settings.read(environ, resources="gpu=1")
    policy = environment.decide((), config, environ)
    survivor = subprocess.Popen(["sleep", "600"])
    notes: list[str] = []
    try:
        with isolation.isolation(policy, config, ["work"], notes.append) as held:
            assert held is not None and held.resources == {"gpu": 1}
            stat = stat_of(survivor.pid)
            held.survivors = [stat]
        what = "gpu=1 stays" if disabled else f"ROS_DOMAIN_ID {ids[0]} and gpu=1 stay"
        assert any(
            note.startswith(f"{what} blocked while {stat.describe()} live") for note in notes
        ), notes
        assert [hold.survivors for hold in resource_holds.holds(lock_dir)] == [(survivor.pid,)]
    finally:
        survivor.kill()
        survivor.wait()
    # The control: with the survivor gone, nothing is held.
    assert resource_holds.holds(lock_dir) == []

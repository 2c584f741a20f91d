"""Beside ROS 2 Kilted's own isolated runner: one machine, never one ID twice at a time.

Kilted's ``run_test_isolated.py`` puts ``run_rmw_isolated`` (rmw_test_fixture, C++) in
front of the test command; it holds its ID by binding TCP 127.0.0.1:32768+ID, and knows
nothing of our lock directory. Ours binds 0.0.0.0:32768+ID while it holds an ID, and the
two binds exclude each other (neither sets SO_REUSEADDR), so both pick from 1-101 on one
machine without collision. The port is all Kilted's fixture sees of ours, and all ours
sees of Kilted's probes below (they are no DDS participants, whose UDP ports ours would
see too). So the run puts all of them in one private network namespace, which they must
share.

What each runner does with a ``ROS_DOMAIN_ID`` already set (P):

==========================================  ============================================
RUNNER                                      preset ``ROS_DOMAIN_ID=P``
==========================================  ============================================
Jazzy upstream ``run_test_isolated.py``     runs the test on P, silently: no port taken,
(``domain_coordinator``)                    no message; every test so started shares P
Kilted upstream ``run_test_isolated.py``    ignores P, silently: takes a free ID by its
(``run_rmw_isolated``)                      port and runs the test on that
ros-isolated-test (``run``, the RUNNER)     refuses: exit 2, one error line naming the
                                            fix, the test never runs, the result file
                                            holds one failed case saying why
==========================================  ============================================
"""

from __future__ import annotations

import re
import subprocess
from collections.abc import Mapping, Sequence
from pathlib import Path

import pytest
from helpers import capabilities, commands
from helpers.commands import CLI, HUNG
from helpers.distros import JAZZY, KILTED
from helpers.domains import free_ids
from helpers.overlap import Board, Job, run_at_once
from helpers.results import DOMAIN_LINE, load_result

from ros_isolated_test.domain_coordinator.pool import (
    DEFAULT_SPEC,
    HIGHEST_VALID_ID,
    parse_pool,
)

#: How many of ours and of Kilted's start at once (each half by the CLI or the RUNNER).
EACH = 26
OUR_POOL = set(parse_pool(DEFAULT_SPEC))
VALID_IDS = set(range(1, HIGHEST_VALID_ID + 1))


def ament_args(result: Path, command: Sequence[str]) -> list[str]:
    """run_test.py's arguments, as ctest passes them to any RUNNER."""
    return commands.ament_args(result, command, "--generate-result-on-success", package="p")


def ours(board: Board, label: str, runner_script: str, env: Mapping[str, str], out: Path) -> Job:
    """Our runner around a probe: the shell ``run`` for even labels, the RUNNER for odd."""
    probe = board.probe(label)
    result = out / f"{label}.xml"
    if int(label.rsplit("-", 1)[1]) % 2:
        argv = [str(JAZZY.python), "-u", runner_script, *ament_args(result, probe)]
    else:
        argv = [CLI, "run", "--junit-xml", str(result), "--", *probe]
    return Job(label, argv, env)


def kilted(board: Board, label: str, env: Mapping[str, str], out: Path) -> Job:
    """Kilted's fixture around a probe: its RUNNER (what ctest runs) for odd labels, the
    bare ``run_rmw_isolated`` for even ones."""
    probe = board.probe(label)
    fixture = KILTED.run_rmw_isolated
    assert fixture is not None
    if int(label.rsplit("-", 1)[1]) % 2:
        runner = [str(KILTED.python), "-u", str(KILTED.upstream_runner)]
        argv = [*runner, *ament_args(out / f"{label}.xml", probe)]
    else:
        argv = [str(fixture), *probe]
    return Job(label, argv, KILTED.env(env))


def domain_of(record: Mapping[str, object]) -> int:
    domain = record["domain"]
    assert isinstance(domain, str) and domain.isdigit(), f"the probe saw no ID: {record}"
    return int(domain)


@capabilities.KILTED
@capabilities.NETWORK_NAMESPACES
@capabilities.UNSHARE
def test_ours_and_kilteds_started_at_once_never_share_an_id(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    """26 of ours and 26 of Kilted's, interleaved, in one private network and PID namespace.

    Every probe holds its ID until all 52 have tried to claim theirs, so all 52 held
    their IDs at the same instant: 52 distinct IDs and no collision is the proof.
    """
    board = Board(tmp_path / "board", total=2 * EACH)
    out = tmp_path / "results"
    out.mkdir()
    jobs: list[Job] = []
    for i in range(EACH):
        jobs.append(ours(board, f"ours-{i}", runner_script, env, out))
        jobs.append(kilted(board, f"kilted-{i}", env, out))

    done = run_at_once(jobs, tmp_path / "run")

    assert not board.collisions, f"two tests held one ID at once: {board.collisions}"
    failed = {label: d for label, d in done.items() if d.returncode != 0}
    assert not failed, "\n".join(f"{k}: exit {d.returncode}\n{d.output}" for k, d in failed.items())
    records = board.records
    assert set(records) == {job.label for job in jobs}, "a test never ran"
    assert all(r["all_held_at_once"] for r in records.values()), records
    domains = {label: domain_of(record) for label, record in records.items()}
    assert len(set(domains.values())) == len(jobs), domains
    for label, domain in domains.items():
        assert domain in (OUR_POOL if label.startswith("ours") else VALID_IDS), (label, domain)
        if label.startswith("ours"):
            announced = DOMAIN_LINE.search(done[label].output)
            assert announced and int(announced[1]) == domain, done[label].output
    # Every RUNNER and ``run`` left its result file (the bare fixture writes none); ours
    # are canonical xUnit (Kilted's is run_test.py's own, which our schema does not cover).
    writers = {job.label for job in jobs if job.argv[0] != str(KILTED.run_rmw_isolated)}
    assert {path.stem for path in out.iterdir()} == writers
    for result in out.glob("ours-*.xml"):
        assert load_result(result).only.outcome == "passed", result


@capabilities.KILTED
@capabilities.NETWORK_NAMESPACES
@capabilities.UNSHARE
@capabilities.UPSTREAM_RUNNER
def test_control_probes_on_one_preset_id_do_collide(env: dict[str, str], tmp_path: Path) -> None:
    """The check above can fail: the same probes, at once, under Jazzy upstream's RUNNER
    with one ROS_DOMAIN_ID exported (it keeps it) collide, each one recorded."""
    (shared,) = free_ids(1)
    count = 4
    board = Board(tmp_path / "board", total=count)
    preset = {**JAZZY.env(env), "ROS_DOMAIN_ID": str(shared)}
    runner = [str(JAZZY.python), "-u", str(JAZZY.upstream_runner)]
    jobs = [
        Job(
            f"jazzy-{i}",
            [*runner, *ament_args(tmp_path / f"{i}.xml", board.probe(f"jazzy-{i}"))],
            preset,
        )
        for i in range(count)
    ]

    done = run_at_once(jobs, tmp_path / "run")

    # The first to claim the ID holds it until the others have tried: all of them collide.
    collisions = board.collisions
    assert len(collisions) == count - 1, collisions
    assert {domain_of(c) for c in collisions.values()} == {shared}
    (holder,) = board.records.values()
    assert domain_of(holder) == shared
    assert sorted(d.returncode != 0 for d in done.values()) == [False] + [True] * (count - 1)


def run(argv: Sequence[str], env: Mapping[str, str], cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        list(argv),
        env=dict(env),
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=HUNG,
        check=False,
    )


#: The test command of the preset tests: writes the ID it runs on into ``seen``.
SEE = ["sh", "-c", 'printf %s "${ROS_DOMAIN_ID-unset}" > seen']


def preset_id() -> int:
    """A valid ID nobody uses now, from 215-232 where it can: outside Kilted's 1-101."""
    (preset,) = free_ids(1)
    return preset


@capabilities.KILTED
def test_kilted_upstream_runner_ignores_a_preset_id(env: dict[str, str], tmp_path: Path) -> None:
    preset = preset_id()
    args = ament_args(tmp_path / "t.xml", SEE)
    proc = run(
        [str(KILTED.python), "-u", str(KILTED.upstream_runner), *args],
        {**KILTED.env(env), "ROS_DOMAIN_ID": str(preset)},
        tmp_path,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    seen = (tmp_path / "seen").read_text()
    assert seen.isdigit(), seen
    assert int(seen) != preset, f"Kilted's runner kept the preset {preset}"
    assert int(seen) in VALID_IDS
    assert not re.search(r"(?i)warn", proc.stdout + proc.stderr), "it says nothing of it"


@capabilities.UPSTREAM_RUNNER
def test_jazzy_upstream_runner_keeps_a_preset_id_silently(
    env: dict[str, str], tmp_path: Path
) -> None:
    preset = preset_id()
    args = ament_args(tmp_path / "t.xml", SEE)
    proc = run(
        [str(JAZZY.python), "-u", str(JAZZY.upstream_runner), *args],
        {**JAZZY.env(env), "ROS_DOMAIN_ID": str(preset)},
        tmp_path,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (tmp_path / "seen").read_text() == str(preset)
    # Without a preset it announces the ID it took; with one, not a word.
    assert "Running with ROS_DOMAIN_ID" not in proc.stdout
    assert not re.search(r"(?i)warn|domain", proc.stderr), proc.stderr


@pytest.mark.parametrize("mode", ["runner", "shell"])
def test_ours_refuses_a_preset_id(
    runner_script: str, env: dict[str, str], tmp_path: Path, mode: str
) -> None:
    preset = preset_id()
    result = tmp_path / "t.xml"
    if mode == "runner":
        argv = [str(JAZZY.python), "-u", runner_script, *ament_args(result, SEE)]
    else:
        argv = [CLI, "run", "--junit-xml", str(result), "--", *SEE]
    proc = run(argv, {**env, "ROS_DOMAIN_ID": str(preset)}, tmp_path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert not (tmp_path / "seen").exists(), "a refused test must not run"
    (line,) = proc.stderr.splitlines()
    assert line.startswith("ros-isolated-test: error: "), line
    assert f"ROS_DOMAIN_ID is already set to '{preset}'" in line
    assert "unset ROS_DOMAIN_ID" in line, "the line names the fix"
    case = load_result(result).only
    assert case.outcome == "failure"
    assert case.message == line.removeprefix("ros-isolated-test: error: ")

    # Control: without the preset the same command runs, on an ID of the pool.
    isolated = run(argv, env, tmp_path)
    assert isolated.returncode == 0, isolated.stdout + isolated.stderr
    assert int((tmp_path / "seen").read_text()) in OUR_POOL

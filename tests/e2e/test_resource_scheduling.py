"""Acceptance: machine-wide test resources (CPUs, memory, devices), held like domain IDs.

Every test command here is ``helpers/resource_probe.py``: it appends ``start``/``end``
lines to one log with ``O_APPEND``, so the log's order is the order of events, and it
waits for partners where a test must prove that runners overlapped (a probe whose
partners never come gives up and fails its runner: the test fails, it does not hang).
Capacity is set explicitly in every test (ROS_ISOLATED_TEST_CAPACITY), never read from
this machine; the pool is IDs free now, in a lock directory of the test's own.

- an exclusive device (gpu=1) is held by one test at a time, while tests asking nothing
  run beside it and beside the runners queued for it;
- cpu=2 requests on a capacity of 4 run exactly two at a time;
- a random mix of 24 runners on 3 IDs finishes, within a stated bound, never above any
  capacity; a large request is never starved by small ones arriving after it, and the
  queue is first come, first served per resource only (a gpu request passes a cpu waiter);
- a SIGKILLed holder frees what it held, a SIGKILLed waiter blocks nobody;
- --wait-timeout on held resources: exit 3 and a result file; a request above capacity,
  an invalid one, or one whose capacity another live runner sees otherwise: exit 2,
  nothing run, a result file saying why; each beside a control that runs;
- the result file records what was held, how long it waited and the capacity; ``status``
  shows holders, waiters and the capacity; resources are released only once the test's
  whole process tree is gone, and are held with DISABLE_ROS_ISOLATION too.
"""

from __future__ import annotations

import json
import random
import re
import shlex
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import pytest
from helpers import resource_probe
from helpers.commands import HUNG, ament_args, run_cli, run_runner, start_cli
from helpers.domains import free_ids
from helpers.orphans import in_background
from helpers.processes import poll_until
from helpers.resource_probe import ended, peaks, starts
from helpers.results import load_result, result_error

from ros_isolated_test.domain_coordinator import resource_holds
from ros_isolated_test.domain_coordinator.resources import CAPACITY_ENV, RESOURCES_ENV, parse
from ros_isolated_test.runner.settings import WAIT_TIMEOUT_ENV

Started = list[subprocess.Popen[bytes]]

#: Each runner's test works this long in the mix (no timing is asserted on it).
MIX_HOLD = 0.2
#: What one runner may cost beyond its test on a loaded 2-core machine (start-up, queue,
#: result file): the mix's bound is 3x (this + MIX_HOLD) per runner, all run one by one.
RUNNER_BUDGET = 2.0
#: A test child that, on SIGTERM, takes a second to finish, then logs its end and exits.
SLOW_TO_DIE = """
import os, signal, sys, time
log, label = sys.argv[1], sys.argv[2]
def append(line):
    fd = os.open(log, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    os.write(fd, (line + "\\n").encode())
    os.close(fd)
def stop(signum, frame):
    time.sleep(1.0)
    append("end " + label)
    os._exit(0)
signal.signal(signal.SIGTERM, stop)
append("start " + label)
time.sleep(120)
"""


# --- runners -------------------------------------------------------------------------------


def _env(env: dict[str, str], capacity: str, ids: int = 3) -> dict[str, str]:
    """``env`` with ``ids`` IDs free now as the pool and ``capacity`` set, no request."""
    scoped = {key: value for key, value in env.items() if key != RESOURCES_ENV}
    scoped["ROS_ISOLATED_TEST_DOMAINS"] = ",".join(map(str, free_ids(ids)))
    scoped[CAPACITY_ENV] = capacity
    return scoped


def _run_args(request: str, command: Sequence[str], *options: str) -> list[str]:
    """``run [--resources REQUEST] OPTIONS -- COMMAND`` (no request: asks for nothing)."""
    asked = ["--resources", request] if request else []
    return ["run", *asked, *options, "--", *command]


class Probes:
    """Runners whose tests are probes logging into one file, started in the background."""

    def __init__(self, env: dict[str, str], tmp_path: Path, into: Started) -> None:
        self.env = env
        self.tmp_path = tmp_path
        self.log = tmp_path / "events.log"
        self.into = into
        self.runners: dict[str, subprocess.Popen[bytes]] = {}
        self.asked: dict[str, dict[str, int]] = {}

    def start(
        self,
        label: str,
        request: str,
        *options: object,
        env: dict[str, str] | None = None,
        orphan: bool = False,
    ) -> subprocess.Popen[bytes]:
        """A runner asking ``request`` whose test is the probe ``label`` with ``options``.

        ``orphan``: the probe runs as the test's own child, so it outlives a runner killed
        alone (the runner's direct child dies with it).
        """
        probe = resource_probe.command(self.log, label, *options)
        args = _run_args(
            request,
            in_background(probe) if orphan else probe,
            "--wait-timeout",
            "600",
            "--junit-xml",
            str(self.result(label)),
        )
        runner = start_cli(args, env or self.env, self.output(label), self.into)
        self.runners[label] = runner
        self.asked[label] = parse(request, "test")
        return runner

    def result(self, label: str) -> Path:
        return self.tmp_path / f"{label}.xml"

    def output(self, label: str) -> Path:
        return self.tmp_path / f"{label}.log"

    def said(self, label: str) -> str:
        return self.output(label).read_text(errors="replace")

    def wait_started(self, *labels: str) -> None:
        """Until each of ``labels`` logged its start (its runner still alive till then)."""
        for label in labels:

            def up(label: str = label) -> bool:
                if label in starts(self.log):
                    return True
                assert self.runners[label].poll() is None, self.said(label)
                return False

            poll_until(up, f"{label} to start")

    def finish(self, label: str) -> None:
        """Wait for ``label``'s runner; it must pass."""
        code = self.runners[label].wait(HUNG)
        assert code == 0, f"{label} exited {code}:\n{self.said(label)}"

    def peaks(self, *names: str) -> dict[str, int]:
        return peaks(self.log, self.asked, names)


# --- status --------------------------------------------------------------------------------


def _status(env: dict[str, str]) -> tuple[list[dict[str, object]], dict[str, object]]:
    """``status --json``: its rows, and the resources part as {"capacity", "held"}.

    Resources come as rows too: one ``"via": "capacity"`` row with the capacity, and a
    ``"via": "hold"`` row per runner holding some.
    """
    shown = run_cli(["status", "--json"], env)
    assert shown.returncode == 0, shown.stdout + shown.stderr
    rows: list[dict[str, object]] = json.loads(shown.stdout)
    capacity = [row.get("capacity") for row in rows if row.get("via") == "capacity"]
    assert len(capacity) <= 1, rows
    held = [row for row in rows if row.get("via") == "hold"]
    return rows, {"capacity": capacity[0] if capacity else None, "held": held}


def _queued(env: dict[str, str]) -> list[dict[str, object]]:
    """The runners waiting (for an ID or resources), first in line first."""
    rows, _ = _status(env)
    waiting = [row for row in rows if row.get("via") == "queue"]
    return sorted(waiting, key=lambda row: int(str(row["position"])))


def _wait_queued(probes: Probes, *labels: str) -> list[dict[str, object]]:
    """Until the runners of ``labels`` all wait in the queue; their rows, in queue order."""
    pids = {probes.runners[label].pid for label in labels}

    def waiting() -> bool:
        for label in labels:
            assert probes.runners[label].poll() is None, probes.said(label)
        return pids <= {row.get("pid") for row in _queued(probes.env)}

    poll_until(waiting, f"{', '.join(labels)} to wait in the queue")
    return [row for row in _queued(probes.env) if row.get("pid") in pids]


# --- scheduling ----------------------------------------------------------------------------


def test_an_exclusive_device_is_held_by_one_test_at_a_time_and_requests_for_nothing_pass(
    env: dict[str, str], tmp_path: Path, started: Started
) -> None:
    """gpu=1: four 1 s tests never overlap; four tests asking nothing all run beside them.

    The first gpu test holds on until all four nothing-tests have started, and each
    nothing-test until all four have: so they ran at one moment, beside the gpu holder
    and while three gpu runners waited in the queue ahead of them.
    """
    probes = Probes(_env(env, "cpu=4,gpu=1", ids=6), tmp_path, started)
    gpus = [f"gpu.{index}" for index in range(4)]
    for label in gpus:
        probes.start(label, "gpu=1", "--await", "none.", 4, "--hold", 1)
    poll_until(lambda: len(starts(probes.log, "gpu.")) >= 1, "a gpu test to start")
    holder = starts(probes.log, "gpu.")[0]
    _wait_queued(probes, *(label for label in gpus if label != holder))
    nothing = [f"none.{index}" for index in range(4)]
    for label in nothing:
        probes.start(label, "", "--batch", 4)
    for label in [*gpus, *nothing]:
        probes.finish(label)

    assert probes.peaks("gpu") == {"gpu": 1}, probes.log.read_text()
    order = resource_probe.events(probes.log)
    holder_end = order.index(("end", holder))
    assert all(order.index(("start", label)) < holder_end for label in nothing), order
    assert len(starts(probes.log, "gpu.")) == 4


def test_cpu_requests_run_exactly_as_many_at_once_as_the_capacity_allows(
    env: dict[str, str], tmp_path: Path, started: Started
) -> None:
    """cpu=4, four tests asking cpu=2: two at a time (each pair waits for its partner).

    Each then works 1 s more, so a scheduler letting a third one in would show it.
    """
    probes = Probes(_env(env, "cpu=4,gpu=1", ids=4), tmp_path, started)
    labels = [f"cpu.{index}" for index in range(4)]
    for label in labels:
        probes.start(label, "cpu=2", "--batch", 2, "--hold", 1)
    for label in labels:
        probes.finish(label)
    assert probes.peaks("cpu", "running") == {"cpu": 4, "running": 2}, probes.log.read_text()


def test_a_random_mix_finishes_without_deadlock_never_above_any_capacity(
    env: dict[str, str], tmp_path: Path, started: Started
) -> None:
    """24 runners asking cpu, gpu, both or nothing, in random order, on a pool of 3 IDs.

    Bound: every runner exits 0 within 3 x (MIX_HOLD + RUNNER_BUDGET) per runner, i.e.
    three times the time they would take one after another on a loaded machine; a
    deadlock or a starved runner overruns it (the runners wait up to 600 s).
    """
    probes = Probes(_env(env, "cpu=4,gpu=1,sim=2", ids=3), tmp_path, started)
    kinds = (
        ["cpu=1"] * 7 + ["cpu=2"] * 4 + ["cpu=4"] * 2 + ["gpu=1"] * 3
        + ["cpu=1,gpu=1"] * 2 + ["sim=1"] * 2 + [""] * 4
    )  # fmt: skip
    random.shuffle(kinds)
    for index, request in enumerate(kinds):
        probes.start(f"mix.{index}", request, "--hold", MIX_HOLD)
    bound = 3 * len(kinds) * (MIX_HOLD + RUNNER_BUDGET)
    deadline = time.monotonic() + bound
    for label, runner in probes.runners.items():
        left = max(0.1, deadline - time.monotonic())
        try:
            code = runner.wait(left)
        except subprocess.TimeoutExpired:
            pytest.fail(
                f"{label} ({probes.asked[label]}) still running after the bound of {bound:.0f} s; "
                f"events so far:\n{probes.log.read_text()}\n{_queued(probes.env)}"
            )
        assert code == 0, f"{label} exited {code}:\n{probes.said(label)}"
    assert sorted(starts(probes.log)) == sorted(probes.runners)
    top = probes.peaks("cpu", "gpu", "sim", "running")
    assert top["cpu"] <= 4 and top["gpu"] <= 1 and top["sim"] <= 2, top
    assert top["running"] <= 3, top  # one ID each, a pool of three


def test_a_large_request_is_not_starved_by_small_ones_arriving_after_it(
    env: dict[str, str], tmp_path: Path, started: Started
) -> None:
    """cpu=4 of 4 arrives while three cpu=1 hold; small ones keep coming as cpus free up.

    Controls: the three small ones arriving before it start at once, and a gpu=1 request
    arriving after it passes it (per resource first come, first served: it asks no cpu).
    """
    probes = Probes(_env(env, "cpu=4,gpu=1", ids=8), tmp_path, started)
    go = {index: tmp_path / f"go{index}" for index in range(3)}
    for index in range(3):
        probes.start(f"small.{index}", "cpu=1", "--until", go[index])
        probes.wait_started(f"small.{index}")  # control: nothing earlier claims a cpu
    probes.start("large", "cpu=4")
    (large,) = _wait_queued(probes, "large")
    assert large.get("resources") in (None, {"cpu": 4}), large
    probes.start("gpu", "gpu=1")  # asks no cpu: the cpu waiter does not hold it up
    probes.finish("gpu")
    late = []
    for index in range(3):
        label = f"late.{index}"
        late.append(label)
        probes.start(label, "cpu=1")
        rows = _wait_queued(probes, "large", label)
        assert [row["pid"] for row in rows] == [
            probes.runners["large"].pid,
            probes.runners[label].pid,
        ], rows
        go[index].touch()  # one more cpu free, still not enough for the large one
        probes.finish(f"small.{index}")
    for label in ["large", *late]:
        probes.finish(label)

    order = starts(probes.log)
    assert order.index("gpu") < order.index("large"), order
    assert all(order.index("large") < order.index(label) for label in late), order
    assert probes.peaks("cpu")["cpu"] <= 4, probes.log.read_text()


# --- death, timeouts, refusals -----------------------------------------------------------


def test_sigkill_of_a_runner_holding_resources_frees_them(
    env: dict[str, str], tmp_path: Path, started: Started
) -> None:
    """The waiter runs once its holder is SIGKILLed, while the holder's orphaned test lives."""
    probes = Probes(_env(env, "gpu=1"), tmp_path, started)
    go = tmp_path / "go"
    holder = probes.start("holder", "gpu=1", "--until", go, orphan=True)
    probes.wait_started("holder")
    probes.start("waiter", "gpu=1")
    _wait_queued(probes, "waiter")
    assert "waiter" not in starts(probes.log)  # control: it waited for the holder
    holder.kill()
    holder.wait(HUNG)
    try:
        probes.finish("waiter")
        assert not ended(probes.log, "holder"), probes.log.read_text()
    finally:
        go.touch()  # the orphaned test ends itself
    poll_until(lambda: ended(probes.log, "holder"), "the orphaned test to end")


def test_sigkill_of_a_waiting_runner_does_not_block_the_queue(
    env: dict[str, str], tmp_path: Path, started: Started
) -> None:
    probes = Probes(_env(env, "gpu=1"), tmp_path, started)
    go = tmp_path / "go"
    probes.start("holder", "gpu=1", "--until", go)
    probes.wait_started("holder")
    first = probes.start("first", "gpu=1")
    _wait_queued(probes, "first")
    probes.start("second", "gpu=1")
    rows = _wait_queued(probes, "first", "second")
    assert [row["pid"] for row in rows] == [first.pid, probes.runners["second"].pid], rows
    first.kill()
    first.wait(HUNG)
    go.touch()
    probes.finish("holder")
    probes.finish("second")
    order = resource_probe.events(probes.log)
    assert order.index(("end", "holder")) < order.index(("start", "second")), order
    assert "first" not in starts(probes.log)


@pytest.mark.parametrize("holder_isolation", ["isolated", "DISABLE_ROS_ISOLATION=1"])
def test_wait_timeout_on_held_resources_exits_3_with_a_result_file(
    env: dict[str, str], tmp_path: Path, started: Started, holder_isolation: str
) -> None:
    """Also: a holder running with isolation disabled still holds its resources."""
    probes = Probes(_env(env, "cpu=4,gpu=1"), tmp_path, started)
    go, marker, result = tmp_path / "go", tmp_path / "marker", tmp_path / "out" / "waiter.xml"
    holder_env = dict(probes.env)
    if holder_isolation != "isolated":
        holder_env["DISABLE_ROS_ISOLATION"] = "1"
    probes.start("holder", "gpu=1", "--until", go, env=holder_env)
    probes.wait_started("holder")
    args = _run_args("gpu=1", ["touch", str(marker)], "--wait-timeout", "1", "--junit-xml",
                     str(result))  # fmt: skip
    try:
        proc = run_cli(args, probes.env)
        holder_held_on = probes.runners["holder"].poll() is None
    finally:
        go.touch()
    probes.finish("holder")
    said = proc.stdout + proc.stderr
    assert proc.returncode == 3, said
    assert holder_held_on, "the waiter gave up only after the holder had ended"
    assert not marker.exists(), said
    holder = probes.runners["holder"].pid
    waiting = [line for line in proc.stdout.splitlines() if "waiting for gpu=1" in line]
    assert waiting and f"held by pid {holder} " in waiting[0], said  # who holds what
    summary = load_result(result)
    assert summary.only.outcome == "error", summary
    assert "after waiting" in summary.only.message, summary.only.message
    assert "gpu" in summary.only.message, summary.only.message
    assert summary.properties.get("exit") == "not run", summary.properties

    control = run_cli(args, probes.env)  # the same, once nothing holds the gpu
    assert control.returncode == 0, control.stdout + control.stderr
    assert marker.exists()
    assert load_result(result).only.outcome == "passed"


ABOVE = "gpu=2"
ENTRIES = ["option", "env", "ament --env", "ament env"]
#: (request, a word its error names): every entry point with one of each kind, the option
#: with every kind.
REFUSED = [(ABOVE, "capacity"), ("cpu=x", "cpu")]
REFUSED_BY_OPTION = [
    ("cpu=9", "capacity"),
    ("gpu", "gpu"),
    ("CPU=1", "CPU"),
    ("gpu=0", "gpu"),
    ("gpu=1,gpu=1", "twice"),
    ("mem=4Q", "mem"),
]


def _refusable(
    entry: str, request: str, marker: Path, result: Path, env: dict[str, str], runner: str
) -> subprocess.CompletedProcess[str]:
    """``touch MARKER`` asking ``request`` through ``entry``, the result into ``result``."""
    command = ["touch", str(marker)]
    if entry == "option":
        return run_cli(_run_args(request, command, "--junit-xml", str(result)), env)
    if entry == "env":
        return run_cli(["run", "--junit-xml", str(result), "--", *command],
                       {**env, RESOURCES_ENV: request})  # fmt: skip
    if entry == "ament --env":
        args = ament_args(result, command, "--env", f"{RESOURCES_ENV}={request}",
                          "--generate-result-on-success")  # fmt: skip
        return run_runner(runner, args, env)
    args = ament_args(result, command, "--generate-result-on-success")
    return run_runner(runner, args, {**env, RESOURCES_ENV: request})


@pytest.mark.parametrize(
    ("entry", "request_text", "named"),
    [(entry, *refused) for entry in ENTRIES for refused in REFUSED]
    + [("option", *refused) for refused in REFUSED_BY_OPTION],
)
def test_an_invalid_or_too_large_request_is_refused_at_once(
    env: dict[str, str],
    tmp_path: Path,
    runner_script: str,
    entry: str,
    request_text: str,
    named: str,
) -> None:
    """Exit 2, one error line naming it, the command not run, a result file saying so."""
    # Short: a request wrongly accepted then fails (exit 3) instead of waiting for ever.
    scoped = {**_env(env, "cpu=4,mem=8G,gpu=1", ids=2), WAIT_TIMEOUT_ENV: "5"}
    marker, result = tmp_path / "marker", tmp_path / "out" / "r.xml"
    proc = _refusable(entry, request_text, marker, result, scoped, runner_script)
    said = proc.stdout + proc.stderr
    assert proc.returncode == 2, said
    assert not marker.exists(), said
    errors = [line for line in said.splitlines() if "error" in line.lower()]
    assert len(errors) == 1 and named in errors[0], said
    assert "Running with ROS_DOMAIN_ID" not in said, said
    assert named in result_error(result), result_error(result)

    control = _refusable(entry, "cpu=4,gpu=1", marker, result, scoped, runner_script)
    assert control.returncode == 0, control.stdout + control.stderr
    assert marker.exists()


def test_an_invalid_capacity_is_refused(env: dict[str, str], tmp_path: Path) -> None:
    marker, result = tmp_path / "marker", tmp_path / "r.xml"
    args = _run_args("gpu=1", ["touch", str(marker)], "--junit-xml", str(result))
    proc = run_cli(args, _env(env, "gpu=lots", ids=1))
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert CAPACITY_ENV in proc.stdout + proc.stderr
    assert not marker.exists()
    assert CAPACITY_ENV in result_error(result)
    control = run_cli(args, _env(env, "gpu=1", ids=1))
    assert control.returncode == 0, control.stdout + control.stderr
    assert marker.exists()


def test_runners_that_disagree_on_a_capacity_are_refused(
    env: dict[str, str], tmp_path: Path, started: Started
) -> None:
    """A live holder recorded gpu=1: a runner asking gpu with gpu=2 is an error, exit 2.

    Controls: the same capacity waits (exit 3 after its --wait-timeout), and a runner
    that sees another gpu capacity but asks only cpu runs.
    """
    probes = Probes(_env(env, "cpu=4,gpu=1"), tmp_path, started)
    go, marker, result = tmp_path / "go", tmp_path / "marker", tmp_path / "r.xml"
    probes.start("holder", "gpu=1", "--until", go)
    probes.wait_started("holder")
    other = {**probes.env, CAPACITY_ENV: "cpu=4,gpu=2"}
    command = ["touch", str(marker)]
    try:
        disagree = run_cli(_run_args("gpu=1", command, "--wait-timeout", "30", "--junit-xml",
                                     str(result)), other)  # fmt: skip
        agree = run_cli(_run_args("gpu=1", command, "--wait-timeout", "1"), probes.env)
        cpu_only = run_cli(_run_args("cpu=1", [sys.executable, "-c", "pass"]), other)
    finally:
        go.touch()
    probes.finish("holder")
    said = disagree.stdout + disagree.stderr
    assert disagree.returncode == 2, said
    assert not marker.exists(), said
    errors = [line for line in said.splitlines() if "error" in line.lower()]
    assert len(errors) == 1 and "gpu" in errors[0] and CAPACITY_ENV in errors[0], said
    assert "gpu" in result_error(result)
    assert agree.returncode == 3, agree.stdout + agree.stderr
    assert cpu_only.returncode == 0, cpu_only.stdout + cpu_only.stderr


# --- what is seen ----------------------------------------------------------------------------


def test_the_result_file_records_what_was_held_how_long_it_waited_and_the_capacity(
    env: dict[str, str], tmp_path: Path, started: Started
) -> None:
    probes = Probes(_env(env, "cpu=4,mem=8G,gpu=1,sim=2"), tmp_path, started)
    go = tmp_path / "go"
    probes.start("holder", "mem=4096M,cpu=2", "--until", go)
    probes.wait_started("holder")
    probes.start("waiter", "cpu=4", "--hold", 0)
    _wait_queued(probes, "waiter")
    go.touch()
    probes.finish("holder")
    probes.finish("waiter")
    plain = tmp_path / "plain.xml"
    proc = run_cli(["run", "--junit-xml", str(plain), "--", "true"], probes.env)
    assert proc.returncode == 0, proc.stdout + proc.stderr

    held = load_result(probes.result("holder")).properties
    assert held.get("resources") == "cpu=2,mem=4G", held
    assert held.get("capacity") == "cpu=4,mem=8G", held
    assert re.fullmatch(r"\d+\.\d{3}", held.get("resources_waited", "")), held
    waited = load_result(probes.result("waiter")).properties
    assert waited.get("resources") == "cpu=4", waited
    assert waited.get("capacity") == "cpu=4", waited
    assert re.fullmatch(r"\d+\.\d{3}", waited.get("resources_waited", "")), waited
    assert float(waited["resources_waited"]) > 0, waited
    assert "resources" not in load_result(plain).properties  # control: it asked nothing


def test_status_shows_who_holds_and_who_waits_for_resources_and_the_capacity(
    env: dict[str, str], tmp_path: Path, started: Started
) -> None:
    probes = Probes(_env(env, "cpu=4,gpu=1"), tmp_path, started)
    go = tmp_path / "go"
    holder = probes.start("holder", "cpu=2,gpu=1", "--until", go)
    probes.wait_started("holder")
    waiter = probes.start("waiter", "gpu=1")
    try:
        (queued,) = _wait_queued(probes, "waiter")
        _, resources = _status(probes.env)
        text = run_cli(["status"], probes.env)
    finally:
        go.touch()
    probes.finish("holder")
    probes.finish("waiter")

    assert queued.get("resources") == {"gpu": 1}, queued
    capacity = resources.get("capacity")
    assert isinstance(capacity, dict) and capacity.get("cpu") == 4, resources
    assert capacity.get("gpu") == 1, resources
    held = resources.get("held")
    assert isinstance(held, list), resources
    mine = [entry for entry in held if entry.get("pid") == holder.pid]
    assert len(mine) == 1, held
    assert mine[0].get("resources") == {"cpu": 2, "gpu": 1}, mine
    assert "resource_probe" in str(mine[0].get("command")), mine
    assert mine[0].get("user") and mine[0].get("started"), mine
    assert not [entry for entry in held if entry.get("pid") == waiter.pid], held
    assert text.returncode == 0, text.stdout + text.stderr
    assert "cpu=2,gpu=1" in text.stdout and str(holder.pid) in text.stdout, text.stdout


def test_resources_are_released_only_once_the_whole_process_tree_is_gone(
    env: dict[str, str], tmp_path: Path, started: Started
) -> None:
    """The holder's test leaves a child that takes 1 s to die on SIGTERM: the waiter after.

    The waiter is queued before the holder's main process ends, so a release at that
    moment, before the sweep, would let it start within the child's second.
    """
    probes = Probes(_env(env, "gpu=1"), tmp_path, started)
    go = tmp_path / "go"
    child = shlex.join([sys.executable, "-c", SLOW_TO_DIE, str(probes.log), "child"])
    parent = shlex.join(resource_probe.command(probes.log, "parent", "--await", "child", 1,
                                               "--until", go))  # fmt: skip
    args = _run_args("gpu=1", ["sh", "-c", f"{child} & {parent}"], "--junit-xml",
                     str(tmp_path / "holder.xml"))  # fmt: skip
    holder = start_cli(args, probes.env, tmp_path / "holder.log", started)
    poll_until(lambda: "parent" in starts(probes.log) or holder.poll() is not None,
               "the holder's test to start")  # fmt: skip
    probes.start("waiter", "gpu=1")
    _wait_queued(probes, "waiter")
    go.touch()
    assert holder.wait(HUNG) == 0, (tmp_path / "holder.log").read_text()
    probes.finish("waiter")
    order = resource_probe.events(probes.log)
    assert order.index(("end", "parent")) < order.index(("end", "child")), order
    assert order.index(("end", "child")) < order.index(("start", "waiter")), order


def test_a_rerun_that_meets_another_capacity_stops_with_the_attempts_kept(
    env: dict[str, str], lock_dir: Path, tmp_path: Path, started: list[subprocess.Popen[bytes]]
) -> None:
    """Between attempts a runner told another capacity takes a hold: the series ends, said."""
    env = {
        **env,
        CAPACITY_ENV: "gpu=1",
        "ROS_ISOLATED_TEST_DOMAINS": ",".join(map(str, free_ids(2))),
    }
    ready, go, result = tmp_path / "ready", tmp_path / "go", tmp_path / "result.xml"
    script = f"touch {ready}; while [ ! -e {go} ]; do sleep 0.05; done; exit 1"
    log = tmp_path / "runner.log"
    runner = start_cli(
        ["run", "--rerun-failures", "1", "--resources", "gpu=1", "--junit-xml", str(result),
         "--", "sh", "-c", script],
        env,
        log,
        started,
    )  # fmt: skip
    poll_until(lambda: ready.exists() or runner.poll() is not None, "attempt 1 never ran")
    assert ready.exists(), log.read_text()
    other = resource_holds.hold(lock_dir, ["told gpu=2"], {"gpu": 1}, {"gpu": 2}, None)
    assert other is not None
    try:
        go.touch()
        assert runner.wait(timeout=HUNG) == 1, log.read_text()
    finally:
        other.close()
    said = log.read_text()
    assert "Traceback" not in said, said
    assert "attempt 2 did not run: runners disagree on the capacity of gpu" in said, said
    summary = load_result(result)
    assert "runners disagree" in summary.properties["rerun_not_run"], summary.properties
    assert summary.properties["exit"] == "exited with code 1", summary.properties

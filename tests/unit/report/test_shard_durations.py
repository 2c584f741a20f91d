"""``report.shard_durations``: which tests a result file holds by identity, and how long each took.

A RUNNER's file is its ctest test (its ``duration``), pytest's file under the plugin is
its named items (their times); anything else names no test. Several runs merge into the
median, a split's shards into their union.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import time
from pathlib import Path

from helpers.commands import ament_args, run_cli, start_runner
from helpers.processes import DEADLINE, wait_for
from helpers.split_trees import pytest_file, runner_file, split_trees

from ros_isolated_test.report import shard_durations
from ros_isolated_test.report.shard_durations import Gathered, named_tests
from ros_isolated_test.report.tree import read_file, read_tree
from ros_isolated_test.shard.durations import measured
from ros_isolated_test.xunit import serialise
from ros_isolated_test.xunit.model import Case, Outcome, Suite


def _tests(path: Path) -> list[tuple[str, float | None]]:
    item = read_file(path)
    assert item is not None
    return named_tests(item)


def test_a_runner_file_is_its_ctest_test_and_its_duration(tmp_path: Path) -> None:
    path = runner_file(tmp_path, "nav2_util/test_lifecycle", 12.5)
    assert _tests(path) == [("nav2_util/test_lifecycle", 12.5)]


def test_pytest_items_are_named_by_their_property(tmp_path: Path) -> None:
    path = pytest_file(tmp_path, "py_pkg", {"test/test_a.py::test_x": 0.25, "test/t.py::T::y": 2})
    assert sorted(_tests(path)) == [
        ("py_pkg/test/t.py::T::y", 2.0),
        ("py_pkg/test/test_a.py::test_x", 0.25),
    ]


def test_a_file_naming_no_test_a_split_places_gives_none(tmp_path: Path) -> None:
    """Another producer's file (no runner_version, no identity property) names none; so
    does a runner's file of a test that was not run (it measured nothing)."""
    other = tmp_path / "other.xml"
    other.write_bytes(
        serialise.serialize(
            Suite("pkg.t", [Case("pkg.t", "t", 1.0)], 1.0, "2026-01-01T00:00:00", "h")
        )
    )
    assert _tests(other) == []
    not_run = runner_file(tmp_path, "pkg/t", 3.0)
    not_run.write_text(not_run.read_text().replace("exited with code 0", "not run"))
    assert _tests(not_run) == [("pkg/t", None)]


def test_runs_merge_into_the_median_and_shards_into_their_union(tmp_path: Path) -> None:
    tests = {"a/t1": 10.0, "a/t2": 1.0, "b/test/x.py::test_y": 0.5, "b/test/x.py::test_z": 3.0}
    gathered = Gathered()
    for item in read_tree(split_trees(tmp_path / "run1", tests, 3)):
        gathered.add(item)
    assert gathered.durations() == measured(tests)  # the shards: their union
    slower = {key: seconds * 3 for key, seconds in tests.items()}
    for run, times in (("run2", slower), ("run3", tests)):
        for item in read_tree(split_trees(tmp_path / run, times, 2)):
            gathered.add(item)
    # Each test measured three times: 1x, 3x, 1x: the median is 1x.
    assert gathered.durations() == measured(tests)


#: The test (argv: its result file, a state folder): says its PID, waits for ``go``, writes
#: a passing result, says so (``wrote``), then hangs until it is killed.
_PASS_THEN_HANG = """#!/bin/bash
echo $$ > "$2/pid"
while [ ! -e "$2/go" ]; do sleep 0.05; done
echo '<testsuite name="t" tests="1"><testcase classname="t" name="ok"/></testsuite>' > "$1"
: > "$2/wrote"
exec sleep 600
"""
#: How long the harness holds the test back before it may write its pass.
_HELD = 0.3


def test_a_runner_killed_after_its_test_wrote_a_pass_measured_at_least_that_long(
    tmp_path: Path,
    env: dict[str, str],
    runner_script: str,
    started: list[subprocess.Popen[bytes]],
) -> None:
    """Issue 41 item 4: a ctest TIMEOUT's SIGKILL left the placeholder, measured as 0 s.

    Every bound is an order of events: the placeholder is written before the test starts,
    the harness holds the test ``_HELD`` seconds after it started, and kills the runner's
    tree after the test wrote its file; so the test ran at least ``_HELD`` seconds, and
    no longer than the harness watched it.
    """
    script = tmp_path / "pass_then_hang.sh"
    script.write_text(_PASS_THEN_HANG)
    script.chmod(0o755)
    state = tmp_path / "state"
    state.mkdir()
    result = tmp_path / "tree" / "pkg" / "slow.xml"
    before = time.time()
    runner = start_runner(
        runner_script,
        ament_args(result, [str(script), str(result), str(state)]),
        env, tmp_path / "log", started, start_new_session=True,
    )  # fmt: skip
    wait_for(state / "pid")  # the test started: the placeholder is in place already
    time.sleep(_HELD)  # the test's run, which the measurement must see
    (state / "go").touch()
    wait_for(state / "wrote")  # the test wrote "passed", then hangs
    os.killpg(runner.pid, signal.SIGKILL)  # as ctest's TIMEOUT ends the runner's tree
    assert runner.wait(timeout=DEADLINE) == -signal.SIGKILL
    watched = time.time() - before
    assert "the runner was killed before the test ended" in result.read_text()
    durations = tmp_path / "durations.json"
    proc = run_cli(["report", "--durations", str(durations), str(tmp_path / "tree")], env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    seconds = json.loads(durations.read_text())["durations"]["pkg/slow"]
    assert seconds > 0, "a killed test measured as instant"
    assert _HELD <= seconds <= watched * 1.05, (seconds, watched)  # 1.05: two figures kept
    # A tree copied without its times (the copy's all alike, later) cannot say when the
    # test wrote: the test is left out, so a split weighs it as a new one, never as 0 s.
    copy = tmp_path / "copied"
    shutil.copytree(tmp_path / "tree", copy, copy_function=shutil.copyfile)
    later = time.time() + 3600
    for path in (copy / "pkg").iterdir():
        os.utime(path, (later, later))
    runner_file(copy, "pkg/quick", 1.0)  # the control: a test that ended is measured
    copied = tmp_path / "copied.json"
    proc = run_cli(["report", "--durations", str(copied), str(copy)], env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert json.loads(copied.read_text())["durations"] == {"pkg/quick": 1}


def test_an_older_runners_placeholder_measured_nothing_not_zero(tmp_path: Path) -> None:
    """Left by a runner from before ``placeholder_written_at``: its 0 s was never measured."""
    from ros_isolated_test.xunit.placeholder import KILLED

    folder = tmp_path / "pkg"
    folder.mkdir()
    message = f"The test did not generate a result file. If this is all there is, {KILLED}."
    for name, said in (("killed", message), ("skipped", "Test skipped by developer")):
        case = Case.saying(f"pkg.{name}", name, Outcome.ERROR, said)
        properties = {"command": "t", "runner_version": "0.1.0"}
        suite = Suite(f"pkg.{name}", [case], 0.0, "2026-01-01T00:00:00", "h", properties)
        (folder / f"{name}.xml").write_bytes(serialise.serialize(suite))
    assert _tests(folder / "killed.xml") == [("pkg/killed", None)]
    assert _tests(folder / "skipped.xml") == [("pkg/skipped", 0.0)]  # the control


#: Sixteen pytest items that do nothing: each takes well under a millisecond.
_QUICK_ITEMS = "".join(f"def test_{n:02d}():\n    pass\n\n" for n in range(16))


def _case_seconds(junit: Path) -> dict[str, tuple[str, str]]:
    """Each case's identity -> (pytest's ``time``, the plugin's ``ros_isolated_test_seconds``)."""
    from lxml import etree

    from ros_isolated_test.shard.identity import PROPERTY, SECONDS_PROPERTY

    found = {}
    for case in etree.parse(str(junit)).getroot().iter("testcase"):
        props = {p.get("name"): p.get("value") for p in case.iterfind("properties/property")}
        found[str(props[PROPERTY])] = (str(case.get("time")), str(props[SECONDS_PROPERTY]))
    return found


def test_quick_pytest_items_are_measured_to_the_microsecond_and_spread_by_count(
    tmp_path: Path, env: dict[str, str]
) -> None:
    """Issue 41 item 8, through real processes: pytest under the plugin, ``report
    --durations``, ``shard --plan``. pytest's own ``time`` has three decimals (a quick item
    is ``0.000``); the plugin's property keeps six, and the durations file keeps them (two
    figures), so no item is written as 0. Control: the same file without the property is
    read from ``time``, as before."""
    from helpers.pytest_sessions import project, run_pytest

    from ros_isolated_test.shard.durations import load, rounded

    root = project(tmp_path / "pkg", _QUICK_ITEMS)
    junit = tmp_path / "results" / "pytest.xml"
    done = run_pytest(root, env, f"--junit-xml={junit}", "test")
    assert done.returncode == 0, done.stdout + done.stderr
    cases = _case_seconds(junit)
    assert len(cases) == 16
    for time_text, seconds_text in cases.values():
        assert len(time_text.split(".")[1]) == 3 and len(seconds_text.split(".")[1]) == 6
        # The same measure (setup, call and teardown), to more decimals.
        assert abs(float(seconds_text) - float(time_text)) <= 0.0005 + 1e-9
        assert float(seconds_text) > 0
    written = tmp_path / "durations.json"
    proc = run_cli(["report", "--durations", str(written), str(junit.parent)], env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    micros = load(written).micros
    assert micros == {key: rounded(float(seconds)) for key, (_t, seconds) in cases.items()}
    assert all(micros.values())  # none written as 0
    for line in written.read_text().splitlines()[3:-2]:  # one test a line: at most 6 decimals
        assert "e" not in line.split(": ")[1] and len(line.rstrip(",").split(".")[-1]) <= 6
    # The plan from that file: the quick items by count over 3 shares (those a loaded
    # machine slowed past a millisecond, weighed first, are evened out by the rest).
    proc = run_cli(["shard", "--plan", "--json", "--durations", str(written), "--total", "3"], env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    counts = [len(share["tests"]) for share in json.loads(proc.stdout)["shares"]]
    assert sum(counts) == 16 and max(counts) - min(counts) <= 1, counts
    # Control: without the plugin's property, pytest's three decimals are all there is.
    stripped = tmp_path / "stripped" / "pytest.xml"
    stripped.parent.mkdir()
    text = junit.read_text()
    stripped.write_text(re.sub(r'<property name="ros_isolated_test_seconds" value="[^"]*" */>',
                               "", text))  # fmt: skip
    assert "ros_isolated_test_seconds" in text and "ros_isolated_test_seconds" not in (
        stripped.read_text()
    )
    from_time = tmp_path / "from_time.json"
    proc = run_cli(["report", "--durations", str(from_time), str(stripped.parent)], env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert load(from_time).micros == {key: rounded(float(t)) for key, (t, _s) in cases.items()}


def test_tests_in_a_tree_are_the_runners_tests_and_other_files_name_none(
    env: dict[str, str], tmp_path: Path
) -> None:
    tree = tmp_path / "tree"
    ran = run_cli(
        ["run", "--junit-xml", str(tree / "pkg" / "t.xml"), "--package-name", "pkg", "--", "true"],
        env,
        cwd=tmp_path,
    )
    assert ran.returncode == 0, ran.stderr
    (tree / "other.xml").write_text(
        '<testsuite name="x" tests="1"><testcase name="c"/></testsuite>'
    )
    found, unreadable = shard_durations.tests_in((tree,))
    assert len(found) == 1 and next(iter(found)).startswith("pkg"), found
    assert unreadable == []

"""Reruns where needed: ``run --rerun-flaky N`` / ``ROS_ISOLATED_TEST_RERUNS_FLAKY=N``.

The same test, failing its first attempt and passing the next, run through the real
``run``: rerun (and passing) only when the test history calls it flaky; a test the
history calls stable or broken, or does not know, fails at once, its one attempt on
record (the controls). Every attempt stays in the result file as with reruns today.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from helpers.commands import run_cli
from helpers.results import load_result
from helpers.split_trees import START, runner_file

from ros_isolated_test.history import record
from ros_isolated_test.shard.durations import measured, write

HISTORY_ENV = "ROS_ISOLATED_TEST_HISTORY"
FLAKY_ENV = "ROS_ISOLATED_TEST_RERUNS_FLAKY"
#: What the history holds of each test: one letter per run, P passed, F failed.
HISTORY = {"flaky_t": "PFPF", "stable_t": "PPPP", "broken_t": "FFFF"}
#: Fails its first attempt, passes the next (a mark file per test).
SCRIPT = 'if [ -e "$MARK" ]; then exit 0; fi; touch "$MARK"; echo first; exit 1'


def _history(tmp_path: Path) -> Path:
    db = tmp_path / "history.sqlite3"
    for number in range(4):
        tree = tmp_path / "before" / f"run{number}"
        for name, outcomes in HISTORY.items():
            path = runner_file(tree, f"pkg/{name}", 1.0, started=START + 100 * number)
            if outcomes[number] == "F":
                case = 'time="1.000"'
                failed = f'{case}><failure message="no">no</failure></testcase>'
                path.write_text(path.read_text().replace(f"{case}/>", failed))
        assert record.record(db, [tree]) is True
    return db


def _run(
    tmp_path: Path, env: dict[str, str], name: str, *options: str
) -> tuple[int, str, dict[str, str]]:
    result = tmp_path / "now" / "pkg" / f"{name}.xml"
    proc = run_cli(
        ["run", "--junit-xml", str(result), "--package-name", "pkg", *options,
         "--", "sh", "-c", SCRIPT],
        {**env, "MARK": str(tmp_path / f"mark-{name}-{len(options)}")},
    )  # fmt: skip
    return proc.returncode, proc.stdout + proc.stderr, load_result(result).properties


@pytest.mark.parametrize("how", ["option", "variable"])
def test_only_a_test_the_history_calls_flaky_is_rerun(
    tmp_path: Path, env: dict[str, str], how: str
) -> None:
    db = _history(tmp_path)
    given = {**env, HISTORY_ENV: str(db)}
    options: tuple[str, ...] = ("--rerun-flaky", "2")
    if how == "variable":
        given[FLAKY_ENV], options = "2", ()
    code, said, properties = _run(tmp_path, given, "flaky_t", *options)
    assert code == 0, said
    assert "the test history calls pkg/flaky_t flaky: running it again up to 2" in said
    assert properties["attempts"] == "2" and properties["rerun_flaky"] == "2"
    assert "attempt_1.exit" in properties  # the failed first attempt stays on record
    # Controls: the same test, stable, broken or unknown to the history, fails at once.
    for name in ("stable_t", "broken_t", "new_t"):
        code, said, properties = _run(tmp_path, given, name, *options)
        assert code == 1, (name, said)
        assert "calls" not in said and properties["attempts"] == "1", name


def test_without_a_history_nothing_is_rerun_and_a_bad_count_is_refused(
    tmp_path: Path, env: dict[str, str]
) -> None:
    absent = {**env, HISTORY_ENV: str(tmp_path / "none.sqlite3"), FLAKY_ENV: "2"}
    code, said, properties = _run(tmp_path, absent, "flaky_t")
    assert code == 1 and properties["attempts"] == "1", said
    bad = run_cli(["run", "--", "true"], {**env, FLAKY_ENV: "lots"})
    assert bad.returncode == 2
    assert f"{FLAKY_ENV}='lots' is not a number of reruns" in bad.stderr
    # Control: --rerun-failures reruns it whatever the history says.
    code, said, properties = _run(tmp_path, absent, "plain", "--rerun-failures", "1")
    assert code == 0 and properties["attempts"] == "2", said


def _imports(argv: list[str], env: dict[str, str], cwd: Path) -> tuple[int, set[str]]:
    """The exit code of ``python -X importtime ARGV`` and the modules it imported."""
    proc = subprocess.run(
        [sys.executable, "-X", "importtime", *argv],
        env=env, cwd=cwd, capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    names = {
        line.rsplit("|", 1)[1].strip()
        for line in proc.stderr.splitlines()
        if line.startswith("import time:") and "|" in line
    }
    return proc.returncode, names


def test_sqlite_is_loaded_only_after_a_failure_and_never_for_a_json_durations_file(
    tmp_path: Path, env: dict[str, str], runner_script: str
) -> None:
    durations = tmp_path / "durations.json"
    write(durations, measured({"pkg/t": 1.0}))
    given = {
        **env,
        FLAKY_ENV: "2",
        "ROS_ISOLATED_TEST_SHARD": "1/1",
        "ROS_ISOLATED_TEST_DURATIONS": str(durations),
    }
    args = ["-u", runner_script, str(tmp_path / "pkg" / "t.xml"), "--package-name", "pkg"]
    code, names = _imports(
        [*args, "--generate-result-on-success", "--command", "true"], given, tmp_path
    )
    assert code == 0
    assert "ros_isolated_test.shard.plan" in names, "the check must see the split decided"
    assert "sqlite3" not in names and "ros_isolated_test.history.stats" not in names
    # Control: a failure asks the history, and only then loads it.
    code, names = _imports([*args, "--command", "false"], given, tmp_path)
    assert code == 1
    assert "sqlite3" in names and "ros_isolated_test.history.stats" in names

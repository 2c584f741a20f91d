"""The test history end to end: four real runs recorded, read, merged, and recorded at once.

Each run is ``ros-isolated-test run --junit-xml`` into a tree of its own: a test that
always passes, one that always fails, one failing on runs 1 and 3, one failing its
first attempt and passing on a rerun in every run (``--rerun-failures 1``).
"""

from __future__ import annotations

import json
import sqlite3
import subprocess
from pathlib import Path

import pytest
from helpers.commands import run_cli, start_cli

#: The tests of a run: name -> the shell command, given the run's number and folder.
_SCRIPTS = {
    "always_passes": "exit 0",
    "always_fails": "echo broken; exit 1",
    "odd_runs_fail": 'if [ "$RUN" = 1 ] || [ "$RUN" = 3 ]; then echo odd; exit 1; fi',
    "passes_on_rerun": 'if [ -e "$MARK" ]; then exit 0; fi; touch "$MARK"; echo first; exit 1',
}


def _run_tree(root: Path, number: int, env: dict[str, str], names: dict[str, str]) -> Path:
    """One run of ``names``' tests into ``root/run<number>``, through the real runner."""
    tree = root / f"run{number}"
    for name, script in names.items():
        mark = root / f"mark-{number}-{name}"
        proc = run_cli(
            [
                "run",
                "--junit-xml",
                str(tree / "pkg" / f"{name}.xml"),
                "--package-name",
                "pkg",
                "--rerun-failures",
                "1" if name == "passes_on_rerun" else "0",
                "--",
                "sh",
                "-c",
                script,
            ],
            {**env, "RUN": str(number), "MARK": str(mark)},
            cwd=root,
        )
        assert proc.returncode in (0, 1), proc.stderr
    return tree


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory, module_env: dict[str, str]) -> list[Path]:
    """The four runs' trees, oldest first."""
    root = tmp_path_factory.mktemp("history-runs")
    return [_run_tree(root, number, module_env, _SCRIPTS) for number in (1, 2, 3, 4)]


def _history(db: Path, env: dict[str, str], *args: str) -> subprocess.CompletedProcess[str]:
    return run_cli(["history", *args, "--db", str(db)], env)


def _record(db: Path, env: dict[str, str], *trees: Path) -> None:
    proc = run_cli(["history", "record", "--db", str(db), *map(str, trees)], env)
    assert proc.returncode == 0 and not proc.stderr, proc.stderr


def _shown(db: Path, env: dict[str, str]) -> list[dict[str, object]]:
    proc = _history(db, env, "--json")
    assert proc.returncode == 0, proc.stderr
    found: list[dict[str, object]] = json.loads(proc.stdout)
    return found


def test_four_runs_tell_stable_broken_and_flaky(
    runs: list[Path], module_env: dict[str, str], tmp_path: Path
) -> None:
    db = tmp_path / "history.sqlite3"
    for tree in runs:
        _record(db, module_env, tree)
    shown = {item["test"]: item for item in _shown(db, module_env)}
    assert {name: item["status"] for name, item in shown.items()} == {
        "pkg/always_passes": "stable",
        "pkg/always_fails": "broken",
        "pkg/odd_runs_fail": "flaky",
        "pkg/passes_on_rerun": "flaky",
    }
    assert all(item["runs"] == 4 for item in shown.values())
    since = shown["pkg/always_fails"]["broken_since"]
    assert isinstance(since, dict) and since["run"] == 1
    assert shown["pkg/odd_runs_fail"]["strip"] == "FPFP"
    assert shown["pkg/passes_on_rerun"]["strip"] == "ffff"
    assert shown["pkg/passes_on_rerun"]["flaky"] == 4
    # Worst first: the broken test leads.
    assert next(iter(shown)) == "pkg/always_fails"
    assert [item["test"] for item in _shown(db, module_env) if item["status"] == "flaky"] == [
        item["test"] for item in json.loads(_history(db, module_env, "--json", "--flaky").stdout)
    ]

    # Recording run 2 again changes nothing; recording it first (the control) did.
    exported = _history(db, module_env, "export", "--jsonl")
    _record(db, module_env, runs[1])
    assert _history(db, module_env, "export", "--jsonl").stdout == exported.stdout
    assert len(exported.stdout.splitlines()) == 4 * 4 + 4  # a rerun's two attempts each run


def test_two_databases_merged_read_as_one(
    runs: list[Path], module_env: dict[str, str], tmp_path: Path
) -> None:
    one, first, second, merged = (tmp_path / f"{name}.sqlite3" for name in ("one", "a", "b", "m"))
    for tree in runs:
        _record(one, module_env, tree)
    _record(first, module_env, *runs[:1])
    _record(first, module_env, runs[1])
    _record(second, module_env, runs[2])
    _record(second, module_env, runs[3])
    assert _shown(first, module_env) != _shown(one, module_env)  # control: halves differ
    proc = run_cli(["history", "merge", "--db", str(merged), str(first), str(second)], module_env)
    assert proc.returncode == 0, proc.stderr
    assert _shown(merged, module_env) == _shown(one, module_env)
    again = run_cli(["history", "merge", "--db", str(merged), str(first), str(second)], module_env)
    assert again.returncode == 0 and again.stdout.startswith("0 new run(s)"), again.stdout
    assert _shown(merged, module_env) == _shown(one, module_env)


def test_eight_recorders_at_once_lose_nothing(
    module_env: dict[str, str], tmp_path: Path, started: list[subprocess.Popen[bytes]]
) -> None:
    trees = [
        _run_tree(tmp_path, number, module_env, {"always_passes": "exit 0"}) for number in range(8)
    ]
    db = tmp_path / "history.sqlite3"
    logs = [tmp_path / f"record{k}.log" for k in range(8)]
    recorders = [
        start_cli(["history", "record", "--db", str(db), str(tree)], module_env, log, started)
        for tree, log in zip(trees, logs, strict=True)
    ]
    assert [recorder.wait(timeout=120) for recorder in recorders] == [0] * 8
    assert all(log.read_text() == "" for log in logs), [log.read_text() for log in logs]
    (item,) = _shown(db, module_env)
    assert item["runs"] == 8 and item["status"] == "stable"


def _failing_run(
    db: Path, env: dict[str, str], tmp_path: Path, name: str
) -> tuple[subprocess.CompletedProcess[str], str]:
    """A failing test run with ``ROS_ISOLATED_TEST_HISTORY=db``: its process and result file."""
    result = tmp_path / name / "pkg" / "always_fails.xml"
    proc = run_cli(
        ["run", "--junit-xml", str(result), "--package-name", "pkg", "--", "sh", "-c", "exit 3"],
        {**env, "ROS_ISOLATED_TEST_HISTORY": str(db)},
    )
    return proc, result.read_text()


def _counts(text: str) -> str:
    """The root element of a result file: its counts, without times."""
    root = text.split("<testsuite ", 1)[0]
    return root.split(" time=", 1)[0]


@pytest.mark.parametrize("damage", ["corrupt", "foreign"])
def test_a_damaged_database_is_one_warning_and_the_same_result(
    damage: str, env: dict[str, str], tmp_path: Path
) -> None:
    good = tmp_path / "good.sqlite3"
    control, control_result = _failing_run(good, env, tmp_path, "control")
    assert control.returncode == 3 and "warning" not in control.stderr
    assert _shown(good, env)[0]["runs"] == 1  # control: it recorded

    bad = tmp_path / "bad name.sqlite3"
    if damage == "corrupt":
        bad.write_bytes(b"SQLite format 3\0" + b"\xff" * 4000)
    else:
        with sqlite3.connect(bad) as other:
            other.execute("CREATE TABLE mine (x)")
        other.close()
    before = bad.read_bytes()
    proc, result = _failing_run(bad, env, tmp_path, "damaged")
    assert proc.returncode == control.returncode
    assert _counts(result) == _counts(control_result)
    warnings = [line for line in proc.stderr.splitlines() if "warning" in line]
    assert len(warnings) == 1 and str(bad) in warnings[0], proc.stderr
    assert "Traceback" not in proc.stderr
    assert bad.read_bytes() == before  # never changed
    recorded = run_cli(["history", "record", "--db", str(bad), str(tmp_path / "damaged")], env)
    assert recorded.returncode == 0 and len(recorded.stderr.splitlines()) == 1
    shown = _history(bad, env)
    assert shown.returncode == 1 and len(shown.stderr.splitlines()) == 1, shown.stderr


def test_a_read_only_database_is_one_warning_and_the_same_result(
    env: dict[str, str], traversable_dir: Path
) -> None:
    """The runner as nobody; the database root's, readable by all, writable by none else."""
    locks = traversable_dir / "locks"
    locks.mkdir(mode=0o777)
    locks.chmod(0o777)
    as_nobody = {**env, "ROS_ISOLATED_TEST_LOCK_DIR": str(locks), "HOME": str(traversable_dir)}
    nobody = {"user": 65534, "group": 65534, "extra_groups": [], "cwd": traversable_dir}

    def failing(db: Path, name: str) -> tuple[subprocess.CompletedProcess[str], str]:
        folder = traversable_dir / name
        folder.mkdir(mode=0o777)
        folder.chmod(0o777)
        result = folder / "always_fails.xml"
        proc = run_cli(
            [
                "run",
                "--junit-xml",
                str(result),
                "--package-name",
                "pkg",
                "--",
                "sh",
                "-c",
                "exit 3",
            ],
            {**as_nobody, "ROS_ISOLATED_TEST_HISTORY": str(db)},
            **nobody,
        )
        return proc, result.read_text()

    writable = traversable_dir / "writable.sqlite3"
    writable.touch(mode=0o666)
    writable.chmod(0o666)
    control, control_result = failing(writable, "control")
    assert control.returncode == 3 and "warning" not in control.stderr, control.stderr
    assert _shown(writable, env)[0]["runs"] == 1  # control: nobody recorded into it

    db = traversable_dir / "read-only.sqlite3"
    _record(db, env, traversable_dir / "control")
    db.chmod(0o644)
    before = db.read_bytes()
    proc, result = failing(db, "read-only")
    assert proc.returncode == control.returncode
    assert _counts(result) == _counts(control_result)
    warnings = [line for line in proc.stderr.splitlines() if "warning" in line]
    assert len(warnings) == 1 and str(db) in warnings[0], proc.stderr
    assert "Traceback" not in proc.stderr
    assert db.read_bytes() == before

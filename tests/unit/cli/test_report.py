"""``cli.report``: ``ros-isolated-test report`` over a split's trees, and ``--durations``.

Run as a user runs it, on the trees a split's machines leave (``helpers.split_trees``):
the merge counts each test once and exits 1, naming the problem, when a share is
missing; ``--durations FILE`` writes the file the next split plans from, whose plan
places every test the trees hold. Each mistake is one line with its exit code, beside
its control.
"""

from __future__ import annotations

import json
from pathlib import Path

from helpers.commands import run_cli
from helpers.split_trees import runner_file, split_trees

from ros_isolated_test.shard.durations import load, measured
from ros_isolated_test.shard.spec import SHARD_ENV

TESTS = {
    **{f"nav_{p}/test_{n}": 1.0 + 10 * n for p in range(3) for n in range(4)},
    **{f"py_pkg/test/test_{n}.py::test_case": 0.5 + n for n in range(5)},
}


def test_the_merge_counts_each_test_once_and_names_a_missing_share(
    env: dict[str, str], tmp_path: Path
) -> None:
    trees = split_trees(tmp_path, TESTS, 3)
    merged = run_cli(["report", *map(str, trees)], env)
    assert merged.returncode == 0, merged.stdout + merged.stderr
    assert f"Summary: {len(TESTS)} tests, 0 errors, 0 failures, 0 skipped" in merged.stdout
    assert "Shards: 1/3 (plan count), 2/3, 3/3\n" in merged.stdout
    as_json = json.loads(run_cli(["report", "--json", *map(str, trees)], env).stdout)
    assert as_json["total"]["tests"] == len(TESTS)
    assert [found["shard"] for found in as_json["shards"]["found"]] == ["1/3", "2/3", "3/3"]
    assert as_json["shards"]["problems"] == []
    short = run_cli(["report", str(trees[0]), str(trees[2])], env)
    assert short.returncode == 1
    assert "The split's results are incomplete (1 problem(s)):\n- shard 2 of 3 left no results" in (
        short.stdout
    )
    problems = json.loads(run_cli(["report", "--json", str(trees[0]), str(trees[2])], env).stdout)
    assert problems["shards"]["problems"][0].startswith("shard 2 of 3 left no results")


def test_a_machines_own_report_expects_its_share_and_a_bad_share_is_named(
    env: dict[str, str], tmp_path: Path
) -> None:
    trees = split_trees(tmp_path, TESTS, 3)
    own = run_cli(["report", str(trees[1])], {**env, SHARD_ENV: "2/3"})
    assert own.returncode == 0, own.stdout
    assert run_cli(["report", str(trees[1])], env).returncode == 1  # the control: a merge
    bad = run_cli(["report", str(trees[1])], {**env, SHARD_ENV: "2 of 3"})
    assert bad.returncode == 2
    assert bad.stderr.startswith("ros-isolated-test: error: ROS_ISOLATED_TEST_SHARD='2 of 3' is")


def test_durations_are_written_from_a_splits_trees_and_plan_every_test(
    env: dict[str, str], tmp_path: Path
) -> None:
    trees = split_trees(tmp_path / "run", TESTS, 3)
    written = tmp_path / "durations.json"
    proc = run_cli(["report", "--durations", str(written), *map(str, trees)], env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    durations = load(written)
    assert durations == measured(TESTS)
    files = sum(len(list(tree.glob("**/*.xml"))) for tree in trees)
    assert proc.stdout.startswith(f"{written}: {len(TESTS)} tests' durations from ")
    assert proc.stdout.endswith(f" of {files} result file(s) (plan {durations.fingerprint})\n")
    # The next split plans from it: every test in exactly one share, balanced.
    balanced = split_trees(tmp_path / "next", TESTS, 3, durations)
    assert run_cli(["report", *map(str, balanced)], env).returncode == 0
    plan = run_cli(
        ["shard", "--plan", "--json", "--durations", str(written), "--total", "3",
         *map(str, trees)],
        env,
    )  # fmt: skip
    shown = json.loads(plan.stdout)
    assert shown["not_in_durations"] == 0 and shown["not_in_trees"] == []
    assert shown["longest_share_seconds"] <= 1.1 * shown["lower_bound_seconds"]


def test_durations_mistakes_are_one_line(env: dict[str, str], tmp_path: Path) -> None:
    trees = split_trees(tmp_path, {"a/t": 1.0}, 1)
    out = tmp_path / "d.json"
    with_page = run_cli(["report", "--durations", str(out), "--html", "p.html", str(trees[0])], env)
    assert with_page.returncode == 2 and "--durations writes the durations file alone" in (
        with_page.stderr
    )
    empty = tmp_path / "empty"
    (empty / "pkg").mkdir(parents=True)
    (empty / "pkg" / "other.xml").write_text('<testsuite name="x"><testcase name="y"/></testsuite>')
    nothing = run_cli(["report", "--durations", str(out), str(empty)], env)
    assert nothing.returncode == 2 and not out.exists()
    assert nothing.stderr.startswith(f"ros-isolated-test: error: no test's duration in {empty}")
    (tmp_path / "a-file").write_text("")
    under_a_file = tmp_path / "a-file" / "d.json"
    unwritable = run_cli(["report", "--durations", str(under_a_file), str(trees[0])], env)
    assert unwritable.returncode == 2
    (line,) = unwritable.stderr.splitlines()
    assert line.startswith(f"ros-isolated-test: error: --durations {under_a_file}: cannot write")
    in_the_way = f"{under_a_file.parent} is a file, not a folder"
    assert line.endswith(f": {in_the_way}; name a path in a folder instead"), line
    # The control: the same tree, a writable file.
    runner_file(empty, "pkg/t", 2.0)
    assert run_cli(["report", "--durations", str(out), str(empty)], env).returncode == 0
    assert load(out) == measured({"pkg/t": 2.0})

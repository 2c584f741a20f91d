"""``cli.shard``: ``ros-isolated-test shard --plan``, run as a user runs it.

The plan a user reads before paying for machines: from a durations file, with the tests
of result trees the file does not know, as text and JSON, the same from every process;
every mistake one line and exit 2, beside its control.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from helpers import result_tree
from helpers.commands import run_cli, the_error_line

from ros_isolated_test.shard.durations import DURATIONS_ENV, measured, write
from ros_isolated_test.shard.identity import spread

TESTS = {
    "nav2_util/test_long": 300,
    "nav2_util/test_mid": 40,
    "msgs/test_a": 20,
    "msgs/test_b": 5,
    "py_pkg/test/test_node.py::test_talks": 2,
}


@pytest.fixture
def durations_file(tmp_path: Path) -> Path:
    path = tmp_path / "durations.json"
    write(path, measured(TESTS))
    return path


def test_help_explains_the_plan_the_bound_and_the_trees(env: dict[str, str]) -> None:
    proc = run_cli(["shard", "--help"], env)
    assert proc.returncode == 0
    said = " ".join(proc.stdout.split())
    for words in (
        "lower bound",
        "the larger of the total / N and the longest test",
        "TREE...",
        "weighed as the file's median",
        "by count",
        "ROS_ISOLATED_TEST_DURATIONS",
        "--json",
    ):
        assert words in said, words
    listed = run_cli(["--help"], env)
    assert "shard" in listed.stdout  # the group lists the command


def test_the_plan_is_printed_from_the_file(env: dict[str, str], durations_file: Path) -> None:
    proc = run_cli(["shard", "--plan", "--durations", str(durations_file), "--total", "2"], env)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""
    lines = proc.stdout.splitlines()
    assert lines[0].startswith(f"Plan for 2 shares from the durations file {durations_file} ")
    assert "lower bound 300.0 s" in lines[1]
    assert "Share 1/2: 300.0 s expected, 1 test" in lines
    assert "Share 2/2: 67.0 s expected, 4 tests" in lines


def test_the_variable_names_the_file_when_the_option_does_not(
    env: dict[str, str], durations_file: Path
) -> None:
    proc = run_cli(["shard", "--plan", "--total", "2"], {**env, DURATIONS_ENV: str(durations_file)})
    assert proc.returncode == 0, proc.stderr
    assert "Share 2/2: 67.0 s expected" in proc.stdout
    # The option wins: the variable is then not read.
    bad = {**env, DURATIONS_ENV: "/nowhere.json"}
    proc = run_cli(["shard", "--plan", "--total", "2", "--durations", str(durations_file)], bad)
    assert proc.returncode == 0, proc.stderr
    # Control: alone, the variable's missing file is the error, named by the variable.
    proc = run_cli(["shard", "--plan", "--total", "2"], bad)
    assert proc.returncode == 2
    assert the_error_line(proc).startswith(
        f"ros-isolated-test: error: {DURATIONS_ENV}=/nowhere.json: cannot open it"
    )


def test_a_relative_variable_is_refused_as_the_runners_refuse_it(
    env: dict[str, str], durations_file: Path
) -> None:
    """The plan shown is the one the runners would compute, so the same rule holds."""
    relative = {**env, DURATIONS_ENV: durations_file.name}
    proc = run_cli(["shard", "--plan", "--total", "2"], relative, cwd=durations_file.parent)
    assert proc.returncode == 2
    assert f"{DURATIONS_ENV}={durations_file.name} is not an absolute path" in the_error_line(proc)
    # Control: the same file as an option, relative to here, is read.
    argv = ["shard", "--plan", "--total", "2", "--durations", durations_file.name]
    assert run_cli(argv, relative, cwd=durations_file.parent).returncode == 0


def test_three_processes_print_the_same_plan(env: dict[str, str], durations_file: Path) -> None:
    argv = ["shard", "--plan", "--durations", str(durations_file), "--total", "3"]
    printed = {run_cli(argv, {**env, "PYTHONHASHSEED": seed}).stdout for seed in ("1", "2", "3")}
    assert len(printed) == 1
    assert "Share 3/3" in printed.pop()


def test_the_trees_add_the_tests_the_file_does_not_know(
    env: dict[str, str], durations_file: Path, tmp_path: Path
) -> None:
    tree = tmp_path / "build"
    # A test the real runner ran, shaped as colcon leaves it; and made-up runner results.
    result = tree / "new_pkg" / "test_results" / "new_pkg" / "test_fresh.xunit.xml"
    ran = run_cli(
        ["run", "--junit-xml", str(result), "--package-name", "new_pkg", "--", "true"], env
    )
    assert ran.returncode == 0, ran.stderr
    result_tree.write_tree(tree, 3, 1, packages=1)  # pkg_000/test_00000 ... 00002
    # A producer's own file names no test: it is left out.
    (tree / "py_pkg").mkdir()
    (tree / "py_pkg" / "pytest.xml").write_text(
        '<testsuites><testsuite name="pytest"><testcase classname="a" name="b"/></testsuite>'
        "</testsuites>"
    )
    proc = run_cli(
        [
            "shard",
            "--plan",
            "--durations",
            str(durations_file),
            "--total",
            "4",
            "--json",
            str(tree),
        ],
        env,
    )
    assert proc.returncode == 0, proc.stderr
    document = json.loads(proc.stdout)
    new = {
        test["identity"]: share["share"]
        for share in document["shares"]
        for test in share["tests"]
        if not test["known"]
    }
    expected = [
        "new_pkg/test_fresh",
        "pkg_000/test_00000",
        "pkg_000/test_00001",
        "pkg_000/test_00002",
    ]
    assert sorted(new) == expected
    # Each where a runner would put it: by its identity's hash.
    assert all(new[identity] == f"{spread(identity, 4)}/4" for identity in expected)
    assert document["not_in_durations"] == 4
    assert document["median_seconds"] == 20.0
    assert sorted(document["not_in_trees"]) == sorted(TESTS)  # none of the file's ran there


def test_by_count_from_trees_alone(env: dict[str, str], tmp_path: Path) -> None:
    result_tree.write_tree(tmp_path, 6, 1, packages=2)
    proc = run_cli(["shard", "--plan", "--total", "2", str(tmp_path)], env)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("Plan for 2 shares by count (no durations): 6 tests")


@pytest.mark.parametrize(
    ("argv", "said"),
    [
        (["--total", "2", "--durations", "{file}"], "say what to show: --plan"),
        (["--plan", "--total", "2"], "nothing to plan: give --durations FILE, or result trees"),
        (["--plan", "--durations", "{file}"], "Missing option '--total'"),
        (["--plan", "--total", "0", "--durations", "{file}"], "0 is not in the range 1<=x<=1000"),
        (["--plan", "--total", "1001", "--durations", "{file}"], "1001 is not in the range"),
        (["--plan", "--total", "2", "/nowhere/tree"], "'/nowhere/tree' does not exist"),
    ],
)
def test_a_usage_error_is_one_line_and_exit_2(
    env: dict[str, str], durations_file: Path, argv: list[str], said: str
) -> None:
    proc = run_cli(["shard", *(word.format(file=durations_file) for word in argv)], env)
    assert proc.returncode == 2
    line = the_error_line(proc)
    assert said in line
    assert line.endswith("; see ros-isolated-test shard --help")
    assert proc.stdout == ""


def test_a_bad_durations_file_is_one_line_and_exit_2(env: dict[str, str], tmp_path: Path) -> None:
    bad = tmp_path / "durations.json"
    bad.write_text('{"version": 1, "durations": {"p/t": -1}}')
    proc = run_cli(["shard", "--plan", "--durations", str(bad), "--total", "2"], env)
    assert proc.returncode == 2
    assert the_error_line(proc) == (
        f"ros-isolated-test: error: --durations {bad}: test 'p/t': -1 seconds is negative; name "
        "a durations file written by ros-isolated-test (format version 1), or leave out "
        "--durations to split by count"
    )
    assert proc.stdout == ""
    # Control: the value made right is read.
    bad.write_text('{"version": 1, "durations": {"p/t": 1}}')
    assert (
        run_cli(["shard", "--plan", "--durations", str(bad), "--total", "2"], env).returncode == 0
    )

"""``runner.shard``: a split's step of the run, through the RUNNER and ``run`` as real processes.

A test of another share runs nothing, leaves no result file (a stale one goes) but the
machine's record, says why in one line and exits with its skip code (77 when it has
none); the share that runs it records the share in its result. A test that ran and
exited 77 with no skip code of its own fails (RUNNER mode). Every bad value is a usage
error naming the variable or option, with its result file. Each beside its control.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from helpers.commands import ament, run_cli
from helpers.results import load_result

from ros_isolated_test.shard.durations import DURATIONS_ENV, measured, write
from ros_isolated_test.shard.selection import select
from ros_isolated_test.shard.spec import SHARD_ENV

TEST = ("pkg", "t")


def _shares(total: int = 2) -> tuple[str, str]:
    """(the share that runs pkg/t, another share), by count."""
    runs = select({SHARD_ENV: f"1/{total}"})
    assert runs is not None
    index = runs.share_of(*TEST)
    other = index % total + 1
    return f"{index}/{total}", f"{other}/{total}"


def _touch(marker: Path) -> list[str]:
    return ["touch", str(marker)]


def test_a_test_of_another_share_runs_nothing_and_leaves_no_result(
    tmp_path: Path, env: dict[str, str], runner_script: str
) -> None:
    here, elsewhere = _shares()
    result = tmp_path / "pkg" / "t.xml"
    result.parent.mkdir()
    result.write_text("<testsuite name='stale'/>")  # a restored build folder's
    marker = tmp_path / "ran"
    skipped = ament(
        runner_script, result, _touch(marker), {**env, SHARD_ENV: elsewhere},
        "--generate-result-on-success", cwd=tmp_path,
    )  # fmt: skip
    assert skipped.returncode == 77, skipped.stdout + skipped.stderr
    assert not marker.exists() and not result.exists()
    (line,) = skipped.stdout.splitlines()
    assert line == f"ros-isolated-test: not in shard {elsewhere} (shard {here} runs it; by count)"
    assert skipped.stderr == ""
    record = json.loads((result.parent / f"ros_isolated_test_shard-{elsewhere[0]}-of-2.json")
                        .read_text())  # fmt: skip
    assert (record["shard"], record["plan"]) == (elsewhere, "count")
    # The control: the share that runs it runs it, and its result says which share.
    ran = ament(
        runner_script, result, _touch(marker), {**env, SHARD_ENV: here},
        "--generate-result-on-success", cwd=tmp_path,
    )  # fmt: skip
    assert ran.returncode == 0, ran.stdout + ran.stderr
    assert marker.exists()
    properties = load_result(result).properties
    assert (properties["shard"], properties["shard_plan"]) == (here, "count")
    assert (result.parent / f"ros_isolated_test_shard-{here[0]}-of-2.json").is_file()


@pytest.mark.parametrize(
    ("options", "code"),
    [(["--skip-return-code", "5"], 5), (["--skip-test"], 0), ([], 77)],
    ids=["its-own-code", "skip-test", "none"],
)
def test_a_test_of_another_share_exits_with_its_own_skip_code(
    tmp_path: Path, env: dict[str, str], runner_script: str, options: list[str], code: int
) -> None:
    _here, elsewhere = _shares()
    proc = ament(
        runner_script, tmp_path / "pkg" / "t.xml", _touch(tmp_path / "ran"),
        {**env, SHARD_ENV: elsewhere}, *options, cwd=tmp_path,
    )  # fmt: skip
    assert proc.returncode == code, proc.stdout + proc.stderr
    assert not (tmp_path / "ran").exists()


def test_a_test_that_ran_and_exited_77_fails_unless_77_is_its_own_skip_code(
    tmp_path: Path, env: dict[str, str], runner_script: str
) -> None:
    """ctest reads 77 as skipped for every test the include registered: one that ran and
    ended so is failed (1), its result keeping 77. Controls: with --skip-return-code 77
    it is the test's own skip; through ``run`` the command's code is kept."""
    result = tmp_path / "pkg" / "t.xml"
    command = ["sh", "-c", "exit 77"]
    failed = ament(runner_script, result, command, env, cwd=tmp_path)
    assert failed.returncode == 1, failed.stdout + failed.stderr
    assert "the test exited 77, which ctest reads as skipped" in failed.stdout
    assert load_result(result).properties["exit"] == "exited with code 77"
    own = ament(runner_script, result, command, env, "--skip-return-code", "77", cwd=tmp_path)
    assert own.returncode == 77
    assert load_result(result).only.outcome == "skipped"
    shell = run_cli(["run", "--", *command], env, cwd=tmp_path)
    assert shell.returncode == 77


@pytest.mark.parametrize(
    ("variable", "value", "says"),
    [
        (SHARD_ENV, "0/4", "ROS_ISOLATED_TEST_SHARD='0/4': shares count from 1"),
        (SHARD_ENV, "3", "ROS_ISOLATED_TEST_SHARD='3' is not I/N"),
        (DURATIONS_ENV, "relative.json", "ROS_ISOLATED_TEST_DURATIONS=relative.json is not an"),
        (DURATIONS_ENV, "/nowhere/d.json", "ROS_ISOLATED_TEST_DURATIONS=/nowhere/d.json: cannot"),
    ],
    ids=["index-0", "no-total", "relative-file", "missing-file"],
)
def test_a_bad_split_setting_is_a_usage_error_with_a_result_file(
    tmp_path: Path, env: dict[str, str], runner_script: str, variable: str, value: str, says: str
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    marker = tmp_path / "ran"
    given = {**env, SHARD_ENV: "1/2", variable: value}
    proc = ament(runner_script, result, _touch(marker), given, cwd=tmp_path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert not marker.exists()
    (line,) = proc.stderr.splitlines()
    assert line.startswith(f"ros-isolated-test: error: {says}"), line
    case = load_result(result).only
    assert case.outcome == "error" and says in case.message
    shell = run_cli(["run", "--junit-xml", str(result), "--", *_touch(marker)], given)
    assert shell.returncode == 2 and says in shell.stderr
    assert says in load_result(result).only.message
    # The control: the same variables, well set, run the test.
    good = tmp_path / "durations.json"
    write(good, measured({"pkg/t": 1.0}))
    fine = ament(
        runner_script, result, _touch(marker), {**env, SHARD_ENV: "1/1", DURATIONS_ENV: str(good)},
        "--generate-result-on-success", cwd=tmp_path,
    )  # fmt: skip
    assert fine.returncode == 0 and marker.exists(), fine.stdout + fine.stderr


def test_run_takes_its_share_from_the_option_and_names_it_when_bad(
    tmp_path: Path, env: dict[str, str]
) -> None:
    here, elsewhere = _shares()
    result = tmp_path / "pkg" / "t.xml"
    marker = tmp_path / "ran"
    # The option wins over the variable, which is then not read (a bad one is harmless).
    options = ["run", "--junit-xml", str(result)]
    skipped = run_cli([*options, "--shard", elsewhere, "--", *_touch(marker)],
                      {**env, SHARD_ENV: "bad"})  # fmt: skip
    assert skipped.returncode == 77, skipped.stderr
    assert not marker.exists() and not result.exists()
    assert f"not in shard {elsewhere}" in skipped.stdout
    ran = run_cli([*options, "--shard", here, "--", *_touch(marker)], {**env, SHARD_ENV: "bad"})
    assert ran.returncode == 0 and marker.exists(), ran.stderr
    assert load_result(result).properties["shard"] == here
    bad = run_cli([*options, "--shard", "5/4", "--", *_touch(marker)], env)
    assert bad.returncode == 2
    assert bad.stderr.startswith("ros-isolated-test: error: --shard '5/4': I must be from 1")
    assert "--shard '5/4'" in load_result(result).only.message


def test_the_test_never_sees_the_split_its_runner_decided(
    tmp_path: Path, env: dict[str, str], runner_script: str
) -> None:
    """A runner or the plugin inside the test would split its own tests again."""
    here, _elsewhere = _shares(1)
    good = tmp_path / "durations.json"
    write(good, measured({"pkg/t": 1.0}))
    seen = tmp_path / "seen"
    command = ["sh", "-c", f'env > "{seen}"']
    given = {**env, SHARD_ENV: here, DURATIONS_ENV: str(good)}
    proc = ament(runner_script, tmp_path / "pkg" / "t.xml", command, given,
                 "--generate-result-on-success", cwd=tmp_path)  # fmt: skip
    assert proc.returncode == 0, proc.stdout + proc.stderr
    names = {line.split("=", 1)[0] for line in seen.read_text().splitlines()}
    assert SHARD_ENV not in names and DURATIONS_ENV not in names
    assert "ROS_ISOLATED_TEST_HELD_DOMAIN_ID" in names  # the control: the test's env is read


def _run_share(folder: Path, share: str, env: dict[str, str], tests: int) -> None:
    """``run --shard`` of each of ``tests`` tests of pkg, results in ``folder``."""
    for n in range(tests):
        done = run_cli(
            ["run", "--shard", share, "--package-name", "pkg",
             "--junit-xml", str(folder / f"t{n}.xml"), "--", "true"], env,
        )  # fmt: skip
        assert done.returncode in (0, 77), done.stdout + done.stderr


def test_a_share_run_where_another_ran_leaves_no_record_of_the_other(
    tmp_path: Path, env: dict[str, str]
) -> None:
    """Share 3's tree copied as share 2's folder (a restored build): share 2's runners
    remove share 3's results and its record too, so a merge without share 3's own tree
    says it is missing. The control: the merge of all three trees is whole."""
    for index in (1, 2, 3):
        _run_share(tmp_path / f"shard-{index}", f"{index}/3", env, 8)
    whole = run_cli(["report", *(str(tmp_path / f"shard-{i}") for i in (1, 2, 3))], env)
    assert whole.returncode == 0, whole.stdout + whole.stderr
    assert "Summary: 8 tests, 0 errors" in whole.stdout
    reused = tmp_path / "m2"
    reused.mkdir()
    for found in (tmp_path / "shard-3").iterdir():
        (reused / found.name).write_bytes(found.read_bytes())
    _run_share(reused, "2/3", env, 8)
    assert sorted(path.name for path in reused.glob("*.json")) == [
        "ros_isolated_test_shard-2-of-3.json"
    ]
    merged = run_cli(["report", str(tmp_path / "shard-1"), str(reused)], env)
    assert merged.returncode == 1, merged.stdout + merged.stderr
    assert "- shard 3 of 3 left no results (no record ros_isolated_test_shard-3-of-3.json" in (
        merged.stdout
    )

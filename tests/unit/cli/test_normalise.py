"""``cli.normalise``: one producer's file made canonical; a failing result exits 1, a bad -o 2."""

from __future__ import annotations

from pathlib import Path

from helpers.commands import REPO, run_cli, the_error_line

from ros_isolated_test.cli import usage

SAMPLES = REPO / "tests" / "data" / "xunit"


def test_a_passing_file_prints_canonical_and_a_failing_one_exits_failed(
    env: dict[str, str], tmp_path: Path
) -> None:
    passed = run_cli(
        ["normalise", "--package-name", "pkg", str(SAMPLES / "pytest-9.2_no_tests.xml")], env
    )
    assert passed.returncode == 0, passed.stderr
    assert passed.stdout.startswith("<?xml")
    failed = run_cli(
        ["normalise", "--package-name", "pkg", str(SAMPLES / "gtest-1.17.0_mixed.gtest.xml")],
        env,
        cwd=tmp_path,
    )
    assert failed.returncode == usage.FAILED, failed.stderr
    assert "<failure" in failed.stdout


def test_an_output_path_that_cannot_be_used_is_one_line(
    env: dict[str, str], tmp_path: Path
) -> None:
    args = ["normalise", "--package-name", "pkg", str(SAMPLES / "pytest-9.2_no_tests.xml")]
    proc = run_cli([*args, "-o", str(tmp_path)], env)
    assert proc.returncode == usage.USAGE
    assert str(tmp_path) in the_error_line(proc)

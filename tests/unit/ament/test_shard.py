"""``ament.shard``: a package's other shares' tests, decided once as ctest loads it.

Run as ctest's include runs it (``python -m``, a real process): the lines it prints are
exactly the tests whose RUNNER would say "not in this shard" (``shard.selection``, the
RUNNER's own identity from the result file's name), over every share each test is
printed by all but one; their stale result files go, the share's own stay, and the
record is left in each result folder. A bad share prints the RUNNER's error, exits 2
and disables nothing; no split prints nothing.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from ros_isolated_test.ament.shard import USAGE, read_list
from ros_isolated_test.shard import record
from ros_isolated_test.shard.durations import DURATIONS_ENV, measured, write
from ros_isolated_test.shard.selection import select
from ros_isolated_test.shard.spec import SHARD_ENV

PACKAGE = "pkg"
TOTAL = 3
#: ctest name -> the result file's name its RUNNER is given (the suffixes ament's macros use).
TESTS = {
    **{f"t_{n}": f"t_{n}.xml" for n in range(12)},
    "gtest_a": "gtest_a.gtest.xml",
    "launch_b": "launch_b.xunit.xml",
}


def _listing(tmp_path: Path) -> Path:
    results = tmp_path / "test_results" / PACKAGE
    path = tmp_path / "tests.txt"
    path.write_text("".join(f"{name}\t{results / file}\n" for name, file in TESTS.items()))
    return path


def _run(listing: Path, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "ros_isolated_test.ament.shard", PACKAGE, str(listing)],
        env=env, capture_output=True, text=True, check=False,
    )  # fmt: skip


def _stale(tmp_path: Path) -> None:
    """Every test's result file of an earlier run (a restored build folder)."""
    for file in TESTS.values():
        path = tmp_path / "test_results" / PACKAGE / file
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("<testsuites/>")


def test_each_share_disables_exactly_what_its_runners_would_skip(
    tmp_path: Path, env: dict[str, str]
) -> None:
    listing = _listing(tmp_path)
    durations = tmp_path / "durations.json"
    write(durations, measured({f"{PACKAGE}/t_{n}": 0.5 * n for n in range(6)}))
    disabled: list[str] = []
    for index in range(1, TOTAL + 1):
        _stale(tmp_path)
        share = {SHARD_ENV: f"{index}/{TOTAL}", DURATIONS_ENV: str(durations)}
        done = _run(listing, {**env, **share})
        assert (done.returncode, done.stderr) == (0, ""), done.stderr
        names = [line.split("\t")[0] for line in done.stdout.splitlines()]
        selection = select(share)
        assert selection is not None
        runner_test = {name: file.split(".")[0] for name, file in TESTS.items()}
        assert names == [name for name in TESTS if not selection.runs(PACKAGE, runner_test[name])]
        folder = tmp_path / "test_results" / PACKAGE
        left = {path.name for path in folder.glob("*.xml")}
        assert left == {TESTS[name] for name in TESTS if name not in names}
        (kept,) = folder.glob("*.json")
        found = record.read(kept)
        assert not isinstance(found, str) and str(found.share) == f"{index}/{TOTAL}"
        disabled += names
    # Over the shares, every test is disabled everywhere but in the one share that runs it.
    assert sorted(disabled) == sorted(name for name in TESTS for _ in range(TOTAL - 1))


def test_a_bad_share_disables_nothing_and_says_the_runners_error(
    tmp_path: Path, env: dict[str, str]
) -> None:
    listing = _listing(tmp_path)
    _stale(tmp_path)
    done = _run(listing, {**env, SHARD_ENV: "4/3"})
    assert done.returncode == USAGE
    assert done.stdout == ""
    assert done.stderr == (
        "ros-isolated-test: ROS_ISOLATED_TEST_SHARD='4/3': I must be from 1 to N=3; give "
        "I/N: share I of N, I from 1 to N, N at most 1000 (e.g. 2/4)\n"
    )
    assert len(list((tmp_path / "test_results" / PACKAGE).glob("*.xml"))) == len(TESTS)
    # The control: a good share disables some of them.
    assert _run(listing, {**env, SHARD_ENV: "1/3"}).stdout


def test_no_split_prints_nothing_and_touches_nothing(tmp_path: Path, env: dict[str, str]) -> None:
    listing = _listing(tmp_path)
    _stale(tmp_path)
    done = _run(listing, {key: value for key, value in env.items() if key != SHARD_ENV})
    assert (done.returncode, done.stdout, done.stderr) == (0, "", "")
    assert not list((tmp_path / "test_results" / PACKAGE).glob("*.json"))


def test_the_list_keeps_a_names_last_line_and_skips_odd_ones(tmp_path: Path) -> None:
    path = tmp_path / "tests.txt"
    path.write_text("a\t/r/a.xml\nb\t/r/b.xml\nno tab\n\t/r/c.xml\na\t/r/a2.xml\n")
    assert read_list(path) == [("b", Path("/r/b.xml")), ("a", Path("/r/a2.xml"))]

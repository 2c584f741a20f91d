"""``shard.selection``: what an entry point asks, answered alike on every machine, cheaply.

The entry points read the split once (``select``) and ask ``runs`` per test; their
results record ``properties``. Each machine below is a ``select`` of its own.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from helpers.commands import REPO

from ros_isolated_test.shard import selection as selecting
from ros_isolated_test.shard.durations import DURATIONS_ENV, measured, write
from ros_isolated_test.shard.identity import spread
from ros_isolated_test.shard.selection import BY_COUNT, Selection, select
from ros_isolated_test.shard.spec import SHARD_ENV, ShardSettingError, Share

TESTS = {f"pkg_{number % 3}/test_{number}": 1.0 + number for number in range(24)}


@pytest.fixture
def durations_file(tmp_path: Path) -> Path:
    path = tmp_path / "durations.json"
    write(path, measured(TESTS))
    return path


def test_no_share_no_split_and_the_durations_are_not_read(tmp_path: Path) -> None:
    missing = str(tmp_path / "nowhere.json")
    assert select({}) is None
    assert select({SHARD_ENV: " ", DURATIONS_ENV: missing}) is None
    # Control: with a share, the same missing file is an error.
    with pytest.raises(ShardSettingError, match=r"nowhere\.json: cannot open it"):
        select({SHARD_ENV: "1/2", DURATIONS_ENV: missing})


def test_a_share_without_durations_splits_by_count() -> None:
    selection = select({SHARD_ENV: "2/4"})
    assert selection is not None
    assert selection.share == Share(2, 4)
    assert selection.plan.by_count
    assert selection.plan_name == BY_COUNT
    assert selection.properties() == {"shard": "2/4", "shard_plan": "count"}
    assert selection.runs("pkg", "t") == (spread("pkg/t", 4) == 2)
    blank = select({SHARD_ENV: "2/4", DURATIONS_ENV: "  "})
    assert blank is not None and blank.plan.by_count  # a blank variable is none


def test_a_share_with_durations_plans_from_the_file(durations_file: Path) -> None:
    selection = select({SHARD_ENV: "1/3", DURATIONS_ENV: str(durations_file)})
    assert selection is not None
    assert not selection.plan.by_count
    assert selection.durations_file == durations_file
    fingerprint = measured(TESTS).fingerprint
    assert selection.properties() == {"shard": "1/3", "shard_plan": fingerprint}


@pytest.mark.parametrize("total", [1, 2, 3, 5, 8])
def test_each_test_runs_on_exactly_one_machine(durations_file: Path, total: int) -> None:
    machines = [
        select({SHARD_ENV: f"{index}/{total}", DURATIONS_ENV: str(durations_file)})
        for index in range(1, total + 1)
    ]
    for identity in [*TESTS, "pkg_0/test_new", "new_pkg/test/test_a.py::test_b"]:
        package, name = identity.split("/", 1)
        running = [
            machine for machine in machines if machine is not None and machine.runs(package, name)
        ]
        assert len(running) == 1, identity


def test_a_relative_durations_variable_is_refused(durations_file: Path) -> None:
    """ctest starts each test in a folder of its own: a relative path names many files."""
    with pytest.raises(ShardSettingError) as raised:
        select({SHARD_ENV: "1/2", DURATIONS_ENV: "durations.json"}, None, None)
    message = str(raised.value)
    assert message.startswith(f"{DURATIONS_ENV}=durations.json is not an absolute path")
    assert "$PWD/durations.json" in message
    assert "\n" not in message
    # Control: an absolute path to the same kind of file is read.
    assert select({SHARD_ENV: "1/2", DURATIONS_ENV: str(durations_file)}) is not None


def test_which_durations_file_is_named_and_by_what(tmp_path: Path) -> None:
    absolute = str(tmp_path / "d.json")
    assert selecting.durations_file({}) is None
    assert selecting.durations_file({DURATIONS_ENV: " "}) is None
    assert selecting.durations_file({DURATIONS_ENV: absolute}) == (Path(absolute), DURATIONS_ENV)
    assert selecting.durations_file({}, "d.json") == (Path("d.json"), "--durations")
    # An option, even blank, wins: the variable (here a bad one) is then not read.
    assert selecting.durations_file({DURATIONS_ENV: "relative.json"}, "") is None
    assert selecting.durations_file({DURATIONS_ENV: "relative.json"}, "x.json", "--opt") == (
        Path("x.json"),
        "--opt",
    )
    with pytest.raises(ShardSettingError, match="is not an absolute path"):
        selecting.durations_file({DURATIONS_ENV: "relative.json"})


def test_options_win_over_the_variables_and_may_be_relative(
    durations_file: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(durations_file.parent)
    environ = {SHARD_ENV: "bad", DURATIONS_ENV: "also bad"}
    selection = select(environ, "3/3", durations_file.name)
    assert selection is not None
    assert selection.share == Share(3, 3)
    assert not selection.plan.by_count
    with pytest.raises(ShardSettingError, match=r"^--durations nowhere.json: "):
        select(environ, "3/3", "nowhere.json")
    with pytest.raises(ShardSettingError, match=r"^--ros-isolated-test-shard '0/3': "):
        select(environ, "0/3", shard_origin="--ros-isolated-test-shard")


def test_a_skipped_test_is_told_which_share_runs_it(durations_file: Path) -> None:
    selection = Selection(Share(1, 2), measured(TESTS), durations_file)
    elsewhere = next(name for name in TESTS if not selection.runs(*name.split("/", 1)))
    package, name = elsewhere.split("/", 1)
    assert selection.share_of(package, name) == 2
    assert selection.not_here(package, name) == (
        f"not in shard 1/2 (shard 2/2 runs it; plan {measured(TESTS).fingerprint})"
    )
    by_count = Selection(Share(1, 2), None)
    assert by_count.not_here("p", "t").endswith("; by count)")


def _loaded(code: str) -> set[str]:
    done = subprocess.run(
        [sys.executable, "-c", code + "\nimport sys\nprint(' '.join(sys.modules))"],
        capture_output=True,
        text=True,
        check=True,
        cwd=REPO,
    )
    return set(done.stdout.split())


#: What a runner must not pay for to ask about its test (each costs a millisecond or more).
HEAVY = {"typing", "dataclasses", "hashlib", "_hashlib", "subprocess", "inspect", "click"}


def test_a_runner_asking_loads_nothing_heavy(durations_file: Path) -> None:
    asking = (
        "from ros_isolated_test.shard.selection import select\n"
        "selection = select({{'ROS_ISOLATED_TEST_SHARD': '1/2'{durations}}})\n"
        "selection.runs('pkg_0', 'test_0'); selection.properties()"
    )
    by_count = _loaded(asking.format(durations=""))
    assert not by_count & (HEAVY | {"json", "heapq"})
    planned = _loaded(asking.format(durations=f", {DURATIONS_ENV!r}: {str(durations_file)!r}"))
    assert not planned & HEAVY
    assert "json" in planned  # control: the walk sees what the file's reading loads

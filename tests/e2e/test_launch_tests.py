"""Real launch tests (launch_testing, Jazzy), four at once, each on a domain of its own.

examples/launch_tokens registers one launch file four times, one token each: the launch
test starts the crosstalk demo's token talker with ``ExecuteProcess`` and checks in its
test case that only its own token is heard. Through ``ros_isolated_add_launch_test`` (and
through the README's ``runner-path`` recipe) all four pass on four distinct IDs; through
plain ``add_launch_test`` (the control) they share one domain and fail.

launch_testing exists only in the outside tier (vendored sources in ``../shared``) and
breaks pytest 9, so the package is built and tested with an environment of its own
(helpers/launch_env.py), never this suite's ``.venv``.
"""

from __future__ import annotations

import itertools
import re
import subprocess
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import pytest
from helpers import capabilities, launch_env
from helpers.workspace import crosstalk_workspace

if TYPE_CHECKING:  # annotations only; at run time the module is loaded by path
    from examples.crosstalk_workspace import Record, ResultSummary

pytestmark = [pytest.mark.colcon, capabilities.OUTSIDE.mark]

PACKAGE_DIR = Path(__file__).resolve().parents[2] / "examples" / "launch_tokens"
TOKENS = ("amber", "birch", "cobalt", "dahlia")
_RUNNING = re.compile(r"^Running with ROS_DOMAIN_ID (\d+)\b", re.MULTILINE)


@dataclass(frozen=True)
class LaunchRun:
    """One build and ``colcon test --ctest-args -j4`` of the package, registered one way."""

    registered: str  # CTestTestfile.cmake: the commands ctest ran
    output: str  # colcon test's console
    records: dict[str, Record]  # what each talker wrote about itself, by token
    announced: dict[str, list[int]]  # "Running with ROS_DOMAIN_ID N" lines, by token
    result: ResultSummary
    cmake_cache: str  # CMakeCache.txt: where each package was found


def _cache_value(cache: str, name: str) -> str | None:
    for line in cache.splitlines():
        key, _, value = line.partition("=")
        if key.split(":")[0] == name:
            return value
    return None


def _launch_run(python: Path, root: Path, mode: str) -> LaunchRun:
    """Build the package with LAUNCH_TOKENS_RUNNER=mode and run its four tests at once."""
    ws = crosstalk_workspace()
    prefix = python.parents[1]
    env = ws.colcon_env()  # then the launch environment in front of the suite's own
    env["PATH"] = f"{prefix / 'bin'}:{env['PATH']}"
    env["CMAKE_PREFIX_PATH"] = f"{prefix}:{env['CMAKE_PREFIX_PATH']}"
    env["ROS_ISOLATED_TEST_LOCK_DIR"] = str(root / "locks")
    env["CROSSTALK_RECORD_DIR"] = str(root / "records")
    paths = ["--base-paths", str(PACKAGE_DIR), "--build-base", str(root / "build"),
             "--install-base", str(root / "install")]  # fmt: skip
    colcon = [str(prefix / "bin" / "colcon"), "--log-base", str(root / "log")]
    build = subprocess.run(
        [*colcon, "build", *paths, "--cmake-args", f"-DLAUNCH_TOKENS_RUNNER={mode}",
         f"-DPython3_EXECUTABLE={python}"],
        cwd=root, env=env, capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert build.returncode == 0, f"colcon build ({mode}) failed:\n{build.stdout}{build.stderr}"
    test = subprocess.run(
        [*colcon, "test", *paths, "--ctest-args", "-j4"],
        cwd=root, env=env, capture_output=True, text=True, check=False,
    )  # fmt: skip
    built = root / "build" / "launch_tokens"
    announced = {
        token: [int(n) for n in _RUNNING.findall(
            (built / "launch_test" / f"launch_token_{token}.txt").read_text(errors="replace"))]
        for token in TOKENS
    }  # fmt: skip
    return LaunchRun(
        registered=(built / "CTestTestfile.cmake").read_text(),
        output=test.stdout + test.stderr,
        records=ws.read_records(root / "records"),
        announced=announced,
        result=ws.result_summary(root),
        cmake_cache=(built / "CMakeCache.txt").read_text(),
    )


@pytest.fixture(scope="module")
def launch_python() -> Path:
    """The launch tier's own environment (built once, then kept in ``.venv-launch/``)."""
    capabilities.require(capabilities.OUTSIDE, capabilities.CTEST, capabilities.TOMLLIB)
    return launch_env.ensure()


@pytest.fixture(scope="module")
def macro_run(launch_python: Path, tmp_path_factory: pytest.TempPathFactory) -> LaunchRun:
    return _launch_run(launch_python, tmp_path_factory.mktemp("launch-macro"), "macro")


@pytest.fixture(scope="module")
def recipe_run(launch_python: Path, tmp_path_factory: pytest.TempPathFactory) -> LaunchRun:
    return _launch_run(launch_python, tmp_path_factory.mktemp("launch-recipe"), "runner_path")


@pytest.fixture(scope="module")
def plain_run(launch_python: Path, tmp_path_factory: pytest.TempPathFactory) -> LaunchRun:
    return _launch_run(launch_python, tmp_path_factory.mktemp("launch-plain"), "plain")


def _talkers(run: LaunchRun) -> list[Record]:
    missing = sorted(set(TOKENS) - set(run.records))
    assert not missing, f"no talker record from {missing}:\n{run.output}"
    return [run.records[token] for token in TOKENS]


def _assert_isolated(run: LaunchRun) -> None:
    """All four passed, each on an ID of its own that the runner announced, all at once."""
    assert run.registered.count("run_test_isolated.py") == 4, run.registered
    assert (run.result.returncode, run.result.errors, run.result.failures) == (0, 0, 0), (
        f"{run.result.line}\n{run.output}"
    )
    assert run.result.tests >= 8, run.result.line  # an active and a post-shutdown case each
    records = _talkers(run)
    assert all(r.passed for r in records), {r.token: r.foreign for r in records}
    ids = {r.token: r.domain_id for r in records}
    assert len(set(ids.values())) == 4 and None not in ids.values(), f"IDs shared: {ids}"
    assert all(int(i) > 0 for i in ids.values() if i is not None), f"domain 0 handed out: {ids}"
    announced = {token: [str(n) for n in lines] for token, lines in run.announced.items()}
    assert announced == {token: [ids[token]] for token in TOKENS}, (announced, ids)
    for a, b in itertools.combinations(records, 2):
        assert a.start < b.end and b.start < a.end, f"{a.token} and {b.token} did not overlap"


def test_ros_isolated_add_launch_test_four_at_once_on_distinct_ids(macro_run: LaunchRun) -> None:
    _assert_isolated(macro_run)


def test_the_macro_comes_from_the_launch_environment_own_prefix(macro_run: LaunchRun) -> None:
    """Found where pip would put it in the launch prefix, not through any other environment."""
    found = _cache_value(macro_run.cmake_cache, "ros_isolated_test_DIR")
    assert found == str(launch_env.CMAKE_PACKAGE), found


def test_readme_runner_path_recipe_four_at_once_on_distinct_ids(recipe_run: LaunchRun) -> None:
    _assert_isolated(recipe_run)


def test_plain_add_launch_test_control_fails_with_crosstalk(plain_run: LaunchRun) -> None:
    assert "run_test_isolated.py" not in plain_run.registered
    records = _talkers(plain_run)
    assert all(r.domain_id is None for r in records), [r.domain_id for r in records]
    assert all(lines == [] for lines in plain_run.announced.values()), plain_run.announced
    heard = [r.token for r in records if r.foreign]
    assert len(heard) >= 3, (
        f"only {heard} heard crosstalk on one shared domain; the control is too weak to "
        f"prove anything:\n{plain_run.output}"
    )
    result = plain_run.result
    assert result.returncode != 0 and result.failures + result.errors >= 3, result.line

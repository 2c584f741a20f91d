"""The CI recipes of docs/adopting.md, read from the page and run with real colcon.

Each snippet (industrial_ci, ros-tooling/action-ros-ci, GitLab CI) is taken from the
page as it is written, so the page cannot say what no test ran. What runs on one
machine is run as the tool runs it, from the tool's own sources: industrial_ci reads
``CMAKE_ARGS`` as a bash array (``eval``) for ``colcon build --cmake-args`` and turns
``PARALLEL_TESTS`` into colcon's executor options (src/builders/colcon.sh), passing
``DOCKER_RUN_OPTS``' ``-e`` variables into its container; action-ros-ci writes
``colcon-defaults`` (a JSON string, after GitHub put the environment into it) as the
file ``COLCON_DEFAULTS_FILE`` names, for ``colcon build --packages-up-to`` and ``colcon
test --packages-select``; GitLab runs the job's ``script`` and ``after_script`` lines
in a shell. Installing (pip from the repository's URL, apt, sourcing /opt/ros) is what
cannot run here.

The workspace proves what each recipe turns on: every test ran through our runner (its
result file carries the ID) and at the same time as the tests it must meet, its package's
own (ctest running several at once) and the other package's (packages at once): a test
that never meets its peer fails.
"""

from __future__ import annotations

import itertools
import json
import re
import shlex
import subprocess
from pathlib import Path
from typing import Any

import pytest
import yaml  # type: ignore[import-untyped]
from helpers import capabilities
from helpers.commands import REPO, run_cli
from helpers.domains import free_ids
from helpers.results import load_result
from helpers.workspace import crosstalk_workspace

pytestmark = [pytest.mark.colcon, capabilities.COLCON.mark, capabilities.CTEST.mark]

ADOPTING = REPO / "docs" / "adopting.md"
RECIPE = re.compile(r"<!-- recipe: (?P<name>[\w-]+) -->\n```yaml\n(?P<body>.*?)\n```", re.S)
PACKAGES = ("ci_alpha", "ci_beta")
#: Each test's peer: x meets the other package's x, y and z meet each other.
TESTS = ("x", "y", "z")
MEET = """\
import os, sys, time
from pathlib import Path

here, me, peer = Path(sys.argv[1]), sys.argv[2], sys.argv[3]
(here / me).touch()
# Only ends a test whose peer never comes (the control: at once, as it never will).
deadline = time.monotonic() + float(os.environ.get("MEET_PATIENCE", "120"))
while not (here / peer).exists():
    if time.monotonic() > deadline:
        sys.exit(f"{me} never met {peer}: they did not run at the same time")
    time.sleep(0.05)
"""
CMAKE_LISTS = """\
cmake_minimum_required(VERSION 3.15)
project({name} NONE)
find_package(ament_cmake REQUIRED)
if(BUILD_TESTING)
  set(meet "${{Python3_EXECUTABLE}}" "{meet}" "{folder}")
  ament_add_test(x COMMAND ${{meet}} {name}_x {other}_x GENERATE_RESULT_FOR_RETURN_CODE_ZERO)
  ament_add_test(y COMMAND ${{meet}} {name}_y {name}_z GENERATE_RESULT_FOR_RETURN_CODE_ZERO)
  ament_add_test(z COMMAND ${{meet}} {name}_z {name}_y GENERATE_RESULT_FOR_RETURN_CODE_ZERO)
endif()
ament_package()
"""
MANIFEST = """\
<?xml version="1.0"?>
<package format="3">
  <name>{name}</name><version>0.1.0</version><description>A CI recipe's package.</description>
  <maintainer email="maintainer@example.com">Example Maintainer</maintainer>
  <license>Apache-2.0</license>
  <buildtool_depend>ament_cmake</buildtool_depend>
  <export><build_type>ament_cmake</build_type></export>
</package>
"""


def recipes() -> dict[str, Any]:
    """Each snippet of docs/adopting.md marked ``<!-- recipe: NAME -->``, as YAML reads it."""
    found = {m["name"]: yaml.safe_load(m["body"]) for m in RECIPE.finditer(ADOPTING.read_text())}
    assert sorted(found) == ["action-ros-ci", "gitlab-ci", "industrial_ci"], sorted(found)
    return found


class Workspace:
    """Two ament_cmake packages of meeting tests in ``root``, with colcon's environment."""

    def __init__(self, root: Path, base: dict[str, str]) -> None:
        self.root = root
        meetings = root / "meetings"
        meetings.mkdir(parents=True)
        (root / "meet.py").write_text(MEET)
        for name, other in zip(PACKAGES, reversed(PACKAGES), strict=True):
            package = root / "src" / name
            package.mkdir(parents=True)
            (package / "package.xml").write_text(MANIFEST.format(name=name))
            lists = CMAKE_LISTS.format(
                name=name, other=other, meet=root / "meet.py", folder=meetings
            )
            (package / "CMakeLists.txt").write_text(lists)
        ws = crosstalk_workspace()
        pool = ",".join(map(str, free_ids(8)))
        self.env = ws.colcon_env(ws.Toolchain(base_env={**base, "ROS_ISOLATED_TEST_DOMAINS": pool}))
        self.env["COLCON_HOME"] = str(root / "colcon-home")  # no defaults of the machine's user
        self.env.pop("COLCON_DEFAULTS_FILE", None)

    def run(self, argv: list[str], **extra: str) -> subprocess.CompletedProcess[str]:
        done = subprocess.run(
            argv, cwd=self.root, env={**self.env, **extra}, capture_output=True, text=True,
            check=False,
        )  # fmt: skip
        assert done.returncode == 0, f"{argv} failed:\n{done.stdout}{done.stderr}"
        return done

    def bash(self, line: str, **extra: str) -> subprocess.CompletedProcess[str]:
        return self.run(["bash", "-c", line], **extra)

    def assert_isolated_and_met(self) -> None:
        """Every test ran through our runner (an ID in its result file) and met its peer."""
        for name in PACKAGES:
            for test in TESTS:
                path = self.root / "build" / name / "test_results" / name / f"{test}.xml"
                result = load_result(path)
                assert result.properties.get("ros_domain_id"), (path, result.properties)
                assert [case.outcome for case in result.cases] == ["passed"], result.cases
        met = sorted(path.name for path in (self.root / "meetings").iterdir())
        assert met == sorted(f"{name}_{test}" for name in PACKAGES for test in TESTS), met


def _industrial_ci_test_options(parallel_tests: str) -> list[str]:
    """``colcon test`` options for PARALLEL_TESTS, as industrial_ci's colcon builder makes
    them (``true`` unsets the limit: colcon's own parallel executor, no option)."""
    jobs = {"": "1", "true": "0", "false": "1"}.get(parallel_tests, parallel_tests)
    if int(jobs) == 1:
        return ["--executor", "sequential", "--ctest-args", "-j1"]
    if int(jobs) > 1:
        return ["--executor", "parallel", "--parallel-workers", jobs]
    return []


def test_industrial_ci(tmp_path: Path, env: dict[str, str]) -> None:
    (step,) = [s for s in recipes()["industrial_ci"]["jobs"]["industrial_ci"]["steps"]
               if "industrial_ci" in s.get("uses", "")]  # fmt: skip
    settings: dict[str, str] = step["env"]
    ws = Workspace(tmp_path, env)
    # CMAKE_ARGS as industrial_ci reads it: eval'd into a bash array, in its container.
    ws.bash('eval "cmake_args=(${CMAKE_ARGS})" && colcon build --cmake-args "${cmake_args[@]}"',
            CMAKE_ARGS=settings["CMAKE_ARGS"])  # fmt: skip
    words = shlex.split(settings["DOCKER_RUN_OPTS"])
    passed = dict(value.split("=", 1) for flag, value in itertools.pairwise(words) if flag == "-e")
    options = _industrial_ci_test_options(settings["PARALLEL_TESTS"])
    assert options == [], "PARALLEL_TESTS does not unset industrial_ci's sequential default"
    ws.run(["colcon", "test", *options], **passed)
    ws.run(["colcon", "test-result", "--verbose"])
    ws.assert_isolated_and_met()

    # The control: industrial_ci's default (PARALLEL_TESTS unset) runs one test at a time,
    # so the first of each pair never meets its peer (the other package's x, its own z).
    for met in (tmp_path / "meetings").iterdir():
        met.unlink()
    default = _industrial_ci_test_options("")
    assert default == ["--executor", "sequential", "--ctest-args", "-j1"]
    ws.run(["colcon", "test", *default], MEET_PATIENCE="0")
    results = tmp_path / "build" / PACKAGES[0] / "test_results" / PACKAGES[0]
    for test in ("x", "y"):
        (case,) = load_result(results / f"{test}.xml").cases
        assert case.outcome == "failure" and "did not run at the same time" in case.text, case


def test_action_ros_ci(tmp_path: Path, env: dict[str, str]) -> None:
    steps = recipes()["action-ros-ci"]["steps"]
    (install,) = [step for step in steps if step.get("name") == "Install ros-isolated-test"]
    (action,) = [step for step in steps if "action-ros-ci" in step.get("uses", "")]
    ws = Workspace(tmp_path, env)
    # The install step's own lines but pip's, with GitHub's file of the job's environment.
    github_env = tmp_path / "github-env"
    lines = [line for line in install["run"].splitlines() if "pip3 install" not in line]
    ws.bash("\n".join(lines), GITHUB_ENV=str(github_env))
    job_env = dict(line.split("=", 1) for line in github_env.read_text().splitlines())
    assert job_env["ROS_ISOLATED_TEST_INCLUDE"].endswith("ros_isolated_test_project_include.cmake")
    # GitHub puts the expression's value into the input; action-ros-ci checks it is JSON
    # and writes it as colcon's defaults file.
    defaults = re.sub(r"\$\{\{ env\.(\w+) \}\}", lambda m: job_env[m[1]],
                      action["with"]["colcon-defaults"])  # fmt: skip
    json.loads(defaults)
    (tmp_path / "defaults.yaml").write_text(defaults)
    selection = [*PACKAGES]
    defaults_file = str(tmp_path / "defaults.yaml")
    ws.run(["colcon", "build", "--packages-up-to", *selection], COLCON_DEFAULTS_FILE=defaults_file)
    ws.run(["colcon", "test", "--event-handlers=console_direct+", "--packages-select", *selection],
           COLCON_DEFAULTS_FILE=defaults_file)  # fmt: skip
    ws.run(["colcon", "test-result", "--all"], COLCON_DEFAULTS_FILE=defaults_file)
    ws.assert_isolated_and_met()


def test_gitlab_ci(tmp_path: Path, env: dict[str, str]) -> None:
    job = recipes()["gitlab-ci"]["ros_tests"]
    ws = Workspace(tmp_path, env)
    # The job's lines in one shell, as GitLab runs them; the environment is already what
    # sourcing ROS gives.
    script = [line for line in job["script"] if "/opt/ros/" not in line]
    assert len(script) == len(job["script"]) - 1, job["script"]
    ws.bash("set -e\n" + "\n".join(script))
    ws.bash("set -e\n" + "\n".join(job["after_script"]))
    ws.assert_isolated_and_met()
    page = tmp_path / job["artifacts"]["paths"][0]
    assert page.is_file() and page.stat().st_size > 0
    reported = sorted(tmp_path.glob(job["artifacts"]["reports"]["junit"]))
    assert len(reported) == len(PACKAGES) * len(TESTS), reported
    report = run_cli(["report", "--json", *map(str, reported)], ws.env)
    total = json.loads(report.stdout)["total"]
    assert (total["tests"], total["failures"], total["errors"]) == (6, 0, 0), report.stdout

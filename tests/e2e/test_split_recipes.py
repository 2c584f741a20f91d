"""The split recipes of docs/adopting.md (GitHub Actions, GitLab, Kubernetes), read from the page.

What can run here runs as the CI would run it: each snippet parses as YAML; every
machine's share comes out of the CI's own variables (GitHub's matrix expression,
GitLab's ``CI_NODE_INDEX``/``CI_NODE_TOTAL`` and ``JOB_COMPLETION_INDEX`` of a
Kubernetes Indexed Job, the shell lines evaluated by bash) as ``1/N`` to ``N/N``, once
each, with the durations file named by an absolute path; the fallback that makes an
empty durations file makes one that reads; the lines that collect a machine's results
run on a machine's tree (``helpers.split_trees``, laid out as colcon leaves a build
folder), and the merge job's commands run on what they collected: every test counted
once, the durations file written. Running colcon on N machines, the CI's artifact
transfer and its caches are what cannot run here.
"""

from __future__ import annotations

import glob
import re
import shutil
import subprocess
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml  # type: ignore[import-untyped]
from helpers.commands import BIN, REPO
from helpers.split_trees import split_trees

from ros_isolated_test.shard.durations import load
from ros_isolated_test.shard.spec import parse

ADOPTING = REPO / "docs" / "adopting.md"
RECIPE = re.compile(r"<!-- split-recipe: (?P<name>[\w-]+) -->\n```yaml\n(?P<body>.*?)\n```", re.S)
TESTS = {
    **{f"nav_{p}/test_{n}": 1.0 + 3 * n for p in range(2) for n in range(5)},
    **{f"py_pkg/test/test_{n}.py::test_case": 0.5 for n in range(4)},
}


def _recipes() -> dict[str, Any]:
    found = {
        match["name"]: yaml.safe_load(match["body"])
        for match in RECIPE.finditer(ADOPTING.read_text())
    }
    assert set(found) == {"github-actions", "gitlab-ci", "kubernetes"}, sorted(found)
    return found


def _bash(script: str, env: Mapping[str, str], cwd: Path) -> str:
    """``script`` run by bash, as a CI runs a job's lines; its output (it must succeed)."""
    done = subprocess.run(
        ["bash", "-c", script], cwd=cwd, capture_output=True, text=True, check=False,
        env={"PATH": f"{BIN}:/usr/bin:/bin", **env},
    )  # fmt: skip
    assert done.returncode == 0, f"{script}\n{done.stdout}{done.stderr}"
    return done.stdout


def _exports(lines: str) -> str:
    """The ``export ROS_ISOLATED_TEST_...`` lines of a script, then a line printing them."""
    kept = [line.strip() for line in lines.splitlines() if line.strip().startswith("export ROS_")]
    assert kept, lines
    return "\n".join([*kept, 'echo "$ROS_ISOLATED_TEST_SHARD $ROS_ISOLATED_TEST_DURATIONS"'])


def _shares(said: list[str], total: int) -> None:
    """Each machine's share, as the variable holds it: 1/N to N/N, once each."""
    shares = [parse(value) for value in said]
    assert sorted(str(share) for share in shares if share) == [
        f"{i}/{total}" for i in range(1, total + 1)
    ]


def _machine_build(root: Path, index: int, total: int) -> Path:
    """Machine ``index``'s ``build`` folder after its share of the tests (a split's tree)."""
    tree = split_trees(root / "made", TESTS, total)[index - 1]
    build = root / f"machine-{index}" / "build"
    shutil.copytree(tree, build)
    return build.parent


def _merge(lines: list[str], cwd: Path) -> None:
    """The merge job's ``ros-isolated-test`` commands: every test counted once, durations kept."""
    for line in lines:
        if line.startswith("ros-isolated-test "):
            _bash(line, {}, cwd)
    assert set(load(cwd / "durations.json").micros) == set(TESTS)
    counted = _bash("ros-isolated-test report --json " + " ".join(
        line.split()[-1] for line in lines if line.startswith("ros-isolated-test report --html")
    ), {}, cwd)  # fmt: skip
    assert f'"tests": {len(TESTS)},' in counted


def test_github_actions_a_matrix_line_gives_each_machine_its_share(tmp_path: Path) -> None:
    jobs = _recipes()["github-actions"]["jobs"]
    matrix = jobs["test"]["strategy"]["matrix"]["shard"]
    template = jobs["test"]["env"]["ROS_ISOLATED_TEST_SHARD"]
    said = [template.replace("${{ matrix.shard }}", str(value)) for value in matrix]
    _shares(said, len(matrix))
    (run,) = [step["run"] for step in jobs["test"]["steps"] if "colcon test" in step.get("run", "")]
    printed = _bash(_exports(run), {"ROS_ISOLATED_TEST_SHARD": said[0]}, tmp_path)
    assert printed.split()[1] == f"{tmp_path}/durations.json"
    # The plan job's fallback: no cache yet, an empty file that reads (a split by count).
    (fallback,) = [step["run"] for step in jobs["plan"]["steps"] if "run" in step]
    _bash(fallback, {}, tmp_path)
    assert len(load(tmp_path / "durations.json")) == 0
    # Each machine uploads what its path globs take from its build folder.
    (upload,) = [
        step for step in jobs["test"]["steps"] if "upload-artifact" in step.get("uses", "")
    ]
    for index in range(1, len(matrix) + 1):
        machine = _machine_build(tmp_path / "machines", index, len(matrix))
        artifact = tmp_path / "merge" / "results" / f"results-{index}"
        for pattern in upload["with"]["path"].split():
            for found in glob.glob(str(machine / pattern)):
                target = artifact / Path(found).relative_to(machine / "build")
                copy = shutil.copytree if Path(found).is_dir() else shutil.copy
                target.parent.mkdir(parents=True, exist_ok=True)
                copy(found, target)
    merge = [step["run"] for step in jobs["merge"]["steps"] if "run" in step]
    _merge(merge, tmp_path / "merge")


def test_gitlab_parallel_gives_each_machine_its_share(tmp_path: Path) -> None:
    recipe = _recipes()["gitlab-ci"]
    tests = recipe["tests"]
    total = tests["parallel"]
    script = "\n".join(tests["script"])
    said = []
    for index in range(1, total + 1):
        env = {
            "CI_NODE_INDEX": str(index),
            "CI_NODE_TOTAL": str(total),
            "CI_PROJECT_DIR": str(tmp_path),
        }
        shard, durations = _bash(_exports(script), env, tmp_path).split()
        assert durations == f"{tmp_path}/durations.json"
        said.append(shard)
        machine = _machine_build(tmp_path / "machines", index, total)
        _bash("\n".join(tests["after_script"]), env, machine)
        shutil.copytree(machine / "results", tmp_path / "merge" / "results", dirs_exist_ok=True)
    _shares(said, total)
    # The plan job's fallback when there is no main pipeline's file to fetch.
    (fetch,) = recipe["plan"]["script"]
    _bash(
        fetch,
        {"CI_API_V4_URL": "http://127.0.0.1:9", "CI_PROJECT_ID": "1", "CI_JOB_TOKEN": "x"},
        tmp_path,
    )
    assert len(load(tmp_path / "durations.json")) == 0
    _merge(recipe["merge"]["script"], tmp_path / "merge")


def test_kubernetes_an_indexed_jobs_index_becomes_a_share(tmp_path: Path) -> None:
    job = _recipes()["kubernetes"]
    spec = job["spec"]
    assert spec["completionMode"] == "Indexed"
    total = spec["completions"]
    (container,) = spec["template"]["spec"]["containers"]
    (script,) = container["args"]
    said = []
    results = tmp_path / "results"
    for index in range(total):
        env = {"JOB_COMPLETION_INDEX": str(index)}
        shard, durations = _bash(_exports(script), env, tmp_path).split()
        assert durations == "/plan/durations.json"
        said.append(shard)
        machine = _machine_build(tmp_path / "machines", index + 1, total)
        collect = [line for line in script.splitlines() if line.startswith(("out=", "find "))]
        _bash("\n".join(collect).replace("/results", str(results)), env, machine)
    _shares(said, total)
    assert sorted(path.name for path in results.iterdir()) == [
        f"shard-{i}" for i in range(1, total + 1)
    ]
    merged = subprocess.run(
        [str(BIN / "ros-isolated-test"), "report", *map(str, sorted(results.iterdir()))],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert merged.returncode == 0, merged.stdout + merged.stderr
    assert f"Summary: {len(TESTS)} tests, 0 errors" in merged.stdout

"""A workspace split over three CI machines, each running its share; one merge reads them all.

One colcon workspace, built once with the zero-edit recipe: two ament_cmake packages
(plain ``ament_add_test`` tests, and an ``ament_add_pytest_test`` run through the RUNNER)
and an ament_python package of pytest items, none of which mentions ros-isolated-test.
Tested once whole, then as three machines would (``ROS_ISOLATED_TEST_SHARD=I/3``, the
durations file written by ``report --durations`` from the whole run), one after another
on the one build, each machine's results copied away as CI uploads them (the results of
the last run stay in the build, as a build folder restored from a cache holds them: a
test of another share must clear its own; share 3 even meets share 2's records, and
must clear them too). ``split_a`` takes the zero-edit include; ``split_b`` turns it off
and registers one test with ``ros_isolated_add_test`` and the rest after its own
``ros_isolated_test_all()``. Python is a wrapper that logs every start, so the RUNNERs
started are counted: a share starts none for another share's test (ctest lists those
"Not Run (Disabled)"), the whole run starts one for every test, and a malformed share
starts every RUNNER, which fails it before any test command runs. Then the merge: each
test ran in exactly one share, the merged counts are the whole run's, the page shows
every test once in Chromium; a share left out (share 2, whose records share 3's build
held), or one run under another plan, is named and fails the merge, as is a share whose
pytest session was killed mid-run.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from collections import Counter
from collections.abc import Mapping
from pathlib import Path

import pytest
from helpers import capabilities, chromium
from helpers.commands import run_cli
from helpers.domains import free_ids
from helpers.report_page import parsed
from helpers.workspace import crosstalk_workspace
from lxml import etree, html

from ros_isolated_test.report.shard_durations import named_tests
from ros_isolated_test.report.tree import read_tree
from ros_isolated_test.shard.durations import load
from ros_isolated_test.xunit import canonical

pytestmark = [pytest.mark.colcon, capabilities.COLCON.mark, capabilities.CTEST.mark]

SHARES = 3
CMAKE = {"split_a": 5, "split_b": 4}
PYTHON = "split_py"
#: Items of the ament_cmake package's pytest (one ctest test, run whole by one share).
PYTEST_ITEMS = 4
PY_ITEMS = 8
#: Set: the ament_python package's pytest session kills itself at its first item.
KILL = "SPLIT_KILL_SESSION"
TEST = "colcon test --parallel-workers 3 --ctest-args -j3"
MANIFEST = """<?xml version="1.0"?>
<package format="3">
  <name>{name}</name><version>0.1.0</version><description>A split's package.</description>
  <maintainer email="maintainer@example.com">Example Maintainer</maintainer>
  <license>Apache-2.0</license>
  <buildtool_depend>{build}</buildtool_depend>
  <test_depend>ament_cmake_pytest</test_depend>
  <export><build_type>{build}</build_type></export>
</package>
"""
SETUP = """from setuptools import setup

setup(
    name="{name}",
    version="0.1.0",
    packages=[],
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/{name}"]),
        ("share/{name}", ["package.xml"]),
    ],
    install_requires=["setuptools"],
    extras_require={{"test": ["pytest"]}},
    zip_safe=True,
)
"""


def _generate(src: Path) -> None:
    """The packages: tests that sleep a little, some longer than others."""
    for package, count in CMAKE.items():
        folder = src / package
        (folder / "test").mkdir(parents=True)
        lines = ["cmake_minimum_required(VERSION 3.15)"]
        if package == "split_b":  # its own calls, not the zero-edit include
            lines.append("set(ROS_ISOLATED_TEST_ALL OFF)")
        lines += [f"project({package} NONE)", "find_package(ament_cmake REQUIRED)"]
        if package == "split_b":
            lines.append("find_package(ros_isolated_test REQUIRED)")
        lines.append("if(BUILD_TESTING)")
        for n in range(count):
            add = "ament_add_test"
            if package == "split_b" and n == 0:
                add = "ros_isolated_add_test"  # before ros_isolated_test_all(): a macro's
            lines.append(
                f'  {add}({package}_{n} COMMAND "${{Python3_EXECUTABLE}}" -c '
                f"\"__import__('time').sleep({0.05 * n:.2f})\" "
                "GENERATE_RESULT_FOR_RETURN_CODE_ZERO)"
            )
            if package == "split_b" and n == 0:
                lines.append("  ros_isolated_test_all()")
        if package == "split_b":
            lines.append("  find_package(ament_cmake_pytest REQUIRED)")
            lines.append("  ament_add_pytest_test(split_b_pytest test/test_items.py)")
            (folder / "test" / "test_items.py").write_text(
                "".join(f"def test_item_{n}():\n    pass\n\n" for n in range(PYTEST_ITEMS))
            )
        lines += ["endif()", "ament_package()", ""]
        (folder / "CMakeLists.txt").write_text("\n".join(lines))
        (folder / "package.xml").write_text(MANIFEST.format(name=package, build="ament_cmake"))
    folder = src / PYTHON
    (folder / "test").mkdir(parents=True)
    (folder / "resource").mkdir()
    (folder / "resource" / PYTHON).write_text("")
    (folder / "setup.py").write_text(SETUP.format(name=PYTHON))
    (folder / "package.xml").write_text(MANIFEST.format(name=PYTHON, build="ament_python"))
    (folder / "test" / "test_py.py").write_text(
        "import os, signal, time\n\n"
        + "".join(
            f"def test_py_{n}():\n    time.sleep({0.02 * n:.2f})\n"
            f"    if os.environ.get('{KILL}'):\n"
            "        os.kill(os.getpid(), signal.SIGKILL)\n\n"
            for n in range(PY_ITEMS)
        )
    )


class Split:
    """The workspace, its one build, and the trees its runs left (copied as CI uploads them)."""

    def __init__(self, root: Path, env: Mapping[str, str]) -> None:
        self.root = root
        ws = crosstalk_workspace()
        self.env = ws.colcon_env(ws.Toolchain(base_env=dict(env)))
        self.env["COLCON_HOME"] = str(root / "colcon-home")
        self.env.pop("COLCON_DEFAULTS_FILE", None)
        #: Each run's tree of results, and ctest's Test.xml per CMake package.
        self.trees: dict[str, Path] = {}
        self.ctest: dict[str, dict[str, etree._Element]] = {}
        #: Each run's RUNNER starts (``<package>/<test>``) and test commands started.
        self.runners: dict[str, list[str]] = {}
        self.commands: dict[str, int] = {}
        #: What ``colcon test-result --all`` said of each share's build.
        self.test_result: dict[str, str] = {}
        #: Python for CMake: every start is logged (to $SPLIT_STARTS, when set).
        self.python = root / "python-logged"
        self.python.write_text(
            '#!/bin/sh\n[ -z "$SPLIT_STARTS" ] || printf \'%s\\n\' "$*" >> "$SPLIT_STARTS"\n'
            f'exec "{sys.executable}" "$@"\n'
        )
        self.python.chmod(0o755)

    def shell(self, line: str, extra: Mapping[str, str] | None = None, fails: bool = False) -> str:
        """``line`` run by bash; it must succeed (or, ``fails``, must not)."""
        done = subprocess.run(
            ["bash", "-c", line], cwd=self.root, env={**self.env, **(extra or {})},
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, check=False,
        )  # fmt: skip
        if (done.returncode != 0) != fails:
            raise AssertionError(f"{line} exited {done.returncode}:\n{done.stdout}")
        return done.stdout

    def test(
        self,
        name: str,
        extra: Mapping[str, str] | None = None,
        keep_records: bool = False,
        fails: bool = False,
    ) -> Path:
        """``colcon test`` once; its results copied to a tree of their own, as CI uploads them.

        The results stay in the build (the next run meets them as a restored build folder
        holds them); the machine's records go, as a fresh machine has none, unless
        ``keep_records``: the next run meets them too, as in a build folder reused whole.
        """
        starts = self.root / f"starts-{name}.log"
        said = self.shell(TEST, {**(extra or {}), "SPLIT_STARTS": str(starts)}, fails)
        if fails:
            assert f"1 package failed: {PYTHON}" in said, said
        self.runners[name], self.commands[name] = _starts(starts)
        if name.startswith("shard-"):
            self.test_result[name] = self.shell("colcon test-result --all")
        build = self.root / "build"
        tree = self.root / "trees" / name
        for package in CMAKE:
            shutil.copytree(build / package / "test_results", tree / package / "test_results")
            tag = (build / package / "Testing" / "TAG").read_text().splitlines()[0]
            self.ctest.setdefault(name, {})[package] = etree.parse(
                str(build / package / "Testing" / tag / "Test.xml")
            ).getroot()
        (tree / PYTHON).mkdir(parents=True)
        for found in (build / PYTHON).glob("*"):
            if found.name == "pytest.xml" or found.name.startswith("ros_isolated_test_shard-"):
                shutil.copy(found, tree / PYTHON / found.name)
        for stale in build.glob("**/ros_isolated_test_shard-*.json"):
            if not keep_records:
                stale.unlink()
        self.trees[name] = tree
        return tree


def _starts(log: Path) -> tuple[list[str], int]:
    """The RUNNERs a run started (``<package>/<test>``, from the arguments ament gives
    them), and how many test commands (the tests' own ``python -c``) it started."""
    runners: list[str] = []
    commands = 0
    for line in log.read_text().splitlines() if log.exists() else []:
        words = line.split()
        if any(word.endswith("run_test_isolated.py") for word in words):
            at = next(i for i, word in enumerate(words) if word.endswith("run_test_isolated.py"))
            package = words[words.index("--package-name") + 1]
            runners.append(f"{package}/{canonical.test_name_of(Path(words[at + 1]))}")
        elif "-c" in words and "__import__('time').sleep(" in line:
            commands += 1
    return runners, commands


@pytest.fixture(scope="module")
def split(tmp_path_factory: pytest.TempPathFactory, module_env: dict[str, str]) -> Split:
    """Built once; tested whole, as three shares by its durations, one share by count, and
    share 1 again with its ament_python session killed mid-run."""
    root = tmp_path_factory.mktemp("split")
    _generate(root / "src")
    env = {**module_env, "ROS_ISOLATED_TEST_DOMAINS": ",".join(map(str, free_ids(8)))}
    ws = Split(root, env)
    ws.shell(
        "colcon build --cmake-args -DCMAKE_PROJECT_INCLUDE=$(ros-isolated-test cmake-include) "
        f"-DPython3_EXECUTABLE={ws.python}"
    )
    ws.test("whole")
    durations = root / "durations.json"
    said = ws.shell(f"ros-isolated-test report --durations {durations} trees/whole")
    assert said.startswith(f"{durations}: "), said
    for index in range(1, SHARES + 1):
        ws.test(
            f"shard-{index}",
            {
                "ROS_ISOLATED_TEST_SHARD": f"{index}/{SHARES}",
                "ROS_ISOLATED_TEST_DURATIONS": str(durations),
            },
            keep_records=index == 2,  # share 3 runs in share 2's build folder, records and all
        )
    ws.test("by-count-2", {"ROS_ISOLATED_TEST_SHARD": f"2/{SHARES}"})
    killed = {
        "ROS_ISOLATED_TEST_SHARD": f"1/{SHARES}",
        "ROS_ISOLATED_TEST_DURATIONS": str(durations),
    }
    ws.test("killed-1", {**killed, KILL: "1"}, fails=True)
    ws.test("malformed", {"ROS_ISOLATED_TEST_SHARD": f"{SHARES + 1}/{SHARES}"}, fails=True)
    return ws


def _identities(tree: Path) -> list[str]:
    return [key for item in read_tree([tree]) for key, _seconds in named_tests(item)]


def _shard_trees(split: Split) -> list[Path]:
    return [split.trees[f"shard-{index}"] for index in range(1, SHARES + 1)]


def test_each_test_ran_in_exactly_one_share(split: Split) -> None:
    whole = _identities(split.trees["whole"])
    expected = sum(CMAKE.values()) + 1 + PY_ITEMS  # the CMake pytest is one ctest test
    assert len(whole) == len(set(whole)) == expected, whole
    ran = [key for tree in _shard_trees(split) for key in _identities(tree)]
    assert sorted(ran) == sorted(whole)
    assert all(_identities(tree) for tree in _shard_trees(split)), "a share ran nothing"


def test_the_shares_follow_the_plan_shard_plan_prints(split: Split) -> None:
    """What each machine ran is what ``shard --plan`` shows before paying for them."""
    durations = split.root / "durations.json"
    assert set(load(durations).micros) == set(_identities(split.trees["whole"]))
    plan = json.loads(
        run_cli(
            ["shard", "--plan", "--json", "--durations", str(durations), "--total", str(SHARES)],
            split.env,
        ).stdout
    )
    for share, tree in zip(plan["shares"], _shard_trees(split), strict=True):
        assert sorted(test["identity"] for test in share["tests"]) == sorted(_identities(tree))


def _cmake_tests(split: Split, run: str) -> list[str]:
    return [
        f"{package}/{test.findtext('Name')}"
        for package, site in split.ctest[run].items()
        for test in site.iterfind("Testing/Test")
    ]


def test_a_share_starts_no_runner_for_another_shares_test(split: Split) -> None:
    """Counted from the logged starts: each share starts the RUNNERs of its own CMake
    tests only, once each; over the shares, every test's once. The control: the whole
    run starts one for every CMake test of both packages (the include's and the
    ros_isolated_test_all() and macro one's)."""
    every = _cmake_tests(split, "whole")
    assert len(every) == sum(CMAKE.values()) + 1  # the CMake pytest is one ctest test
    assert sorted(split.runners["whole"]) == sorted(every)
    assert split.commands["whole"] == sum(CMAKE.values())
    started: list[str] = []
    for index, tree in enumerate(_shard_trees(split), start=1):
        own = _ran_cmake(tree)
        assert own and own < set(every), index
        assert sorted(split.runners[f"shard-{index}"]) == sorted(own), index
        started += split.runners[f"shard-{index}"]
    assert sorted(started) == sorted(every)


def _ran_cmake(tree: Path) -> set[str]:
    """The CMake tests a tree has a RUNNER's result of (``<package>/<test>``)."""
    return {
        f"{path.parent.name}/{canonical.test_name_of(path)}"
        for path in tree.glob("*/test_results/*/*.xml")
    }


def test_a_malformed_share_fails_every_runner_before_its_test_starts(split: Split) -> None:
    """``4/3``: nothing is disabled, every RUNNER starts and fails with the one-line
    error, and no test command runs (the control: the whole run's started them all)."""
    assert sorted(split.runners["malformed"]) == sorted(_cmake_tests(split, "whole"))
    assert split.commands["malformed"] == 0
    for site in split.ctest["malformed"].values():
        assert {test.get("Status") for test in site.iterfind("Testing/Test")} == {"failed"}
    results = list(split.trees["malformed"].glob("*/test_results/*/*.xml"))
    assert len(results) == len(_cmake_tests(split, "whole"))
    for path in results:
        said = path.read_text()
        assert "ROS_ISOLATED_TEST_SHARD=" in said and "4/3" in said, path


def test_colcon_test_result_counts_the_disabled_tests_skipped(split: Split) -> None:
    """colcon reads ctest's Test.xml too: a disabled test is one test, skipped (never an
    error or a failure), beside the result files of the tests that ran."""
    every = _cmake_tests(split, "whole")
    for index, tree in enumerate(_shard_trees(split), start=1):
        disabled = len(every) - len(_ran_cmake(tree))
        ran = json.loads(_report(split, tree).stdout)["total"]["tests"]
        summary = f"Summary: {len(every) + ran} tests, 0 errors, 0 failures, {disabled} skipped"
        assert summary in split.test_result[f"shard-{index}"], split.test_result[f"shard-{index}"]


def test_ctest_lists_the_other_shares_tests_disabled(split: Split) -> None:
    for index, tree in enumerate(_shard_trees(split), start=1):
        ran = set(_identities(tree))
        for package, site in split.ctest[f"shard-{index}"].items():
            for test in site.iterfind("Testing/Test"):
                name = test.findtext("Name")
                status = test.get("Status")
                if f"{package}/{name}" in ran:
                    assert status == "passed", (index, name, status)
                else:
                    assert status == "notrun", (index, name, status)
                    completion = test.find(".//NamedMeasurement[@name='Completion Status']")
                    said = completion.findtext("Value") if completion is not None else None
                    assert said == "Disabled", (index, name, said)
        # No result file of another share's test stayed (the build held them all).
        names = {canonical.test_name_of(path) for path in tree.glob("*/test_results/*/*.xml")}
        assert names == {key.split("/", 1)[1] for key in ran if "::" not in key}


def test_the_pytest_the_runner_ran_is_not_split_again(split: Split) -> None:
    (result,) = [
        path for tree in _shard_trees(split) for path in tree.glob("**/split_b_pytest.xunit.xml")
    ]
    cases = etree.parse(str(result)).getroot().findall(".//testcase")
    assert len(cases) == PYTEST_ITEMS


def _report(split: Split, *trees: Path, json_out: bool = True) -> subprocess.CompletedProcess[str]:
    args = ["report", *(["--json"] if json_out else []), *map(str, trees)]
    return run_cli(args, split.env)


def test_the_merged_report_counts_what_the_whole_run_counted(split: Split) -> None:
    whole = _report(split, split.trees["whole"])
    merged = _report(split, *_shard_trees(split))
    assert (whole.returncode, merged.returncode) == (0, 0), merged.stdout + merged.stderr
    assert json.loads(merged.stdout)["total"] == json.loads(whole.stdout)["total"]
    shards = json.loads(merged.stdout)["shards"]
    assert [found["shard"] for found in shards["found"]] == ["1/3", "2/3", "3/3"]
    assert shards["problems"] == []


def _case_rows(page: html.HtmlElement) -> Counter[tuple[str, str]]:
    rows = page.xpath(f"//section[@id='all']//tr[{chromium.with_class('c')}]")
    return Counter((row.getparent().get("data-class"), row.findtext("td")) for row in rows)


@capabilities.CHROMIUM.mark
def test_the_merged_page_shows_every_test_once(split: Split) -> None:
    whole_page, merged_page = split.root / "whole.html", split.root / "merged.html"
    assert run_cli(["report", "--html", str(whole_page), str(split.trees["whole"])],
                   split.env).returncode == 0  # fmt: skip
    assert run_cli(["report", "--html", str(merged_page), *map(str, _shard_trees(split))],
                   split.env).returncode == 0  # fmt: skip
    dom = chromium.dump_dom(merged_page)
    rows = _case_rows(dom)
    assert set(rows.values()) == {1}, [row for row, count in rows.items() if count > 1]
    assert rows == _case_rows(parsed(whole_page.read_text()))
    machines = {
        row.get("data-machine") for row in dom.xpath("//*[@id='timeline']//div[@data-machine]")
    }
    assert {machine.split(" · ")[0] for machine in machines} == {
        "shard 1/3",
        "shard 2/3",
        "shard 3/3",
    }
    assert dom.xpath("//header//h1")[0].text == "PASSED"


def test_a_share_left_out_fails_the_merge_naming_it(split: Split) -> None:
    """Share 2 is lost, though share 3 ran in its build folder: share 3's runners and
    pytest session removed share 2's records there, so none stands for share 2."""
    trees = _shard_trees(split)
    assert sorted(path.name for path in trees[2].glob("**/ros_isolated_test_shard-*.json")) == [
        "ros_isolated_test_shard-3-of-3.json"
    ] * (len(CMAKE) + 1)
    short = _report(split, trees[0], trees[2], json_out=False)
    assert short.returncode == 1, short.stdout
    assert "- shard 2 of 3 left no results (no record ros_isolated_test_shard-2-of-3.json" in (
        short.stdout
    )


def test_a_share_whose_pytest_session_was_killed_fails_the_merge_naming_it(split: Split) -> None:
    """Share 1 again in the reused build, its ament_python session SIGKILLed mid-run: its
    record says started, its pytest.xml is still the plugin's placeholder (the last run's
    was replaced at the start, not taken for this one's), and the merge names it. The
    control: share 1 whole (test_the_merged_report_counts_what_the_whole_run_counted)."""
    trees = _shard_trees(split)
    killed = split.trees["killed-1"]
    assert "ended before writing its results" in (killed / PYTHON / "pytest.xml").read_text()
    merged = _report(split, killed, trees[1], trees[2], json_out=False)
    assert merged.returncode == 1, merged.stdout
    assert f"a pytest session started and left no results ({killed / PYTHON}" in merged.stdout
    said = merged.stdout.splitlines()
    (line,) = [line for line in said if "started and left no results in" in line]
    assert line.startswith(
        f"- shard 1 of {SHARES} started and left no results in {killed / PYTHON} ("
    )


def test_shares_run_from_different_durations_files_fail_the_merge(split: Split) -> None:
    trees = _shard_trees(split)
    mixed = _report(split, trees[0], split.trees["by-count-2"], trees[2])
    assert mixed.returncode == 1
    (problem,) = [
        line for line in json.loads(mixed.stdout)["shards"]["problems"]
        if line.startswith("the shards ran under different plans")
    ]  # fmt: skip
    fingerprint = load(split.root / "durations.json").fingerprint
    assert f"1/3, 3/3 under plan {fingerprint}" in problem and "2/3 under plan count" in problem

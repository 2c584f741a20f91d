"""``pytest_plugin.shard``: a pytest session runs its share of a split, as real sessions.

Each share's session deselects the others' items (they are not in its ``--junit-xml``),
names every item it keeps by its identity, records its share beside the file (started,
and the file a placeholder, until pytest writes it: a session killed mid-run fails the
merge; more in test_shard_placeholder.py), and exits 0 when
the split emptied its share (and only then: pytest's 5 stays 5). Every bad value is
pytest's usage error naming the variable or option; under a runner's ID nothing is split
again. Each beside its control.
"""

from __future__ import annotations

import json
import signal
from pathlib import Path

import pytest
from helpers.commands import run_cli
from helpers.pytest_sessions import header_lines, project, run_pytest
from lxml import etree

from ros_isolated_test.shard.durations import DURATIONS_ENV, load, measured, write
from ros_isolated_test.shard.identity import PROPERTY
from ros_isolated_test.shard.selection import select
from ros_isolated_test.shard.spec import SHARD_ENV

#: Twelve tests, two of them in a class and parametrized: node ids with "::" and "[...]".
TESTS = (
    "import pytest\n\n"
    + "".join(f"def test_{n}():\n    pass\n\n" for n in range(9))
    + "class TestGroup:\n    @pytest.mark.parametrize('x', [1, 2, 3])\n"
    "    def test_p(self, x):\n        pass\n"
)
NODES = [f"test/test_it.py::test_{n}" for n in range(9)] + [
    f"test/test_it.py::TestGroup::test_p[{x}]" for x in (1, 2, 3)
]


def _junit(path: Path, named: bool = True) -> tuple[list[str], dict[str, str]]:
    """The identities of a --junit-xml file's cases (each has one when ``named``), and
    its suite properties."""
    root = etree.parse(str(path)).getroot()
    cases = root.findall(".//testcase")
    names = [
        str(prop.get("value"))
        for case in cases
        for prop in case.iterfind("properties/property")
        if prop.get("name") == PROPERTY
    ]
    if named:
        assert len(names) == len(cases), "every case named"
    suite = {
        str(prop.get("name")): str(prop.get("value"))
        for prop in root.findall("./testsuite/properties/property")
    }
    return names, suite


def test_three_shares_run_every_item_exactly_once(tmp_path: Path, env: dict[str, str]) -> None:
    root = project(tmp_path / "pkg", TESTS)
    ran: list[str] = []
    for index in (1, 2, 3):
        junit = tmp_path / f"share{index}" / "pytest.xml"
        done = run_pytest(root, {**env, SHARD_ENV: f"{index}/3"}, f"--junit-xml={junit}", "test")
        assert done.returncode == 0, done.stdout + done.stderr
        names, properties = _junit(junit)
        assert (properties["shard"], properties["shard_plan"]) == (f"{index}/3", "count")
        assert (junit.parent / f"ros_isolated_test_shard-{index}-of-3.json").is_file()
        expected = select({SHARD_ENV: f"{index}/3"})
        assert expected is not None
        assert names == [f"pkg/{node}" for node in NODES if expected.runs("pkg", node)]
        assert f"ros-isolated-test: shard {index}/3 (by count)" in " ".join(
            header_lines(done.stdout)
        )
        ran += names
    assert sorted(ran) == sorted(f"pkg/{node}" for node in NODES)
    # The control: unsplit, every item runs, still named (for report --durations).
    whole = tmp_path / "whole" / "pytest.xml"
    assert run_pytest(root, env, f"--junit-xml={whole}", "test").returncode == 0
    names, properties = _junit(whole)
    assert sorted(names) == sorted(f"pkg/{node}" for node in NODES)
    assert "shard" not in properties
    assert not list(whole.parent.glob("ros_isolated_test_shard-*"))


def test_a_share_with_none_of_the_tests_passes(tmp_path: Path, env: dict[str, str]) -> None:
    root = project(tmp_path / "pkg", "def test_only():\n    pass\n")
    here = select({SHARD_ENV: "1/2"})
    assert here is not None
    elsewhere = 3 - here.share_of("pkg", "test/test_it.py::test_only")
    junit = tmp_path / "out" / "pytest.xml"
    empty = run_pytest(root, env, f"--ros-isolated-test-shard={elsewhere}/2",
                       f"--junit-xml={junit}", "test")  # fmt: skip
    assert empty.returncode == 0, empty.stdout + empty.stderr
    assert "1 deselected" in empty.stdout
    assert _junit(junit)[0] == []
    # The control: deselecting everything without a split is still pytest's 5.
    assert run_pytest(root, env, "-k", "nothing", "test").returncode == 5


def test_xdist_workers_deselect_alike(tmp_path: Path, env: dict[str, str]) -> None:
    root = project(tmp_path / "pkg", TESTS)
    alone, spread = tmp_path / "alone.xml", tmp_path / "spread.xml"
    shard = {**env, SHARD_ENV: "2/3"}
    assert run_pytest(root, shard, f"--junit-xml={alone}", "test").returncode == 0
    done = run_pytest(root, shard, "-n", "2", f"--junit-xml={spread}", "test")
    assert done.returncode == 0, done.stdout + done.stderr
    assert sorted(_junit(spread)[0]) == sorted(_junit(alone)[0])
    assert _junit(spread)[1]["shard"] == "2/3"


def test_a_durations_file_places_the_items(tmp_path: Path, env: dict[str, str]) -> None:
    """The longest item alone in its share, as the plan puts it on every machine."""
    root = project(tmp_path / "pkg", TESTS)
    durations = tmp_path / "durations.json"
    write(durations, measured({f"pkg/{node}": 100.0 if n == 0 else 1.0
                               for n, node in enumerate(NODES)}))  # fmt: skip
    given = {**env, SHARD_ENV: "1/2", DURATIONS_ENV: str(durations)}
    junit = tmp_path / "pytest.xml"
    assert run_pytest(root, given, f"--junit-xml={junit}", "test").returncode == 0
    names, properties = _junit(junit)
    assert names == [f"pkg/{NODES[0]}"]
    assert properties["shard_plan"] == load(durations).fingerprint


@pytest.mark.parametrize(
    ("given", "says"),
    [
        ({SHARD_ENV: "0/2"}, "ROS_ISOLATED_TEST_SHARD='0/2': shares count from 1"),
        ({SHARD_ENV: "1/2", DURATIONS_ENV: "/nowhere.json"}, "ROS_ISOLATED_TEST_DURATIONS="),
        ({}, "--ros-isolated-test-shard '3/2': I must be from 1 to N=2"),
    ],
    ids=["variable", "durations", "option"],
)
def test_a_bad_value_is_a_usage_error_naming_it(
    tmp_path: Path, env: dict[str, str], given: dict[str, str], says: str
) -> None:
    root = project(tmp_path / "pkg", TESTS)
    option = [] if given else ["--ros-isolated-test-shard", "3/2"]
    done = run_pytest(root, {**env, **given}, *option, "test")
    assert done.returncode == 4, done.stdout + done.stderr
    assert f"ERROR: ros-isolated-test: {says}" in done.stderr
    # The control: a good value runs.
    assert run_pytest(root, {**env, SHARD_ENV: "1/1"}, "test").returncode == 0


def test_under_a_runners_id_nothing_is_split_again(tmp_path: Path, env: dict[str, str]) -> None:
    """The runner decided for the whole test (ament_add_pytest_test through it)."""
    root = project(tmp_path / "pkg", TESTS)
    held = {**env, "ROS_DOMAIN_ID": "17", "ROS_ISOLATED_TEST_HELD_DOMAIN_ID": "17"}
    junit = tmp_path / "pytest.xml"
    done = run_pytest(root, held, "--ros-isolated-test-shard", "1/3", f"--junit-xml={junit}",
                      "test")  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    names, properties = _junit(junit, named=False)
    assert names == [] and "shard" not in properties  # not named: the runner's test
    assert len(etree.parse(str(junit)).getroot().findall(".//testcase")) == len(NODES)
    assert "--ros-isolated-test-shard not applied: the runner" in done.stdout
    # The control: the same option, not under a runner's ID, splits.
    alone = run_pytest(root, env, "--ros-isolated-test-shard", "1/3", "test")
    assert "deselected" in alone.stdout


def test_only_a_share_the_split_emptied_turns_5_into_0(tmp_path: Path, env: dict[str, str]) -> None:
    """A session that selected nothing itself, or a package of no tests (under xdist too),
    is pytest's 5 under a split as without; a share the split emptied passes, alone or
    under xdist (its workers tell the controller what they deselected)."""
    root = project(tmp_path / "pkg", "def test_only():\n    pass\n")
    here = select({SHARD_ENV: "1/3"})
    assert here is not None
    mine = here.share_of("pkg", "test/test_it.py::test_only")
    elsewhere = {**env, SHARD_ENV: f"{mine % 3 + 1}/3"}
    nothing = run_pytest(root, {**env, SHARD_ENV: f"{mine}/3"}, "-k", "nomatch", "test")
    assert nothing.returncode == 5, nothing.stdout + nothing.stderr
    empty = project(tmp_path / "empty", "")
    for args in ([], ["-n", "2"]):
        done = run_pytest(empty, elsewhere, *args, "test")
        assert done.returncode == 5, (args, done.stdout + done.stderr)
    # The controls: the split emptied the share.
    for args in ([], ["-n", "2"]):
        done = run_pytest(root, elsewhere, *args, "test")
        assert done.returncode == 0, (args, done.stdout + done.stderr)


#: Every test kills its session when $KILL names a signal: SIGKILL or SIGSEGV mid-run.
KILLING = "import os, signal\n\n" + "".join(
    f"def test_{n}():\n"
    "    if os.environ.get('KILL'):\n"
    "        os.kill(os.getpid(), getattr(signal, os.environ['KILL']))\n\n"
    for n in range(6)
)


@pytest.mark.parametrize("signal_name", ["SIGKILL", "SIGSEGV"])
def test_a_share_whose_session_died_fails_the_merge_naming_it(
    tmp_path: Path, env: dict[str, str], signal_name: str
) -> None:
    """Share 1's session dies mid-run: its started record, its --junit-xml still the
    placeholder (an earlier file there is replaced at the start), and the merge names
    it. The control: the same sessions not killed merge whole, exit 0."""
    root = project(tmp_path / "pkg", KILLING)
    out = {index: tmp_path / f"share{index}" / "pytest.xml" for index in (1, 2)}

    def share(index: int, **extra: str) -> int:
        done = run_pytest(root, {**env, SHARD_ENV: f"{index}/2", **extra},
                          f"--junit-xml={out[index]}", "test")  # fmt: skip
        return done.returncode

    assert (share(1), share(2)) == (0, 0)
    merged = run_cli(["report", str(out[1].parent), str(out[2].parent)], env)
    assert merged.returncode == 0, merged.stdout + merged.stderr
    assert "Summary: 6 tests, 0 errors" in merged.stdout
    record = out[1].parent / "ros_isolated_test_shard-1-of-2.json"
    assert "state" not in json.loads(record.read_text())
    assert share(1, KILL=signal_name) == -getattr(signal, signal_name)
    assert "ended before writing its results" in out[1].read_text()
    assert json.loads(record.read_text())["state"] == "started"
    merged = run_cli(["report", str(out[1].parent), str(out[2].parent)], env)
    assert merged.returncode == 1, merged.stdout + merged.stderr
    assert f"- shard 1 of 2 started and left no results in {out[1].parent} (" in merged.stdout
    assert f"- shard 1 of 2: a pytest session started and left no results ({out[1]} " in (
        merged.stdout
    )


def test_the_package_xml_that_switches_the_plugin_on_names_the_items(
    tmp_path: Path, env: dict[str, str]
) -> None:
    """pytest's rootdir above the package (no package.xml there): the one walk finds the
    manifest of the test path, which both switches the plugin on and names the items; the
    control: rootdir in the package, named alike."""
    workspace = tmp_path / "ws"
    root = project(workspace / "src" / "mine", "def test_only():\n    pass\n")
    (root / "package.xml").write_text("<package format='3'><name>mine</name></package>\n")
    names = []
    for rootdir in (f"--rootdir={workspace}", f"--rootdir={root}"):
        junit = tmp_path / "pytest.xml"
        done = run_pytest(workspace, {**env, SHARD_ENV: "1/1"}, rootdir, f"--junit-xml={junit}",
                          "src/mine/test")  # fmt: skip
        assert done.returncode == 0, done.stdout + done.stderr
        names += _junit(junit)[0]
    assert names == [
        "mine/src/mine/test/test_it.py::test_only", "mine/test/test_it.py::test_only"
    ]  # fmt: skip


#: A conftest that counts, without changing them, the split's costly steps in its session:
#: reading the durations file, making a Selection (a plan), planning, and the per-item ask.
_COUNTING_CONFTEST = """
import json, os
from ros_isolated_test.shard import plan, selection

COUNTS = {"load": 0, "selection": 0, "placing": 0, "runs": 0}


def _counted(owner, name, key):
    original = getattr(owner, name)

    def counted(*args, **kwargs):
        COUNTS[key] += 1
        return original(*args, **kwargs)

    setattr(owner, name, counted)


_counted(selection, "load", "load")
_counted(selection.Selection, "__init__", "selection")
_counted(plan.Plan, "_placing", "placing")
_counted(selection.Selection, "runs", "runs")


def pytest_sessionfinish(session):
    with open(os.environ["SPLIT_COUNTS"], "w") as out:
        json.dump(COUNTS, out)
"""


def test_a_session_plans_once_however_many_items(tmp_path: Path, env: dict[str, str]) -> None:
    """200 items, each asked about (the control: ``runs`` counts every one), under one
    read of the durations file, one Selection and one planning: the cost is per session."""
    items = 200
    root = project(
        tmp_path / "pkg", "".join(f"def test_{n}():\n    pass\n\n" for n in range(items))
    )
    (root / "conftest.py").write_text(_COUNTING_CONFTEST)
    durations = tmp_path / "durations.json"
    write(durations, measured({f"pkg/test/test_it.py::test_{n}": 0.01 * n for n in range(items)}))
    counts = tmp_path / "counts.json"
    given = {**env, SHARD_ENV: "2/4", DURATIONS_ENV: str(durations), "SPLIT_COUNTS": str(counts)}
    done = run_pytest(root, given, "-p", "no:cacheprovider", "test")
    assert done.returncode == 0, done.stdout + done.stderr
    assert json.loads(counts.read_text()) == {
        "load": 1,
        "selection": 1,
        "placing": 1,
        "runs": items,
    }

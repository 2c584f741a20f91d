"""``shard.view``: the plan as a person reads it, and as a tool does; the same everywhere.

The printed plan is what every machine would compute: it must not differ between
processes (``hash()`` is salted per process) nor between Pythons (3.10, the oldest
supported; 3.12, Ubuntu 24.04's). The shard package is standard library only, so the
other Pythons run it bare, straight from the checkout.
"""

from __future__ import annotations

import json
import random
import re
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import REPO

from ros_isolated_test.shard.durations import Durations, measured, write
from ros_isolated_test.shard.plan import Plan
from ros_isolated_test.shard.view import as_json, seconds, summary, text

TESTS = {"nav/test_long": 120, "nav/test_mid": 30, "msgs/test_a": 20, "msgs/test_b": 9.4}


def test_the_text_shows_each_share_its_time_and_the_bounds() -> None:
    plan = Plan(2, measured(TESTS))
    fingerprint = plan.durations.fingerprint if plan.durations else ""
    assert text(plan, None, "durations.json") == (
        f"Plan for 2 shares from the durations file durations.json (plan {fingerprint}, 4 "
        "tests): 4 tests, 0 not in the file (weighed as its median, 20.0 s)\n"
        "Expected: 179.4 s in all; lower bound 120.0 s (the larger of the total / 2 and the "
        "longest test, 120.0 s); the longest share 120.0 s, 1.00 x the lower bound\n"
        "\n"
        "Share 1/2: 120.0 s expected, 1 test\n"
        "  120.0 s  nav/test_long\n"
        "\n"
        "Share 2/2: 59.4 s expected, 3 tests\n"
        "   30.0 s  nav/test_mid\n"
        "   20.0 s  msgs/test_a\n"
        "   9.40 s  msgs/test_b\n"
    )


def test_new_tests_from_the_trees_and_gone_ones_are_said() -> None:
    plan = Plan(2, measured(TESTS))
    shown = text(plan, ["nav/test_long", "nav/test_mid", "msgs/test_a", "new/test_x"])
    assert "5 tests, 1 not in the file (weighed as its median, 20.0 s)" in shown
    assert "20.0 s  new/test_x  (new: not in the durations file, weighed as the median)" in shown
    assert "1 test of the file not in the trees (removed since, or not run there)" in shown
    # Control: with every test of the file found, no such line.
    assert "not in the trees" not in text(plan, [*TESTS, "new/test_x"])


def test_where_the_lower_bound_cannot_be_reached_the_pair_bound_says_why() -> None:
    plan = Plan(2, measured({"p/a": 10, "p/b": 10, "p/c": 10}))
    shown = text(plan)
    assert "lower bound 15.0 s" in shown
    assert "No split into 2 does better than 20.0 s: two of the 3 longest tests must share" in shown
    assert "No split into" not in text(Plan(3, measured({"p/a": 10, "p/b": 10, "p/c": 10})))


def test_by_count_lists_tests_without_times() -> None:
    shown = text(Plan(2, None), ["p/a", "p/b", "p/c"])
    assert shown.startswith("Plan for 2 shares by count (no durations): 3 tests")
    assert re.search(r"\d s\b", shown) is None  # no seconds anywhere
    assert sorted(line.strip() for line in shown.splitlines() if line.startswith("  ")) == [
        "p/a",
        "p/b",
        "p/c",
    ]


def test_an_identity_cannot_forge_a_line() -> None:
    shown = text(Plan(1, measured({"p/t\nShare 9/9: forged": 1})))
    assert "Share 9/9" not in shown.splitlines()[-1].split("  ")[0]
    assert "p/t\\x0aShare 9/9: forged" in shown
    assert len(shown.splitlines()) == 5


def test_the_json_has_every_figure_and_test() -> None:
    plan = Plan(2, measured(TESTS))
    document = json.loads(as_json(plan, [*TESTS, "new/test_x"], "d.json"))
    assert document["total"] == 2
    assert document["by"] == "durations"
    assert document["durations_file"] == "d.json"
    assert document["plan"] == measured(TESTS).fingerprint
    assert document["tests"] == 5
    assert document["not_in_durations"] == 1
    assert document["median_seconds"] == 20.0
    assert document["total_seconds"] == 199.4
    assert document["lower_bound_seconds"] == 120.0
    assert document["longest_test_seconds"] == 120.0
    assert document["not_in_trees"] == []
    assert [share["share"] for share in document["shares"]] == ["1/2", "2/2"]
    listed = [test for share in document["shares"] for test in share["tests"]]
    assert sorted(test["identity"] for test in listed) == sorted([*TESTS, "new/test_x"])
    assert {test["identity"]: test["known"] for test in listed}["new/test_x"] is False
    total = sum(share["expected_seconds"] for share in document["shares"])
    assert round(total, 3) == document["total_seconds"]


def test_the_json_by_count_has_no_seconds() -> None:
    document = json.loads(as_json(Plan(3, None), ["p/a", "p/b"]))
    assert document["by"] == document["plan"] == "count"
    assert document["total_seconds"] is None and document["durations_file"] is None
    assert all(test["seconds"] is None for share in document["shares"] for test in share["tests"])


@pytest.mark.parametrize(
    ("us", "shown"),
    [
        (0, "0.00 s"),
        (7, "0.007 ms"),  # below 10 ms: milliseconds to the microsecond, never 0.00 s
        (317, "0.317 ms"),
        (4_500, "4.500 ms"),
        (9_999, "9.999 ms"),
        (10_000, "0.01 s"),
        (14_999, "0.01 s"),
        (15_000, "0.02 s"),
        (1_234_000, "1.23 s"),
        (9_994_999, "9.99 s"),
        (9_995_000, "10.0 s"),
        (10_000_000, "10.0 s"),
        (123_456_000, "123.5 s"),
    ],
)
def test_seconds_are_shown_to_a_tenth_or_a_hundredth(us: int, shown: str) -> None:
    assert seconds(us) == shown


def test_the_summary_counts_every_test_once() -> None:
    figures = summary(Plan(3, measured(TESTS)), ["new/a", "new/b", "nav/test_long"])
    assert sum(len(tests) for tests in figures.listing) == 6
    assert figures.unknown == 2
    assert figures.total == sum(figures.loads)


# --- the same plan in every process and on every Python ------------------------------------

#: Prints the plan as text and JSON: standard library only, as the package is.
PRINT_PLAN = """
import sys
from pathlib import Path
from ros_isolated_test.shard import durations, plan, view
loaded = durations.load(Path(sys.argv[1]))
found = Path(sys.argv[2]).read_text(encoding="utf-8").splitlines()
for total in (1, 2, 3, 7):
    planned = plan.Plan(total, loaded)
    sys.stdout.write(view.text(planned, found, "durations.json"))
    sys.stdout.write(view.as_json(planned, found, "durations.json"))
sys.stdout.write(loaded.fingerprint)
# What a runner on machine 2 of 3 decides for each test, through the entry points' API.
from ros_isolated_test.shard import selection
machine = selection.select({"ROS_ISOLATED_TEST_SHARD": "2/3"}, None, sys.argv[1])
sys.stdout.write(repr(machine.properties()))
sys.stdout.write("".join("1" if machine.runs(*test.split("/", 1)) else "0" for test in found))
"""


@pytest.fixture(scope="module")
def plan_inputs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A durations file of 2,000 tests (ties, odd names) and 300 found in trees, 50 new."""
    rng = random.Random(37)
    tests = {}
    for number in range(2000):
        package = rng.choice(["nav2_util", "msgs", "py_pkg", "\u00e9t\u00e9"])
        name = rng.choice([f"test_{number}", f"test/test_{number}.py::TestA::test_b[{number}]"])
        tests[f"{package}/{name}"] = rng.choice([0.5, 1.0, 30.0, rng.lognormvariate(0, 2)])
    where = tmp_path_factory.mktemp("plan")
    durations_file = where / "durations.json"
    write(durations_file, measured(tests))
    found = [*rng.sample(sorted(tests), 250), *(f"new_pkg/test_{number}" for number in range(50))]
    found_file = where / "found.txt"
    found_file.write_text("\n".join(found), encoding="utf-8")
    return durations_file, found_file


def _printed(python: str, inputs: tuple[Path, Path], seed: str) -> str:
    done = subprocess.run(
        # -E -s: nothing from the environment or a site: the checkout's package, bare.
        [python, "-E", "-s", "-c", PRINT_PLAN, *map(str, inputs)],
        capture_output=True,
        text=True,
        check=True,
        cwd=REPO,
        env={"PYTHONHASHSEED": seed, "PATH": "/usr/bin:/bin", "LC_ALL": "C.UTF-8"},
        timeout=120,
    )
    return done.stdout


@pytest.fixture(scope="module")
def printed_here(plan_inputs: tuple[Path, Path]) -> str:
    return _printed(sys.executable, plan_inputs, "0")


def test_three_processes_print_the_same_plan(
    plan_inputs: tuple[Path, Path], printed_here: str
) -> None:
    others = {_printed(sys.executable, plan_inputs, seed) for seed in ("1", "2")}
    assert others == {printed_here}
    assert printed_here.count("Plan for 7 shares") == 1  # control: a plan was printed
    assert "(new: not in the durations file" in printed_here


@pytest.mark.parametrize(
    "need", [capabilities.PYTHON310, capabilities.PYTHON312], ids=["python3.10", "python3.12"]
)
def test_another_python_prints_the_same_plan(
    need: capabilities.Capability, plan_inputs: tuple[Path, Path], printed_here: str
) -> None:
    capabilities.require(need)
    version = need.name.removeprefix("python")
    python = capabilities.other_python(version)
    assert python is not None
    reported = subprocess.run(
        [python, "-c", "import sys; print('%d.%d' % sys.version_info[:2])"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    assert reported == version  # control: it is that Python
    assert _printed(python, plan_inputs, "3") == printed_here


def test_control_a_different_file_prints_a_different_plan(
    plan_inputs: tuple[Path, Path], printed_here: str, tmp_path: Path
) -> None:
    """The comparison can fail: one test's duration changed changes the printed plan."""
    from ros_isolated_test.shard.durations import load

    durations_file, found_file = plan_inputs
    loaded = load(durations_file)
    first = next(iter(loaded))
    changed = Durations({**loaded.micros, first: loaded.micros[first] + 60_000_000})
    other = tmp_path / "durations.json"
    write(other, changed)
    assert _printed(sys.executable, (other, found_file), "0") != printed_here


def test_quick_tests_are_said_to_be_placed_by_count() -> None:
    """Their time decides nothing (``plan.QUICK``): the header says so, and shows it."""
    durations = measured({"p/slow": 2.0, **{f"p/q{n}": 0.000317 for n in range(5)}})
    shown = text(Plan(2, durations))
    assert "5 tests quicker than a millisecond: placed by count" in shown
    assert "  0.320 ms  p/q0" in shown  # not 0.00 s
    # Control: no such line when no test is that quick.
    assert "quicker than" not in text(Plan(2, measured({"p/slow": 2.0, "p/q": 0.001})))

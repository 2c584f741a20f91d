"""The trees a split's machines leave, made quickly: for the report's merge and durations.

Each machine's tree is laid out as colcon leaves it: a RUNNER's result file per CMake test
(``<tree>/<package>/test_results/<package>/<test>.xml``, canonical, with the properties
the runner records: its version, its share and plan, its duration and when it ran), and
pytest's ``--junit-xml`` per ament_python package (``<tree>/<package>/pytest.xml``, each
item with its identity property, the share as suite properties), and beside them the
machine's records, as every runner leaves them whether it ran its test or not. Tests are
placed as the runners place them (``shard.selection``); real runs make the same files
(tests/e2e/test_split_workspace.py).
"""

from __future__ import annotations

from pathlib import Path
from xml.sax.saxutils import quoteattr

from ros_isolated_test.shard import record
from ros_isolated_test.shard.durations import Durations
from ros_isolated_test.shard.identity import PROPERTY, split
from ros_isolated_test.shard.selection import Selection
from ros_isolated_test.shard.spec import Share
from ros_isolated_test.xunit import serialise
from ros_isolated_test.xunit.model import Case, Suite
from ros_isolated_test.xunit.timeline import instant, timeline_properties

#: When the made-up run starts (seconds since the epoch).
START = 1_790_000_000.0


def runner_file(
    tree: Path,
    identity: str,
    seconds: float,
    selection: Selection | None = None,
    host: str = "machine",
    started: float = START,
) -> Path:
    """A RUNNER's canonical result file of CMake test ``identity`` (``<package>/<test>``)."""
    package, test = split(identity)
    properties = {
        "command": f"./{test}",
        "exit": "exited with code 0",
        "duration": f"{seconds:.3f}",
        "runner_version": "0.1.0",
        "ros_domain_id": "7",
        **timeline_properties(started, started + seconds, 0.0, 0.0, "1-10"),
    }
    if selection is not None:
        properties.update(selection.properties())
    name = f"{package}.{test}"
    suite = Suite(
        name=name,
        cases=[Case(name, test, time=seconds)],
        time=seconds,
        timestamp=instant(started)[:19],
        hostname=host,
        properties=properties,
    )
    path = tree / package / "test_results" / package / f"{test}.xml"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(serialise.serialize(suite))
    return path


def pytest_file(
    tree: Path,
    package: str,
    items: dict[str, float],
    selection: Selection | None = None,
    host: str = "machine",
) -> Path:
    """pytest's ``--junit-xml`` of ``package`` under the plugin: node id -> seconds."""
    properties = [] if selection is None else list(selection.properties().items())
    suite_properties = "".join(
        f"<property name={quoteattr(name)} value={quoteattr(value)}/>" for name, value in properties
    )
    cases = "".join(
        f"<testcase classname={quoteattr(package + '.' + node.split('::')[0])} "
        f'name={quoteattr(node.rsplit("::", 1)[-1])} time="{seconds:.3f}"><properties>'
        f"<property name={quoteattr(PROPERTY)} value={quoteattr(f'{package}/{node}')}/>"
        "</properties></testcase>"
        for node, seconds in sorted(items.items())
    )
    total = sum(items.values())
    path = tree / package / "pytest.xml"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(
        '<?xml version="1.0" encoding="utf-8"?><testsuites name="pytest tests">'
        f'<testsuite name="pytest" errors="0" failures="0" skipped="0" tests="{len(items)}" '
        f'time="{total:.3f}" timestamp="2026-09-21T10:00:00" hostname={quoteattr(host)}>'
        f"<properties>{suite_properties}</properties>{cases}</testsuite></testsuites>"
    )
    return path


def split_trees(
    root: Path, tests: dict[str, float], total: int, durations: Durations | None = None
) -> list[Path]:
    """One tree per share of ``tests`` (identity -> seconds) split ``total`` ways.

    A test whose name holds ``::`` is a pytest item of its package's ``pytest.xml``;
    any other a CMake test with a RUNNER's file. Every machine leaves its record in each
    package's result folder, as its runners do, and each machine is a host of its own.
    """
    trees = []
    packages = sorted({split(key)[0] for key in tests})
    for index in range(1, total + 1):
        selection = Selection(Share(index, total), durations)
        tree = root / f"shard-{index}"
        host = f"machine-{index}"
        items: dict[str, dict[str, float]] = {}
        for key, seconds in sorted(tests.items()):
            package, name = split(key)
            if not selection.runs(package, name):
                continue
            if "::" in name:
                items.setdefault(package, {})[name] = seconds
            else:
                runner_file(tree, key, seconds, selection, host)
        for package in packages:
            if any("::" in split(key)[1] for key in tests if split(key)[0] == package):
                pytest_file(tree, package, items.get(package, {}), selection, host)
                folder = tree / package
            else:
                folder = tree / package / "test_results" / package
            record.leave(folder, selection, host, "0.1.0")
        trees.append(tree)
    return trees

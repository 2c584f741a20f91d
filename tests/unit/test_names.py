"""``names``: the registry of our variables and properties, and the docs that list them.

docs/reference.md's table of environment variables and docs/result-file.md's table of
properties name exactly the registry's names; the command's ``--help`` lists every
variable of ours from it; a real run's result file writes no property it lacks. Each
check has a control that a planted difference is seen.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from helpers.commands import REPO, run_cli

from ros_isolated_test import names

DOCS = REPO / "docs"


def _first_column(text: str, heading: str) -> set[str]:
    """The backticked names in the first column of the table under ``heading``."""
    section = text.split(f"\n{heading}\n", 1)[1].split("\n#", 1)[0]
    found: set[str] = set()
    for row in re.findall(r"(?m)^\| ([^|]+) \|", section):
        found.update(re.findall(r"`([^`]+)`", row))
    return found


def _variables(text: str) -> set[str]:
    return _first_column(text, "## Environment variables")


def _properties(text: str) -> set[str]:
    return _first_column(text, "## Properties")


def test_the_reference_lists_exactly_the_registrys_variables() -> None:
    text = (DOCS / "reference.md").read_text(encoding="utf-8")
    assert _variables(text) == {entry.name for entry in names.ENVIRONMENT}
    # Control: a row the registry lacks is seen.
    planted = text.replace("| `ROS_ISOLATED_TEST_DOMAINS` |", "| `ROS_ISOLATED_TEST_DOMAINZ` |")
    assert "ROS_ISOLATED_TEST_DOMAINZ" in _variables(planted)


def test_the_result_file_page_lists_exactly_the_registrys_properties() -> None:
    text = (DOCS / "result-file.md").read_text(encoding="utf-8")
    assert _properties(text) == {entry.name for entry in names.PROPERTIES}
    planted = text.replace("| `runner_version` |", "| `runner_versio` |")
    assert "runner_version" not in _properties(planted)


def test_names_are_unique() -> None:
    for registry in (names.ENVIRONMENT, names.PROPERTIES):
        spelt = [entry.name for entry in registry]
        assert len(spelt) == len(set(spelt))


def test_the_help_lists_every_variable_of_ours(env: dict[str, str]) -> None:
    shown = run_cli(["--help"], env).stdout
    ours = [e.name for e in names.ENVIRONMENT if e.name.startswith("ROS_ISOLATED_TEST_")]
    assert ours and all(f"\n    {name}\n" in shown for name in ours), shown
    assert f"\n    {names.DISABLE}\n" in shown
    assert "\n    ROS_DOMAIN_ID\n" not in shown  # control: not ours, not listed as ours


@pytest.mark.parametrize(
    "options",
    [
        ["--rerun-failures", "1", "--resources", "cpu=1"],
        ["--shard", "1/1", "--package-name", "pkg"],
        ["--timeout", "0.3"],
    ],
)
def test_a_real_run_writes_only_registered_properties(
    env: dict[str, str], tmp_path: Path, options: list[str]
) -> None:
    result = tmp_path / "r.xml"
    command = ["sleep", "3"] if "--timeout" in options else ["sh", "-c", "exit 1"]
    run_cli(["run", "--junit-xml", str(result), *options, "--", *command], env, cwd=tmp_path)
    written = set(re.findall(r'<property name="([^"]+)"', result.read_text()))
    assert names.RUNNER_VERSION in written  # control: the file is the runner's
    bare = {re.sub(r"^attempt_\d+\.", "", name) for name in written}
    assert bare <= {entry.name for entry in names.PROPERTIES}, bare

"""``ros-isolated-test report``'s printed lines as the tests read them, and a tree to read.

colcon's line per file and the summary last (``file_lines``, ``summary_of``), and a colcon
build tree of canonical and raw files, a ctest ``Test.xml``, broken and hidden ones, with
the counts each file must get (``build_tree``).
"""

from __future__ import annotations

import re
import shutil
from dataclasses import dataclass
from pathlib import Path

from lxml import etree

from helpers.commands import run_cli
from helpers.xunit import SAMPLES

#: Where ``build_tree`` puts its result files, below its root.
RESULTS = Path("build/pkg_a/test_results/pkg_a")
#: A file's line: its path and colcon's counts.
LINE = re.compile(r"^(?P<path>.+): (\d+) tests, (\d+) errors, (\d+) failures, (\d+) skipped$")
#: The last line: the counts of every file.
SUMMARY = re.compile(r"^Summary: (\d+) tests, (\d+) errors, (\d+) failures, (\d+) skipped$")
#: ctest's own Test.xml: XML that is no test result.
CTEST_SITE = (
    '<?xml version="1.0" encoding="UTF-8"?>\n<Site BuildName="Linux" Name="vm">'
    '<Testing><TestList><Test>./t</Test></TestList><Test Status="failed"><Name>t</Name>'
    "</Test></Testing></Site>\n"
)


#: (tests, errors, failures, skipped), the order of colcon's line.
Counts = tuple[int, int, int, int]


@dataclass(frozen=True)
class Tree:
    """A tree made by :func:`build_tree`."""

    root: Path
    expected: dict[str, Counts]
    """Counts of each file report must list, by path relative to ``root``."""


def failed_cases_of(sample: Path) -> list[tuple[str, str, str, str]]:
    """(classname, name, outcome, message) of each failing case, read from the raw sample."""
    found = []
    for case in etree.parse(str(sample)).getroot().iter("testcase"):
        for child in case:
            if child.tag in ("failure", "error"):
                found.append(
                    (
                        case.get("classname", ""),
                        case.get("name", ""),
                        str(child.tag),
                        child.get("message", ""),
                    )
                )
    return found


def canonical_run(env: dict[str, str], cwd: Path, result: Path, script: str) -> None:
    """A canonical file written by ``run --junit-xml`` for a real command."""
    proc = run_cli(
        ["run", "--package-name", "pkg_a", "--junit-xml", str(result), "--", "sh", "-c", script],
        env,
        cwd=cwd,
    )
    assert result.is_file(), proc.stdout + proc.stderr


def build_tree(env: dict[str, str], tmp_path: Path) -> Tree:
    """A colcon build tree: canonical and raw files, a ctest Test.xml, broken and hidden ones."""
    root = tmp_path / "ws"
    results = root / RESULTS
    results.mkdir(parents=True)
    canonical_run(env, root, results / "talker.xml", "echo fine")
    canonical_run(env, root, results / "crash.xml", "echo boom-marker; exit 4")
    shutil.copy(SAMPLES / "pytest-9.2_xunit2.xml", results / "pytest_raw.xml")
    proc = run_cli(
        [
            "normalise",
            "--package-name",
            "pkg_a",
            str(SAMPLES / "pytest-9.2_xunit2.xml"),
            "-o",
            str(results / "pytest_canonical.xml"),
        ],
        env,
        cwd=root,
    )
    assert proc.returncode == 1, proc.stdout + proc.stderr
    shutil.copy(SAMPLES / "ament_run_test_skip_result.xml", results / "skipped_raw.xml")
    (results / "broken.xml").write_text("this is not xml\n")
    testing = root / "build/pkg_a/Testing/20260101-0000"
    testing.mkdir(parents=True)
    (testing / "Test.xml").write_text(CTEST_SITE)
    for hidden in (root / "build/.hidden", root / "build/pkg_a/.colcon"):
        hidden.mkdir(parents=True)
        shutil.copy(SAMPLES / "ament_run_test_missing_result.xml", hidden / "stale.xml")
    expected = {
        f"{RESULTS}/talker.xml": (1, 0, 0, 0),
        f"{RESULTS}/crash.xml": (1, 0, 1, 0),
        # The counts colcon reports for this sample (xunit-formats.md, section 3).
        f"{RESULTS}/pytest_raw.xml": (12, 2, 2, 3),
        f"{RESULTS}/pytest_canonical.xml": (12, 2, 2, 3),
        f"{RESULTS}/skipped_raw.xml": (1, 0, 0, 1),
        f"{RESULTS}/broken.xml": (1, 1, 0, 0),
    }
    return Tree(root, expected)


def file_lines(stdout: str) -> dict[str, Counts]:
    """Each file's counts, by the path its line shows; a file listed twice fails."""
    found: dict[str, Counts] = {}
    for line in stdout.splitlines():
        match = LINE.match(line)
        if match and not line.startswith("Summary: "):
            path, *counts = match.groups()
            assert path not in found, f"{path} listed twice"
            found[path] = (int(counts[0]), int(counts[1]), int(counts[2]), int(counts[3]))
    return found


def summary_of(stdout: str) -> Counts:
    """The counts of the summary, which must be the last line."""
    lines = [line for line in stdout.splitlines() if line.strip()]
    match = SUMMARY.match(lines[-1])
    assert match, f"last line is not the summary:\n{stdout}"
    tests, errors, failures, skipped = (int(value) for value in match.groups())
    return tests, errors, failures, skipped


def total(counts: list[Counts]) -> Counts:
    """The sum of several files' counts."""
    return (
        sum(item[0] for item in counts),
        sum(item[1] for item in counts),
        sum(item[2] for item in counts),
        sum(item[3] for item in counts),
    )

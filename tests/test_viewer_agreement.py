"""Every canonical file is read alike by ``report``, ``colcon test-result`` and xunit-viewer.

The files are produced for real: every reference sample through ``normalise``, and real
runs through the ctest RUNNER and ``run``. colcon trusts only the count attributes and
xunit-viewer only the elements (xunit-formats.md, sections 3 and 4), so agreement of the
two with ``report`` means the attributes and the elements say the same thing.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import pytest
from helpers.commands import BIN, REPO, normalise, run_cli, run_runner
from lxml import etree

from ros_isolated_test.xunit import validate

SAMPLES = Path(__file__).resolve().parent / "data" / "xunit"
SAMPLE_NAMES = sorted(path.name.removesuffix(".xml") for path in SAMPLES.glob("*.xml"))
COLCON = BIN / "colcon"
XUNIT_VIEWER = REPO / "node_modules" / ".bin" / "xunit-viewer"
PACKAGE = "mypkg"

Counts = tuple[int, int, int, int]
"""(tests, errors, failures, skipped), the order of colcon's line."""

COLCON_LINE = re.compile(
    r"^(?P<path>\S.*): (\d+) tests?, (\d+) errors?, (\d+) failures?, (\d+) skipped$"
)
COLCON_NOISE = re.compile(r"^(\[[0-9.]+s\] )?(WARNING|ERROR)\b|^Traceback ")
VIEWER_STATUS = {"✓": "passed", "✗": "failure", "!": "error", "⊘": "skipped", "?": "other"}
VIEWER_CASE = re.compile(r"^     ([✓✗!⊘?]) ")
VIEWER_TOTALS = re.compile(r"^\d+ [a-z-]+(, \d+ [a-z-]+)*$")
OWN_RESULT = (
    '<?xml version="1.0" encoding="UTF-8"?>\n<testsuites><testsuite name="own" tests="3" '
    'failures="0" errors="0" skipped="1"><testcase classname="C" name="a" time="0.1"/>'
    '<testcase classname="C" name="b" time="0.2"/><testcase classname="C" name="c">'
    '<skipped message="later"/></testcase></testsuite></testsuites>\n'
)


@dataclass(frozen=True)
class Run:
    """One real run whose canonical result joins the folder."""

    args: tuple[str, ...]
    """After ``RUNNER RESULT --package-name mypkg`` (or ``run`` options) for this run."""
    counts: Counts
    code: int
    shell: bool = False
    """Through ``ros-isolated-test run --junit-xml`` instead of the RUNNER."""
    preset_domain: bool = False


RUNS: dict[str, Run] = {
    "runner_pass": Run(("--generate-result-on-success", "--command", "true"), (1, 0, 0, 0), 0),
    "runner_no_result": Run(
        ("--generate-result-on-success", "--command", "sh", "-c", "echo out-tail; exit 5"),
        (1, 0, 1, 0),
        5,
    ),
    "runner_sigsegv": Run(
        ("--command", "sh", "-c", "echo dying; ulimit -c 0; kill -SEGV $$"), (1, 0, 1, 0), 139
    ),
    "runner_skip_code": Run(
        ("--skip-return-code", "77", "--command", "sh", "-c", "exit 77"), (1, 0, 0, 1), 77
    ),
    "runner_refused": Run(("--command", "true"), (1, 0, 1, 0), 2, preset_domain=True),
    "runner_own_file_exit_3": Run(
        ("--command", "sh", "-c", 'cat "$0" > "$1"; exit 3', "OWN", "RESULT"), (4, 0, 1, 1), 3
    ),
    "runner_undecodable_output": Run(
        ("--command", "sh", "-c", r"printf 'bad \377\376 bytes\n'; exit 2"), (1, 0, 1, 0), 2
    ),
    "run_timeout": Run(("--timeout", "1", "--", "sleep", "30"), (1, 0, 1, 0), 124, shell=True),
}
NAMES = SAMPLE_NAMES + sorted(RUNS)


@dataclass(frozen=True)
class Folder:
    """The canonical files together, and what ``report`` says of each (by file name)."""

    path: Path
    report: dict[str, Counts]
    suites: dict[str, str]
    """The suite name in each file, to find its section in xunit-viewer's output."""
    scratch: Path


def real_run(name: str, run: Run, staging: Path, runner: str, env: Mapping[str, str]) -> Path:
    """Run it for real; the canonical file it left."""
    result = staging / f"{name}.xml"
    own = staging / f"{name}.own"
    own.write_text(OWN_RESULT)
    args = [{"OWN": str(own), "RESULT": str(result)}.get(arg, arg) for arg in run.args]
    run_env = dict(env)
    if run.preset_domain:
        run_env["ROS_DOMAIN_ID"] = "5"
    if run.shell:
        options, command = args[: args.index("--")], args[args.index("--") :]
        proc = run_cli(
            ["run", "--package-name", PACKAGE, "--junit-xml", str(result), *options, *command],
            run_env,
            cwd=staging,
        )
    else:
        proc = run_runner(
            runner,
            [str(result), "--package-name", PACKAGE, *args],
            run_env,
            cwd=staging,
            errors="replace",
        )
    assert proc.returncode == run.code, proc.stdout + proc.stderr
    assert result.is_file(), proc.stdout + proc.stderr
    return result


@pytest.fixture(scope="module")
def folder(
    module_env: dict[str, str], runner_script: str, tmp_path_factory: pytest.TempPathFactory
) -> Folder:
    out = tmp_path_factory.mktemp("canonical")
    staging = tmp_path_factory.mktemp("staging")
    for name in SAMPLE_NAMES:
        normalise(SAMPLES / f"{name}.xml", out / f"{name}.xml", module_env, PACKAGE)
    for name, run in RUNS.items():
        # Only the canonical file: the test's own, kept as .orig, stays in staging.
        shutil.copy(real_run(name, run, staging, runner_script, module_env), out / f"{name}.xml")
    assert sorted(path.name for path in out.iterdir()) == sorted(f"{n}.xml" for n in NAMES)
    proc = run_cli(["report", "--json", str(out)], module_env)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    report = {
        Path(row["path"]).name: (row["tests"], row["errors"], row["failures"], row["skipped"])
        for row in json.loads(proc.stdout)["files"]
    }
    suites = {
        path.name: str(etree.parse(str(path)).getroot().xpath("string(testsuite/@name)"))
        for path in out.iterdir()
    }
    return Folder(out, report, suites, tmp_path_factory.mktemp("scratch"))


# --- the tools ---------------------------------------------------------------------------------


def colcon(base: Path, cwd: Path, *options: str) -> subprocess.CompletedProcess[str]:
    assert COLCON.is_file(), f"{COLCON} is missing: scripts/setup.sh installs colcon"
    return subprocess.run(
        [str(COLCON), "test-result", "--test-result-base", str(base), "--all", *options],
        check=False,
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=60,
    )


def colcon_files(stdout: str) -> dict[str, Counts]:
    found: dict[str, Counts] = {}
    for line in stdout.splitlines():
        match = COLCON_LINE.match(line)
        if match and not line.startswith("Summary: "):
            path, *counts = match.groups()
            found[Path(path).name] = (
                int(counts[0]),
                int(counts[1]),
                int(counts[2]),
                int(counts[3]),
            )
    return found


def xunit_viewer(results: Path, cwd: Path) -> str:
    """Its console output for ``results``; run where it may leave files, never in the repo."""
    assert XUNIT_VIEWER.exists(), f"{XUNIT_VIEWER} is missing: scripts/setup.sh installs it"
    cwd.mkdir(parents=True, exist_ok=True)
    proc = subprocess.run(
        [str(XUNIT_VIEWER), "-r", str(results), "-c", "-o", "false", "--no-clear", "-n"],
        check=False,
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=60,
    )
    output = proc.stdout + proc.stderr
    assert proc.returncode == 0, f"xunit-viewer crashed on {results}:\n{output[-3000:]}"
    assert "Failed to parse" not in output, output
    assert not (cwd / "index.html").exists()
    return proc.stdout


def viewer_counts(statuses: Mapping[str, int]) -> Counts:
    assert set(statuses) <= {"passed", "failure", "error", "skipped"}, statuses
    failures, errors, skipped = (statuses.get(key, 0) for key in ("failure", "error", "skipped"))
    return (sum(statuses.values()), errors, failures, skipped)


def viewer_totals(stdout: str) -> Counts:
    """The final counts line, e.g. ``20 passed, 7 error, 10 skipped, 14 failure``."""
    lines = [line.strip() for line in stdout.splitlines() if line.strip()]
    assert lines and VIEWER_TOTALS.match(lines[-1]), f"no counts line at the end:\n{stdout}"
    statuses: dict[str, int] = {}
    for part in lines[-1].split(", "):
        count, status = part.split(" ", 1)
        statuses[status] = statuses.get(status, 0) + int(count)
    return viewer_counts(statuses)


def viewer_suites(stdout: str, suites: Sequence[str]) -> dict[str, Counts]:
    """Counts per suite section (`` <suite name>`` then one status line per test case)."""
    headers = {f" {suite}": suite for suite in suites}
    found: dict[str, dict[str, int]] = {}
    current: str | None = None
    for line in stdout.splitlines():
        if line in headers:
            current = headers[line]
            assert current not in found, f"suite {current} shown twice"
            found[current] = {}
        elif re.match(r"^ \S", line):
            current = None
        elif current is not None and (match := VIEWER_CASE.match(line)):
            status = VIEWER_STATUS[match.group(1)]
            found[current][status] = found[current].get(status, 0) + 1
    return {suite: viewer_counts(statuses) for suite, statuses in found.items()}


# --- colcon test-result ------------------------------------------------------------------------


@pytest.mark.parametrize("name", NAMES)
def test_colcon_reads_each_canonical_file_with_reports_counts(folder: Folder, name: str) -> None:
    base = folder.scratch / "colcon" / name
    base.mkdir(parents=True)
    shutil.copy(folder.path / f"{name}.xml", base / f"{name}.xml")
    assert validate.problems(etree.parse(str(base / f"{name}.xml")).getroot()) == []
    expected = folder.report[f"{name}.xml"]
    if name in RUNS:
        assert expected == RUNS[name].counts
    proc = colcon(base, folder.scratch, "--verbose")
    noise = [line for line in proc.stdout.splitlines() if COLCON_NOISE.search(line)]
    assert noise == [], proc.stdout
    assert not re.search("WARNING|ERROR|Traceback", proc.stderr), proc.stderr
    assert colcon_files(proc.stdout) == {f"{name}.xml": expected}, proc.stdout
    _, errors, failures, _ = expected
    assert proc.returncode == (1 if errors or failures else 0), proc.stdout + proc.stderr
    # --verbose lists every failing case (and has not dropped one on the way).
    listed = [line for line in proc.stdout.splitlines() if line.startswith("- ")]
    assert len(listed) == errors + failures, proc.stdout


# --- xunit-viewer ------------------------------------------------------------------------------


def test_xunit_viewer_reads_the_folder_with_reports_counts(folder: Folder) -> None:
    stdout = xunit_viewer(folder.path, folder.scratch / "viewer")
    per_suite = viewer_suites(stdout, list(folder.suites.values()))
    by_file = {name: per_suite.get(suite) for name, suite in folder.suites.items()}
    assert by_file == folder.report
    totals = tuple(sum(counts[i] for counts in folder.report.values()) for i in range(4))
    assert viewer_totals(stdout) == totals
    assert not (REPO / "index.html").exists()


def test_xunit_viewer_reads_a_run_whose_output_was_not_utf8(folder: Folder) -> None:
    """Its encoding guesser takes any U+FFFD for "not UTF-8" and the whole run dies.

    A test printing bytes that are not UTF-8 is ordinary (binary data, a Latin-1 log).
    """
    name = "runner_undecodable_output.xml"
    alone = folder.scratch / "undecodable"
    alone.mkdir()
    shutil.copy(folder.path / name, alone / name)
    stdout = xunit_viewer(alone, folder.scratch / "viewer-undecodable")
    assert viewer_totals(stdout) == folder.report[name]


# --- control: raw files are where the readers disagree -----------------------------------------


@pytest.mark.parametrize(
    "sample",
    [
        # pytest writes the case twice; colcon counts both, xunit-viewer merges them.
        "pytest-9.2_fail_plus_teardown_error",
        # gtest's set-up failure is under failures="0": colcon sees a pass.
        "gtest-1.17.0_setupsuite_failure_after_run_test.gtest",
        # ctest's disabled test: colcon counts it skipped, xunit-viewer passed.
        "ctest-4.4.4_output-junit",
    ],
)
def test_control_raw_file_counts_differ_and_its_canonical_form_agrees(
    folder: Folder, sample: str
) -> None:
    """Proves the comparison above can fail, and that normalising is what makes it pass."""
    work = folder.scratch / "control" / sample
    raw_base = work / "raw"
    raw_base.mkdir(parents=True)
    shutil.copy(SAMPLES / f"{sample}.xml", raw_base / f"{sample}.xml")
    both = work / "both"
    both.mkdir()
    shutil.copy(SAMPLES / f"{sample}.xml", both / "raw.xml")
    shutil.copy(folder.path / f"{sample}.xml", both / "canonical.xml")
    # Without --verbose, which drops the ctest file altogether (see the next test).
    raw_colcon = colcon_files(colcon(raw_base, work).stdout)[f"{sample}.xml"]
    stdout = xunit_viewer(both, work / "viewer")
    canonical_suite = folder.suites[f"{sample}.xml"]
    raw_suites = [
        str(suite.get("name"))
        for suite in etree.parse(str(SAMPLES / f"{sample}.xml")).getroot().iter("testsuite")
    ]
    per_suite = viewer_suites(stdout, [canonical_suite, *raw_suites])
    raw_viewer = tuple(
        sum(counts[i] for suite, counts in per_suite.items() if suite != canonical_suite)
        for i in range(4)
    )
    assert raw_colcon != raw_viewer
    assert per_suite[canonical_suite] == folder.report[f"{sample}.xml"]


def test_control_colcon_verbose_drops_a_raw_ctest_file_with_a_traceback(folder: Folder) -> None:
    """The no-WARNING/ERROR check above can fail: the raw ctest file trips it."""
    base = folder.scratch / "control" / "ctest-verbose"
    base.mkdir(parents=True)
    shutil.copy(SAMPLES / "ctest-3.25.1_output-junit.xml", base / "ctest.xml")
    proc = colcon(base, folder.scratch, "--verbose")
    assert re.search(r"ERROR.*Skipping", proc.stderr), proc.stderr
    assert "Traceback" in proc.stderr
    assert colcon_files(proc.stdout) == {}
    assert proc.returncode == 0, "its failures vanished with the file"

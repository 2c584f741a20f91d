"""Result files as each consumer reads them: GitLab, Jenkins, junitparser, colcon, xunit-viewer.

Not our own reader of result files: the programs our result files are written for. Every
consumer's reading is one ``Reading`` per file in the same shape, so a test can ask whether
they all agree: counts of tests, failures, errors and skips, and the cases, each named the
way that consumer names it (``IDENTITY``). GitLab's and Jenkins' rules are written from
their sources (GitLab's ``lib/gitlab/ci/parsers/test/junit.rb``, ``reports/test_suite.rb``
and ``test_case.rb``, with ActiveSupport's ``Hash.from_xml`` type converter; Jenkins'
junit-plugin ``SuiteResult.java``/``CaseResult.java``) since neither runs here; the other
three are the real programs: junitparser (PyPI), ``colcon test-result`` and xunit-viewer
(node_modules), each run once over a folder of many files.

Surefire's attempt elements (``flakyFailure``, ``flakyError``, ``rerunFailure``,
``rerunError``), as each consumer takes them: GitLab and Jenkins' junit-plugin ignore them
(a flaky pass is a pass, a failure with reruns one failure), colcon reads only the count
attributes, junitparser's xunit2 flavour knows them (``is_flaky``), and xunit-viewer ranks a
testcase by its first child element, so a flaky pass whose first child is ``flakyFailure``
is shown with the status ``flakyFailure`` (``?``), neither passed nor failed
(``Reading.unclassified``).
"""

from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

from lxml import etree

from helpers.commands import BIN, REPO

COLCON = BIN / "colcon"
XUNIT_VIEWER = REPO / "node_modules" / ".bin" / "xunit-viewer"
#: Never a truth that the consumers' disagreement could hang on: only stops a hung tool.
HUNG = 120

FLAKY = ("flakyFailure", "flakyError")
RERUN = ("rerunFailure", "rerunError")


class CaseKey(NamedTuple):
    """A testcase as the file has it."""

    suite: str
    classname: str
    name: str


#: How each consumer names a case. colcon names only failing cases (``--verbose``).
IDENTITY: dict[str, Callable[[CaseKey], str]] = {
    # TestCase#key hashes exactly this string; one case is kept per key and status.
    "gitlab": lambda k: f"{k.suite}_{k.classname}_{k.name}",
    # ClassResult by classname, CaseResult by name (getFullName is classname.name).
    "jenkins": lambda k: f"{k.classname}/{k.name}",
    "junitparser": lambda k: f"{k.suite}/{k.classname}/{k.name}",
    # Testcase.__str__: classname and name joined by a space (no file attribute here).
    "colcon": lambda k: " ".join(part for part in (k.classname, k.name) if part),
    # The console shows a suite section and each test's name; classname is not shown.
    "xunit-viewer": lambda k: f"{k.suite}/{k.name}",
}
CONSUMERS = tuple(IDENTITY)
#: (tests, failures, errors, skipped), the order of ``Reading.counts``.
Counts = tuple[int, int, int, int]


@dataclass(frozen=True)
class Reading:
    """One file as one consumer reads it."""

    consumer: str
    tests: int
    failures: int
    errors: int
    skipped: int
    cases: Counter[str] | None
    """Every case it lists, by ``IDENTITY[consumer]``; None if it lists none (colcon)."""
    failing: Counter[str]
    """The failed and errored cases it lists."""
    suites: frozenset[str] | None = None
    """The suites it shows; None if it shows none (GitLab files cases under the job)."""
    flaky: Counter[str] = field(default_factory=Counter)
    """Cases it marks as flaky (passed after failed attempts); only junitparser does."""
    unclassified: Counter[str] = field(default_factory=Counter)
    """Cases shown with a status that is none of passed, failed, error, skipped."""
    dropped: str = ""
    """Why it dropped the whole file (or reported it as broken); empty if it did not."""

    @property
    def counts(self) -> Counts:
        """(tests, failures, errors, skipped)."""
        return (self.tests, self.failures, self.errors, self.skipped)


def _parse(path: Path) -> etree._Element:
    parser = etree.XMLParser(resolve_entities=False, no_network=True, huge_tree=True)
    return etree.parse(str(path), parser).getroot()


def _tally(
    consumer: str,
    outcomes: Iterable[tuple[str, str]],
    suites: frozenset[str] | None,
    unclassified: Counter[str] | None = None,
) -> Reading:
    """A reading from (identity, outcome) pairs; outcome is failure/error/skipped/passed."""
    pairs = list(outcomes)
    by_outcome = Counter(outcome for _, outcome in pairs)
    return Reading(
        consumer,
        tests=len(pairs),
        failures=by_outcome["failure"],
        errors=by_outcome["error"],
        skipped=by_outcome["skipped"],
        cases=Counter(identity for identity, _ in pairs),
        failing=Counter(i for i, outcome in pairs if outcome in ("failure", "error")),
        suites=suites,
        unclassified=unclassified or Counter(),
    )


def _suites(root: etree._Element) -> list[etree._Element]:
    """Every ``testsuite`` element, the root included, at any depth, in document order."""
    return ([root] if root.tag == "testsuite" else []) + list(root.iterdescendants("testsuite"))


def case_keys(path: Path) -> list[CaseKey]:
    """The file's own cases: ``testcase`` children of every ``testsuite``, in order."""
    return [
        CaseKey(suite.get("name", ""), case.get("classname", ""), case.get("name", ""))
        for suite in _suites(_parse(path))
        for case in suite.iterchildren("testcase")
    ]


def suite_names(path: Path) -> frozenset[str]:
    """The names of every ``testsuite`` of the file."""
    return frozenset(suite.get("name", "") for suite in _suites(_parse(path)))


def expected(consumer: str, keys: Sequence[CaseKey]) -> Counter[str]:
    """The identities ``consumer`` must list for ``keys``: each once, none merged."""
    return Counter(IDENTITY[consumer](key) for key in keys)


# --- GitLab ------------------------------------------------------------------------------------

#: ActiveSupport's XMLConverter raises DisallowedType for these before anything else.
_DISALLOWED_TYPES = ("yaml", "symbol")
_ISO_DATE = re.compile(r"\s*\d{4}-\d{2}-\d{2}")


def _gitlab_conversion_error(root: etree._Element) -> str:
    """Why ``Hash.from_xml`` raises on this document, or "".

    GitLab converts the whole file before looking at a case and turns any exception into a
    suite error, which drops every case of the file. The converter looks at each element's
    ``type`` attribute: "yaml" and "symbol" are refused outright; "date"/"datetime" parse
    the element's text (``Date.parse``, ``Time.xmlschema``/``DateTime.parse``) when it has
    any, raising on a non-date; "file" base64-decodes the text and fails when there is
    none. Ruby's ``Date.parse`` also takes free-form dates ("May 3"); this rule takes only
    ISO dates, so it may drop a file GitLab keeps, never keep one GitLab drops.
    """
    for element in root.iter():
        if not isinstance(element.tag, str):
            continue
        kind = element.get("type")
        text = (element.text or "").strip()
        if kind in _DISALLOWED_TYPES:
            return f"Disallowed type attribute: {kind!r} on <{element.tag}>"
        if kind in ("date", "datetime") and text and not _ISO_DATE.match(text):
            return f"type={kind!r} on <{element.tag}> with the text {text[:40]!r}"
        if kind == "file" and not text:
            return f"type='file' on <{element.tag}> with no text"
    return ""


def gitlab(path: Path) -> Reading:
    """GitLab's "Unit test reports" parser (``Gitlab::Ci::Parsers::Test::Junit``).

    Cases: every ``testcase`` under a top-level ``testsuites`` (its direct ones too) and
    under any ``testsuite`` at any depth; status by the first present of failure, error,
    skipped, else success; count attributes ignored. ``TestSuite#add_test_case`` stores
    ``test_cases[status][key] = case``, key = ``"#{suite}_#{classname}_#{name}"`` (suite:
    the enclosing element's name), so a later case with the same key and status replaces
    the earlier one: one is kept. Attempt elements are not looked at.
    """
    root = _parse(path)
    error = _gitlab_conversion_error(root)
    if error:
        return Reading("gitlab", 0, 0, 0, 0, Counter(), Counter(), dropped=error)
    kept: dict[str, dict[str, CaseKey]] = {}

    def visit(node: etree._Element) -> None:
        for case in node.iterchildren("testcase"):
            key = CaseKey(node.get("name", ""), case.get("classname", ""), case.get("name", ""))
            children = {child.tag for child in case}
            status = next((s for s in ("failure", "error", "skipped") if s in children), "passed")
            kept.setdefault(status, {})[IDENTITY["gitlab"](key)] = key
        for suite in node.iterchildren("testsuite"):
            visit(suite)

    if root.tag in ("testsuites", "testsuite"):
        visit(root)
    return _tally(
        "gitlab",
        ((identity, status) for status, cases in kept.items() for identity in cases),
        suites=None,
    )


# --- Jenkins -----------------------------------------------------------------------------------


def jenkins(path: Path) -> Reading:
    """Jenkins' junit-plugin (``hudson.tasks.junit.SuiteResult``/``CaseResult``).

    Every ``testsuite`` at any depth is visited; one is kept only if it has a direct
    ``testcase`` (or a suite-level ``error``) child, so a suite without cases disappears.
    A case without classname takes the suite's name. Status: skipped if it has a
    ``skipped`` child, else failed if it has an ``error`` or ``failure`` (the error's text
    wins; counted here as an error), else passed. Attempt elements are not read: a flaky
    pass is a pass, a failure with reruns one failure.
    """
    pairs: list[tuple[str, str]] = []
    shown: set[str] = set()
    for suite in _suites(_parse(path)):
        cases = list(suite.iterchildren("testcase"))
        if not cases and suite.find("error") is None:
            continue
        name = suite.get("name", "")
        shown.add(name)
        for case in cases:
            key = CaseKey(name, case.get("classname") or name, case.get("name", ""))
            if case.find("skipped") is not None:
                status = "skipped"
            elif case.find("error") is not None:
                status = "error"
            elif case.find("failure") is not None:
                status = "failure"
            else:
                status = "passed"
            pairs.append((IDENTITY["jenkins"](key), status))
    return _tally("jenkins", pairs, suites=frozenset(shown))


# --- junitparser -------------------------------------------------------------------------------


def junitparser(path: Path) -> Reading:
    """junitparser's xunit2 flavour (the Jenkins junit-10 shape), counts recomputed.

    ``update_statistics`` counts result elements per suite, as junitparser's users
    (EnricoMi's publish action among them) see them; flaky attempts come from ``is_flaky``.
    """
    from junitparser import xunit2

    xml = xunit2.JUnitXml.fromfile(str(path))
    counts = [0, 0, 0, 0]
    cases: Counter[str] = Counter()
    failing: Counter[str] = Counter()
    flaky: Counter[str] = Counter()
    suites: set[str] = set()
    for suite in xml:
        suites.add(str(suite.name or ""))
        suite.update_statistics()  # type: ignore[no-untyped-call]
        for i, value in enumerate((suite.tests, suite.failures, suite.errors, suite.skipped)):
            counts[i] += int(value or 0)
        for case in suite:
            assert isinstance(case, xunit2.TestCase), type(case)
            identity = IDENTITY["junitparser"](
                CaseKey(str(suite.name or ""), str(case.classname or ""), str(case.name or ""))
            )
            cases[identity] += 1
            if case.is_failure or case.is_error:
                failing[identity] += 1
            if case.is_flaky:
                flaky[identity] += 1
    tests, failures, errors, skipped = counts
    return Reading(
        "junitparser", tests, failures, errors, skipped, cases, failing, frozenset(suites), flaky
    )


# --- running the real tools over many files at once ---------------------------------------------


class Staged(NamedTuple):
    """Files copied, under unique names, into one folder a tool reads in one run."""

    folder: Path
    names: dict[str, Path]
    """Staged file name -> the original path."""


def _stage(paths: Sequence[Path], folder: Path) -> Staged:
    folder.mkdir(parents=True, exist_ok=True)
    names: dict[str, Path] = {}
    for index, path in enumerate(paths):
        name = f"{index:03d}_{path.name}" if path.name.endswith(".xml") else f"{index:03d}.xml"
        shutil.copyfile(path, folder / name)
        names[name] = path
    return Staged(folder, names)


_COLCON_FILE = re.compile(
    r"^(?P<path>\S.*?): (?P<tests>\d+) tests?, (?P<errors>\d+) errors?, "
    r"(?P<failures>\d+) failures?, (?P<skipped>\d+) skipped$"
)


def colcon_test_result(base: Path, cwd: Path, *options: str) -> subprocess.CompletedProcess[str]:
    """``colcon test-result --test-result-base BASE --all OPTIONS``, run in ``cwd``."""
    assert COLCON.is_file(), f"{COLCON} is missing: scripts/setup.sh installs colcon"
    return subprocess.run(
        [str(COLCON), "test-result", "--test-result-base", str(base), "--all", *options],
        check=False,
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=HUNG,
    )


def _colcon_file_line(line: str) -> tuple[str, Counts] | None:
    """(file name, counts) of one of colcon's per-file lines; None for any other line."""
    match = _COLCON_FILE.match(line)
    if not match or line.startswith("Summary: "):
        return None
    counts = (match["tests"], match["failures"], match["errors"], match["skipped"])
    tests, failures, errors, skipped = (int(count) for count in counts)
    return Path(match["path"]).name, (tests, failures, errors, skipped)


def colcon_counts(stdout: str) -> dict[str, Counts]:
    """What colcon counted in each file it read, by file name."""
    lines = (_colcon_file_line(line) for line in stdout.splitlines())
    return dict(found for found in lines if found is not None)


def colcon(paths: Sequence[Path], work: Path) -> dict[Path, Reading]:
    """``colcon test-result --all --verbose`` over all ``paths`` at once.

    It reads the count attributes of the ``testsuite`` children of the root (and never the
    elements); ``--verbose`` lists each failing case as ``- classname name``. A file it
    skips (WARNING/ERROR on stderr, or absent from the output) is dropped.
    """
    staged = _stage(paths, work / "colcon")
    proc = colcon_test_result(staged.folder, work, "--verbose")
    found: dict[str, Reading] = {}
    current: str | None = None
    for line in proc.stdout.splitlines():
        file_line = _colcon_file_line(line)
        if file_line is not None:
            current, counts = file_line
            found[current] = Reading("colcon", *counts, None, Counter())
        elif current is not None and line.startswith("- "):
            found[current].failing[line[2:]] += 1
        elif not line.startswith("  "):
            current = None
    readings: dict[Path, Reading] = {}
    for name, original in staged.names.items():
        complaint = [line for line in proc.stderr.splitlines() if name in line]
        if name in found and not complaint:
            readings[original] = found[name]
        else:
            reason = "\n".join(complaint) or f"not in colcon's output:\n{proc.stdout[-2000:]}"
            readings[original] = Reading("colcon", 0, 0, 0, 0, None, Counter(), dropped=reason)
    return readings


_VIEWER_STATUS = {"✓": "passed", "✗": "failure", "!": "error", "⊘": "skipped"}
_VIEWER_CASE = re.compile(r"^     (?P<icon>[✓✗!⊘?]) (?P<name>.*?) ?(?:time=\S*)?$")
_VIEWER_TOTALS = re.compile(r"^\d+ [a-z-]+(, \d+ [a-z-]+)*$")


def run_xunit_viewer(folder: Path, cwd: Path) -> subprocess.CompletedProcess[str]:
    """xunit-viewer's console over every file in ``folder``; it must not crash.

    Run in ``cwd``, where it may leave files (never the repo); asked not to write a page.
    """
    assert XUNIT_VIEWER.exists(), f"{XUNIT_VIEWER} is missing: scripts/setup.sh installs it"
    cwd.mkdir(parents=True, exist_ok=True)
    proc = subprocess.run(
        [str(XUNIT_VIEWER), "-r", str(folder), "-c", "-o", "false", "--no-clear", "-n"],
        check=False,
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=HUNG,
    )
    output = proc.stdout + proc.stderr
    assert proc.returncode == 0, f"xunit-viewer crashed on {folder}:\n{output[-3000:]}"
    assert not (cwd / "index.html").exists()
    return proc


def viewer_totals(stdout: str) -> Counts:
    """The final counts line, e.g. ``20 passed, 7 error, 10 skipped, 14 failure``."""
    lines = [line.strip() for line in stdout.splitlines() if line.strip()]
    assert lines and _VIEWER_TOTALS.match(lines[-1]), f"no counts line at the end:\n{stdout}"
    statuses: Counter[str] = Counter()
    for part in lines[-1].split(", "):
        count, status = part.split(" ", 1)
        statuses[status] += int(count)
    assert set(statuses) <= {"passed", "failure", "error", "skipped"}, statuses
    return (sum(statuses.values()), statuses["failure"], statuses["error"], statuses["skipped"])


def xunit_viewer(paths: Sequence[Path], work: Path) -> dict[Path, Reading]:
    """xunit-viewer's console over all ``paths`` at once (``run_xunit_viewer``).

    It merges suites of one name across files and cases of one name + classname within a
    suite, so every file here must name its suites uniquely (asserted). Its console shows
    one line per case under its suite's name: ``✓`` passed, ``✗`` failure, ``!`` error,
    ``⊘`` skipped, ``?`` any other status (the name of the testcase's first child element
    when that is none of these).
    """
    staged = _stage(paths, work / "xunit-viewer")
    suites_of = {name: sorted(suite_names(original)) for name, original in staged.names.items()}
    every = [suite for names in suites_of.values() for suite in names]
    duplicates = [suite for suite, n in Counter(every).items() if n > 1]
    assert not duplicates, f"suite names shared by files, xunit-viewer would merge: {duplicates}"
    proc = run_xunit_viewer(staged.folder, work / "xunit-viewer-cwd")
    output = proc.stdout + proc.stderr
    sections = _viewer_sections(proc.stdout, set(every))
    readings: dict[Path, Reading] = {}
    for name, original in staged.names.items():
        if re.search(rf"Failed to parse.*{re.escape(name)}", output):
            readings[original] = Reading(
                "xunit-viewer", 0, 0, 0, 0, Counter(), Counter(), dropped="Failed to parse"
            )
            continue
        pairs: list[tuple[str, str]] = []
        unclassified: Counter[str] = Counter()
        shown = frozenset(suite for suite in suites_of[name] if suite in sections)
        for suite in suites_of[name]:
            for icon, case_name in sections.get(suite, []):
                identity = IDENTITY["xunit-viewer"](CaseKey(suite, "", case_name))
                pairs.append((identity, _VIEWER_STATUS.get(icon, "other")))
                if icon not in _VIEWER_STATUS:
                    unclassified[identity] += 1
        readings[original] = _tally("xunit-viewer", pairs, shown, unclassified)
    return readings


def _viewer_sections(stdout: str, suites: set[str]) -> dict[str, list[tuple[str, str]]]:
    """(icon, name) of each case line, under each known suite's header line ``" <name>"``."""
    found: dict[str, list[tuple[str, str]]] = {}
    current: list[tuple[str, str]] | None = None
    for line in stdout.splitlines():
        if line.startswith(" ") and line[1:] in suites:
            current = found.setdefault(line[1:], [])
        elif current is not None and (match := _VIEWER_CASE.match(line)):
            current.append((match["icon"], match["name"]))
    return found


# --- all of them -------------------------------------------------------------------------------


def read_all(paths: Sequence[Path], work: Path | None = None) -> dict[Path, dict[str, Reading]]:
    """Every file as every consumer reads it: ``{path: {consumer: Reading}}``."""
    with tempfile.TemporaryDirectory(prefix="consumers-") as scratch:
        base = work or Path(scratch)
        by_tool = {
            "colcon": colcon(paths, base),
            "xunit-viewer": xunit_viewer(paths, base),
        }
        return {
            path: {
                "gitlab": gitlab(path),
                "jenkins": jenkins(path),
                "junitparser": junitparser(path),
                **{consumer: readings[path] for consumer, readings in by_tool.items()},
            }
            for path in paths
        }


def disagreements(path: Path, readings: Mapping[str, Reading]) -> Iterator[str]:
    """What any consumer reads differently from the file's own cases; nothing if all agree.

    The file's cases (``case_keys``) are the reference: each consumer must list every one
    of them once, under its own identity, with the same counts as every other consumer,
    show each as passed, failed, errored or skipped, and drop nothing.
    """
    keys = case_keys(path)
    all_counts = {consumer: reading.counts for consumer, reading in readings.items()}
    if len(set(all_counts.values())) > 1:
        yield f"counts (tests, failures, errors, skipped) differ: {all_counts}"
    failing_keys = [key for key, failed in zip(keys, _failed(path), strict=True) if failed]
    for consumer, reading in readings.items():
        if reading.dropped:
            yield f"{consumer} dropped the file: {reading.dropped}"
            continue
        if reading.tests != len(keys):
            yield f"{consumer} counts {reading.tests} tests, the file has {len(keys)} cases"
        if reading.cases is not None and reading.cases != expected(consumer, keys):
            missing = expected(consumer, keys) - reading.cases
            extra = reading.cases - expected(consumer, keys)
            yield f"{consumer} lists other cases: missing {dict(missing)}, extra {dict(extra)}"
        if reading.failing != expected(consumer, failing_keys):
            yield (
                f"{consumer} lists other failing cases: {dict(reading.failing)} "
                f"!= {dict(expected(consumer, failing_keys))}"
            )
        if reading.unclassified:
            yield f"{consumer} shows cases with no known status: {dict(reading.unclassified)}"
        suites = suite_names(path)
        if reading.suites is not None and reading.suites != suites:
            yield f"{consumer} shows the suites {sorted(reading.suites)}, not {sorted(suites)}"


def _failed(path: Path) -> list[bool]:
    """Per case of ``case_keys``: has a ``failure`` or ``error`` child."""
    return [
        case.find("failure") is not None or case.find("error") is not None
        for suite in _suites(_parse(path))
        for case in suite.iterchildren("testcase")
    ]

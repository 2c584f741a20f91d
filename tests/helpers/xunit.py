"""Shared by the xunit unit tests: suites made in code, documents read back, files to read.

Suites of the canonical model as the runner builds them (``suite_of``, ``passed``,
``failed``), written by the real serialiser and read back strictly (``canonical_root``: our
schema, its counts and junit-10's rules); producers' files made canonical the way the
runner does it (``canonical_of``); hostile files (entity bombs, many cases) and the
children that read them in measured memory; the result files a run leaves, checked.
"""

from __future__ import annotations

import functools
import subprocess
import sys
from pathlib import Path

from lxml import etree

from helpers import capabilities, jenkins_junit10, peak_rss
from helpers.canonical import Canonical, check_canonical
from helpers.commands import CLI, REPO
from ros_isolated_test.xunit import reader, serialise, validate
from ros_isolated_test.xunit.canonical import normalise_file
from ros_isolated_test.xunit.model import Case, Outcome, Suite
from ros_isolated_test.xunit.raw import ReadResult

#: Real result files of each producer (tests/data/README.md says what is odd in each).
SAMPLES = REPO / "tests" / "data" / "xunit"
DECLARATION = '<?xml version="1.0" encoding="UTF-8"?>\n'
CLASS = "pkg.C"
ATTEMPT_TAGS = ("flakyFailure", "flakyError", "rerunFailure", "rerunError")
MB = 1000 * 1000
#: What the placeholder says, and what a full disk makes the system say.
TIMED_OUT = "timed out"
NO_SPACE = "No space left on device"
#: A result file as a test writes it itself: one passed case.
OWN = (
    b'<?xml version="1.0"?>\n<testsuite name="own" tests="1" failures="0">'
    b'<testcase classname="own" name="its_case"/></testsuite>\n'
)


# --- suites of the model, written and read back -------------------------------------------


def suite_of(cases: list[Case], **kwargs: object) -> Suite:
    """A suite named ``pkg.test`` holding ``cases``; ``kwargs`` override its fields."""
    values: dict[str, object] = {
        "name": "pkg.test",
        "cases": cases,
        "time": 1.0,
        "timestamp": validate.timestamp(),
        "hostname": "host",
    }
    values.update(kwargs)
    return Suite(**values)  # type: ignore[arg-type]


def passed(name: str = "a") -> Case:
    return Case(CLASS, name, time=0.25)


def failed(name: str = "a", message: str = "boom", outcome: Outcome = Outcome.FAILURE) -> Case:
    """A failure (or error) with a message, a traceback as text, a type and output."""
    return Case(
        CLASS,
        name,
        outcome=outcome,
        message=message,
        text=f"Traceback: {message}",
        type="AssertionError" if outcome is Outcome.FAILURE else "RuntimeError",
        system_out=f"out of {message}",
    )


def huge(text: str) -> Case:
    """A failure whose every text is ``text``."""
    return Case(
        CLASS,
        "a",
        outcome=Outcome.FAILURE,
        message=text,
        text=text,
        type="T",
        system_out=text,
        system_err=text,
    )


def parse(data: bytes) -> etree._Element:
    """A document as lxml reads it: no entity resolved, nothing fetched, no size limit."""
    parser = etree.XMLParser(resolve_entities=False, no_network=True, huge_tree=True)
    return etree.fromstring(data, parser)


def canonical_root(made: Suite) -> etree._Element:
    """The canonical file of ``made``, failing unless our schema and junit-10's rules take it."""
    root = parse(serialise.serialize(made))
    assert validate.problems(root) == []
    assert jenkins_junit10.rejections(root) == []
    return root


def case_node(root: etree._Element, name: str) -> etree._Element:
    """The one ``<testcase>`` named ``name``."""
    [node] = [node for node in root.iter("testcase") if node.get("name") == name]
    return node


def child_tags(node: etree._Element) -> list[str]:
    return [str(child.tag) for child in node]


def attempts_of(node: etree._Element) -> list[etree._Element]:
    """A case element's earlier attempts (``flaky*`` and ``rerun*``), in order."""
    return [child for child in node if child.tag in ATTEMPT_TAGS]


def counts_of(root: etree._Element) -> tuple[str | None, ...]:
    """The suite's ``tests``, ``failures``, ``errors`` and ``skipped``, as written."""
    found = root.find("testsuite")
    assert found is not None
    return tuple(found.get(key) for key in ("tests", "failures", "errors", "skipped"))


def properties_of(root: etree._Element) -> dict[str, str]:
    return {node.get("name", ""): node.get("value", "") for node in root.iter("property")}


@functools.cache
def real_junit10() -> etree.XMLSchema:
    """The schema Jenkins' xunit-plugin validates "JUnit" input with (the outside tier)."""
    capabilities.require(capabilities.OUTSIDE)
    parser = etree.XMLParser(resolve_entities=False, no_network=True)
    return etree.XMLSchema(etree.parse(str(capabilities.JENKINS_JUNIT10_XSD), parser))


# --- producers' files, read and made canonical --------------------------------------------


def suite_xml(cases: str, attrs: str = "", head: str = DECLARATION) -> str:
    """A producer's document: ``cases`` (markup) in one suite ``s`` with ``attrs``."""
    return f'{head}<testsuites><testsuite name="s"{attrs}>{cases}</testsuite></testsuites>'


def canonical_of(tmp_path: Path, data: str | bytes, name: str = "t") -> tuple[Canonical, bytes]:
    """``data`` as a test's own result file, normalised and checked as canonical."""
    source = tmp_path / f"{name}.xml"
    source.write_bytes(data.encode() if isinstance(data, str) else data)
    rendered, _ = normalise_file(source, "pkg", name)
    out = tmp_path / f"{name}.canonical.xml"
    out.write_bytes(rendered)
    return check_canonical(out, "pkg", name), rendered


def repairs(result: Canonical) -> str:
    """What the reader repaired in the producer's file, as the canonical file says."""
    return result.properties.get("result_file_repairs", "")


def read_text(tmp_path: Path, text: str) -> ReadResult:
    """``text`` written to a file and read by the reader."""
    source = tmp_path / "t.xml"
    source.write_text(text)
    return reader.read(source)


def with_doctype(subset: str, body: str, prolog: str = DECLARATION) -> str:
    """A suite behind a DOCTYPE of ``subset``: case ``a`` passed, case ``t`` holding ``body``."""
    return (
        f'{prolog}<!DOCTYPE testsuite [{subset}]>\n<testsuite name="s">'
        f'<testcase name="a"/><testcase name="t">{body}</testcase></testsuite>'
    )


def many_cases(path: Path, count: int, outcomes: dict[int, str]) -> None:
    """``count`` cases named ``case<i>``; ``outcomes`` maps an index to failure/error/skipped."""
    with open(path, "w", encoding="utf-8") as handle:
        handle.write(f'<testsuites><testsuite name="s" tests="{count}">')
        for index in range(count):
            kind = outcomes.get(index)
            body = f'<{kind} message="{kind} {index}">trace {index}</{kind}>' if kind else ""
            handle.write(
                f'<testcase classname="C" name="case{index}" time="0.001">{body}</testcase>'
            )
        handle.write("</testsuite></testsuites>\n")


def child_rss(args: list[str], stdout: Path) -> int:
    """Run ``args`` with stdout into a file; its peak RSS in bytes, never charged with ours."""
    peak = peak_rss.measure(args, stdout=stdout)
    assert peak.returncode == 0 and not peak.timed_out, f"{args[:3]} failed"
    return peak.max_rss


def billion_laughs(levels: int) -> str:
    """``levels`` entities, each ten of the one before: 3 * 10**(levels - 1) characters."""
    entities = '<!ENTITY lol0 "lol">' + "".join(
        f'<!ENTITY lol{level} "{f"&lol{level - 1};" * 10}">' for level in range(1, levels)
    )
    return f"<!DOCTYPE r [{entities}]><r>&lol{levels - 1};</r>"


def quadratic_blowup(references: int, size: int = 50_000) -> str:
    """One ``size``-character entity, referenced ``references`` times."""
    return f'<!DOCTYPE r [<!ENTITY big "{"B" * size}">]><r>{"&big;" * references}</r>'


#: Expanded, each is 3 GB and 2.5 GB; on disk 1 kB and 300 kB.
BOMBS = {"billion-laughs": billion_laughs(10), "quadratic-blowup": quadratic_blowup(50_000)}


def modules_loaded(code: str, *names: str) -> list[bool]:
    """Which of the modules ``names`` a fresh interpreter has imported once it ran ``code``."""
    probe = f"{code}\nimport sys\nprint(*(name in sys.modules for name in {names!r}))"
    done = subprocess.run([sys.executable, "-c", probe], check=True, capture_output=True, text=True)
    return [word == "True" for word in done.stdout.split()]


# --- the result files a run leaves ----------------------------------------------------------


def valid_result(path: Path) -> etree._Element:
    """The parsed result file, failing the test unless it matches schemas/junit.xsd."""
    assert path.is_file(), f"no result file at {path}"
    root = etree.parse(str(path), etree.XMLParser(resolve_entities=False)).getroot()
    assert validate.problems(root) == [], f"{path} does not match schemas/junit.xsd"
    assert root.tag == "testsuites"
    return root


def only_error(root: etree._Element) -> str:
    """The message and text of the one case's <error>, which it must have."""
    cases = root.findall("testsuite/testcase")
    assert len(cases) == 1
    error = cases[0].find("error")
    assert error is not None, etree.tostring(cases[0]).decode()
    return f"{error.get('message')}\n{error.text}"


def argv_for(mode: str, runner_script: str, result: Path, *command: str) -> list[str]:
    """``command`` run by the CLI (``shell``) or the runner script, writing ``result``."""
    if mode == "shell":
        return [CLI, "run", "--junit-xml", str(result), "--", *command]
    return [sys.executable, "-u", runner_script, str(result), "--command", *command]

"""What "canonical" means for a result file the runner wrote, as one check tests call.

Valid against schemas/junit.xsd with counts that match its cases, accepted by Jenkins'
junit-10, and what no schema can say (the package prefix once, useful failure text, no
blank output, no producer timestamps in names). Shared by every test of a real producer.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from lxml import etree

from helpers import jenkins_junit10
from helpers.results import CaseResult, ResultSummary, load_result
from ros_isolated_test import __version__
from ros_isolated_test.schemas import junit_schema
from ros_isolated_test.xunit.validate import problems

#: xmlrunner appends the run's timestamp to a classname; canonical files never keep it.
_XMLRUNNER_SUFFIX = re.compile(r"-[0-9]{14}(?:\.|$)")


@dataclass(frozen=True)
class Canonical:
    """A canonical result file, already checked; its cases and raw tree for more checks."""

    summary: ResultSummary
    root: etree._Element

    @property
    def counts(self) -> tuple[int, int, int, int]:
        cases = self.summary.cases
        return (
            len(cases),
            sum(case.outcome == "failure" for case in cases),
            sum(case.outcome == "error" for case in cases),
            sum(case.outcome == "skipped" for case in cases),
        )

    @property
    def properties(self) -> dict[str, str]:
        return self.summary.properties

    def case(self, name: str, classname: str | None = None) -> CaseResult:
        found = [
            case
            for case in self.summary.cases
            if case.name == name and (classname is None or case.classname == classname)
        ]
        assert len(found) == 1, f"{len(found)} cases named {name!r} in {self.summary.cases}"
        return found[0]

    def element(self, name: str, classname: str | None = None) -> etree._Element:
        case = self.case(name, classname)
        return next(
            node
            for node in self.root.iter("testcase")
            if node.get("name") == case.name and node.get("classname") == case.classname
        )


def _classname_ok(classname: str, package: str) -> bool:
    # A classname that is the package itself (ament's own synthesised results, pytest's
    # collection error with --junit-prefix) is left as it is rather than made pkg.pkg.
    if classname == package:
        return True
    return classname.startswith(f"{package}.") and not classname.startswith(f"{package}.{package}.")


def check_canonical(path: Path, package: str, test_name: str) -> Canonical:
    """Fail unless ``path`` is a canonical result file of ``<package>.<test_name>``.

    Valid against schemas/junit.xsd with counts matching the cases, accepted by
    Jenkins' junit-10, and everything the schema cannot say: prefix once, useful text
    in message and element, no blank output, no producer timestamps in names.
    """
    data = path.read_bytes()
    assert re.match(rb"<\?xml [^>]*encoding=['\"]UTF-8['\"]", data), data[:80]
    data.decode("utf-8")  # strict: never invalid UTF-8
    root = etree.fromstring(data, etree.XMLParser(resolve_entities=False, no_network=True))
    schema = junit_schema()
    assert schema.validate(root), schema.error_log
    assert problems(root) == []
    assert jenkins_junit10.rejections(root) == []
    summary = load_result(path)
    suite_name = f"{package}.{test_name}"
    assert summary.suites == (suite_name,)
    assert root.get("name") == suite_name
    keys = [(case.classname, case.name) for case in summary.cases]
    assert len(keys) == len(set(keys)), f"duplicate cases: {keys}"
    for case in summary.cases:
        assert case.name and case.name.strip() == case.name
        assert _classname_ok(case.classname, package), case.classname
        assert not _XMLRUNNER_SUFFIX.search(case.classname), case.classname
        if case.outcome in ("failure", "error"):
            assert case.message.strip(), f"{case} has no message"
            assert case.text.strip(), f"{case} has no element text"
    for output in [*root.iter("system-out"), *root.iter("system-err")]:
        assert output.text and output.text.strip(), "blank system-out/system-err"
    for node in root.iter("testcase"):
        assert float(node.get("time", "")) >= 0
    assert summary.properties.get("runner_version") == __version__
    return Canonical(summary, root)

"""``xunit.validate``: a canonical file checked against our schema and its own counts.

A result holding what a test's own file said is checked at run time; one that fails
the check is a bug of ours, and must still become a valid document that says so (and
fails the run) instead of being lost. Each check is shown failing on a planted fault
beside the same document without it.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time

from helpers.xunit import CLASS, failed, parse, passed, properties_of, suite_of

from ros_isolated_test.xunit import serialise, validate
from ros_isolated_test.xunit.attempts import merge_attempts
from ros_isolated_test.xunit.model import Case, Outcome

TIMESTAMP = re.compile(r"^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d$")


def test_a_file_against_the_schema_valid_and_invalid() -> None:
    root = parse(serialise.serialize(suite_of([passed(), failed("b")])))
    assert validate.problems(root) == []
    suite = root.find("testsuite")
    assert suite is not None
    del suite.attrib["hostname"]
    [problem] = validate.problems(root)
    assert problem.startswith("line ")
    assert "hostname" in problem


def test_counts_that_disagree_with_the_cases_are_problems() -> None:
    root = parse(serialise.serialize(suite_of([passed(), failed("b")])))
    assert validate.problems(root) == []  # the control: as written, they agree
    suite = root.find("testsuite")
    assert suite is not None
    suite.set("failures", "0")
    suite.set("tests", "3")
    assert validate.problems(root) == [
        "suite pkg.test: tests=3, cases say 2",
        "suite pkg.test: failures=0, cases say 1",
    ]


def test_a_flaky_count_property_that_disagrees_with_the_cases_is_a_problem() -> None:
    merged = merge_attempts([suite_of([failed()]), suite_of([passed()])])
    assert validate.problems(parse(serialise.serialize(merged))) == []
    merged.properties["flaky_cases"] = "2"
    found = validate.problems(parse(serialise.serialize(merged)))
    assert found == ["suite pkg.test: property flaky_cases=2, cases say 1"]


def test_a_result_failing_validation_still_renders_valid_without_a_wrong_flaky_count() -> None:
    merged = merge_attempts([suite_of([failed()]), suite_of([passed()])])
    merged.properties["flaky_cases"] = "7"
    rendered = validate.render(merged)
    root = parse(rendered.data)
    assert validate.problems(root) == []
    assert rendered.failed  # the internal error says the result was ours to get right
    assert "flaky_cases" not in properties_of(root)


def test_an_invalid_result_renders_as_a_valid_internal_error_that_fails() -> None:
    """Two cases of one name break the schema's unique key: the file says it is our bug."""
    twins = suite_of([passed("a"), passed("a")], properties={"exit_code": "0"})
    unchecked = validate.render(twins, validate=False)
    assert validate.problems(parse(unchecked.data)) != [], "the control: it is invalid"
    assert not unchecked.failed
    rendered = validate.render(twins)
    root = parse(rendered.data)
    assert validate.problems(root) == []
    assert rendered.failed
    [case] = root.iter("testcase")
    error = case.find("error")
    assert error is not None and error.get("type") == "InternalError"
    assert (case.get("classname"), case.get("name")) == ("pkg.test", "result file")
    assert "does not match its own schema (a bug" in error.get("message", "")
    assert "The test had 2 case(s), 0 failed or errored." in error.get("message", "")
    assert properties_of(root)["exit_code"] == "0"


def test_a_valid_result_renders_as_it_is_written() -> None:
    made = suite_of([passed(), Case(CLASS, "s", outcome=Outcome.SKIPPED)])
    rendered = validate.render(made)
    assert rendered.data == serialise.serialize(made)
    assert not rendered.failed
    failing = validate.render(suite_of([failed()]))
    assert failing.failed and failing.data == serialise.serialize(suite_of([failed()]))


def test_a_timestamp_is_local_time_to_the_second_as_the_schema_wants() -> None:
    when = 1_790_000_000.75
    stamp = validate.timestamp(when)
    assert TIMESTAMP.match(stamp), stamp
    assert stamp == time.strftime("%Y-%m-%dT%H:%M:%S", time.localtime(when))
    probe = "from ros_isolated_test.xunit import validate; print(validate.timestamp(0.75))"
    in_india = subprocess.run(
        [sys.executable, "-c", probe],
        env={**os.environ, "TZ": "Asia/Kolkata"},
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    assert in_india == "1970-01-01T05:30:00"  # local time, as the host's clock shows it
    assert TIMESTAMP.match(validate.timestamp())
    root = parse(serialise.serialize(suite_of([passed()], timestamp=stamp)))
    assert validate.problems(root) == []
    # The control: a timestamp with its zone (what the timeline keeps) is not the schema's.
    zoned = parse(serialise.serialize(suite_of([passed()], timestamp=f"{stamp}+00:00")))
    assert validate.problems(zoned) != []


def test_the_hostname_is_never_empty() -> None:
    name = validate.hostname()
    assert name and name == name.strip()
    root = parse(serialise.serialize(suite_of([passed()], hostname=name)))
    assert validate.problems(root) == []

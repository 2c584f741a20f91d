"""Every real producer sample through ``normalise`` and through the RUNNER, into canonical form.

The samples (tests/data/xunit; tests/data/README.md says how each was made) are what
gtest, pytest, launch_testing, unittest-xml-reporting, ctest and ament's run_test.py
really write; the comments on EXPECTED and the tests below say what is odd in each.
:func:`check_canonical` is the one definition of "a canonical result file" used here
and by test_real_producers.py.
"""

from __future__ import annotations

import os
import re
import shlex
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from helpers.canonical import Canonical, check_canonical
from helpers.commands import BIN, run_cli, run_runner
from helpers.xunit import SAMPLES

PACKAGE = "mypkg"

#: (tests, failures, errors, skipped) of each sample once normalised, worked out by hand
#: from the sample and the fix rules: counts recomputed from the cases, one case per
#: (classname, name), several outcome elements merged into the worst, disabled = skipped.
EXPECTED: dict[str, tuple[int, int, int, int]] = {
    "ament_run_test_missing_result.xml": (1, 0, 1, 0),
    "ament_run_test_missing_result_tidied_ansi.xml": (1, 0, 1, 0),
    "ament_run_test_skip_result.xml": (1, 0, 0, 1),
    "ament_run_test_success_result.xml": (1, 0, 0, 0),
    # fail, timeout, regexfail, segv fail; skip, notfound (skipped elements) and the
    # status="disabled" case are skipped; pass, willfail, bigout pass. No errors attribute.
    "ctest-3.25.1_output-junit.xml": (10, 4, 0, 3),
    "ctest-4.4.4_output-junit.xml": (10, 4, 0, 3),
    # A.B and A.Crash pass; the nameless NonTestSuiteFailure case is a real failure
    # although the root says failures="0".
    "gtest-1.12.1_env_failure.xml": (3, 1, 0, 0),
    "gtest-1.17.0_env_failure.xml": (3, 1, 0, 0),
    # 13 tests (DISABLED_ included); Fail's two <failure> elements are one failed case,
    # plus Ctrl, Throws and Param/1; Skip, DISABLED_Dis and SF.X are skipped. 1.12.1 does
    # not write SF's SetUpTestSuite failure at all.
    "gtest-1.12.1_mixed.gtest.xml": (13, 4, 0, 3),
    # The same, plus the nameless case 1.17 appends to SF for its SetUpTestSuite failure
    # (the suite's own failures attribute stays 0).
    "gtest-1.17.0_mixed.gtest.xml": (14, 5, 0, 3),
    # X skipped and the nameless suite set-up failure, classnames already prefixed
    # "sfpkg." by run_test.py.
    "gtest-1.17.0_setupsuite_failure_after_run_test.gtest.xml": (2, 1, 0, 1),
    # test_exit_codes appears in three runs (suites): passed, skipped and failed; all
    # three are kept, so 5 + 1 + 1 cases.
    "launch_testing_junitxml.xml": (7, 2, 1, 2),
    "launch_testing_junitxml_ctrlchar_INVALID.xml": (7, 2, 1, 2),
    "pytest-9.2_collection_error.xml": (1, 0, 1, 0),
    # One test written twice (call failure, teardown error), tests="2": one failed case.
    "pytest-9.2_fail_plus_teardown_error.xml": (1, 1, 0, 0),
    # No test case at all: one skipped "no test cases" case, so every reader (Jenkins
    # drops a suite without cases) shows that nothing was tested.
    "pytest-9.2_no_tests.xml": (1, 0, 0, 1),
    # Four elements, two tests: test_flaky passed twice, test_always_fails passed then
    # failed (worst outcome wins).
    "pytest-9.2_rerunfailures.xml": (2, 1, 0, 0),
    # fail and xpass_strict fail; setup and teardown errors; skip, skip_inside, xfail.
    "pytest-9.2_xunit1.xml": (12, 2, 2, 3),
    "pytest-9.2_xunit2.xml": (12, 2, 2, 3),
    "pytest-9.2_xunit2_junit_logging_all.xml": (2, 1, 0, 0),
    "xmlrunner-4.0_per_class_file.xml": (1, 0, 0, 0),
    "xmlrunner-4.0_setUpClass_error.xml": (1, 0, 1, 0),
    # TestA: fail and the failing subtest fail; error and the unexpected success
    # (UnexpectedSuccess is an <error>) err; skip and expected failure skipped; TestB passes.
    "xmlrunner-4.0_single_file.xml": (8, 2, 2, 2),
}
_XMLRUNNER_SUFFIX = re.compile(r"-[0-9]{14}(?:\.|$)")


def sample_test_name(file_name: str) -> str:
    """The test name ament gives a result file: the name without the producer suffix."""
    for suffix in (".gtest.xml", ".xunit.xml", ".xml"):
        if file_name.endswith(suffix):
            return file_name[: -len(suffix)]
    return file_name


# --- the CLI, once per sample ------------------------------------------------------------


@dataclass(frozen=True)
class Normalised:
    """``ros-isolated-test normalise`` of one file: its exit code and checked output."""

    returncode: int
    result: Canonical
    path: Path


@pytest.fixture(scope="module")
def normalise(
    tmp_path_factory: pytest.TempPathFactory,
) -> Iterator[Callable[[Path], Normalised]]:
    """``ros-isolated-test normalise --package-name mypkg SOURCE``, cached per source."""
    out_dir = tmp_path_factory.mktemp("normalised")
    env = dict(os.environ)
    env["PATH"] = f"{BIN}{os.pathsep}{env.get('PATH', '')}"
    env["ROS_ISOLATED_TEST_LOCK_DIR"] = str(tmp_path_factory.mktemp("locks"))
    done: dict[Path, Normalised] = {}

    def run(source: Path) -> Normalised:
        if source not in done:
            proc = run_cli(["normalise", "--package-name", PACKAGE, str(source)], env)
            assert proc.returncode in (0, 1), proc.stderr
            path = out_dir / f"{len(done)}-{source.name}"
            path.write_bytes(proc.stdout.encode("utf-8"))
            result = check_canonical(path, PACKAGE, sample_test_name(source.name))
            done[source] = Normalised(proc.returncode, result, path)
        return done[source]

    yield run


def _failed(counts: tuple[int, int, int, int]) -> bool:
    return counts[1] + counts[2] > 0


def test_every_sample_has_expected_counts() -> None:
    assert set(EXPECTED) == {path.name for path in SAMPLES.glob("*.xml")}


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_normalise_cli_gives_canonical_result(
    normalise: Callable[[Path], Normalised], name: str
) -> None:
    done = normalise(SAMPLES / name)
    assert done.result.counts == EXPECTED[name]
    assert done.returncode == (1 if _failed(EXPECTED[name]) else 0)
    assert done.result.properties["original_result_file"] == name


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_runner_gives_canonical_result_and_keeps_the_original(
    runner_script: str, env: dict[str, str], tmp_path: Path, name: str
) -> None:
    """The test's command only copies the sample to RESULT_FILE, as a producer would."""
    sample = SAMPLES / name
    result = tmp_path / "build" / PACKAGE / "test_results" / PACKAGE / name
    command = ["sh", "-c", 'cp "$1" "$2"', "sh", str(sample), str(result)]
    args = [str(result), "--package-name", PACKAGE, "--command", *command]
    proc = run_runner(runner_script, args, env, cwd=tmp_path)
    expected = EXPECTED[name]
    assert proc.returncode == (1 if _failed(expected) else 0), proc.stdout + proc.stderr
    canonical = check_canonical(result, PACKAGE, sample_test_name(name))
    assert canonical.counts == expected
    properties = canonical.properties
    assert re.fullmatch(r"[0-9]+", properties["ros_domain_id"]), properties
    assert properties["command"] == shlex.join(command)
    assert properties["exit"] == "exited with code 0"
    assert properties["exit_code"] == "0"
    assert float(properties["duration"]) >= 0
    assert properties["original_result_file"] == f"{name}.orig"
    original = result.with_name(f"{name}.orig")
    assert original.read_bytes() == sample.read_bytes()


# --- gtest ---------------------------------------------------------------------------------

GTEST_ENV = ("gtest-1.12.1_env_failure.xml", "gtest-1.17.0_env_failure.xml")
GTEST_MIXED = ("gtest-1.12.1_mixed.gtest.xml", "gtest-1.17.0_mixed.gtest.xml")


@pytest.mark.parametrize("name", GTEST_ENV)
def test_gtest_environment_failure_gets_a_real_name(
    normalise: Callable[[Path], Normalised], name: str
) -> None:
    result = normalise(SAMPLES / name).result
    case = result.case("global environment set-up or tear-down")
    assert case.outcome == "failure"
    assert case.classname.startswith(f"{PACKAGE}.")
    assert "env failure" in case.message
    assert "env failure" in case.text
    assert [c.name for c in result.summary.cases if c.outcome == "passed"] == ["B", "Crash"]


def test_gtest_suite_setup_failure_gets_a_real_name(
    normalise: Callable[[Path], Normalised],
) -> None:
    result = normalise(SAMPLES / "gtest-1.17.0_mixed.gtest.xml").result
    case = result.case("suite set-up or tear-down", f"{PACKAGE}.SF")
    assert case.outcome == "failure"
    assert "suite setup failure" in case.message
    assert "suite setup failure" in case.text


def test_gtest_suite_setup_failure_prefixed_by_run_test_gets_a_real_name(
    normalise: Callable[[Path], Normalised],
) -> None:
    """run_test.py turned gtest's empty classname into "sfpkg.": still gtest's ad-hoc case."""
    result = normalise(SAMPLES / "gtest-1.17.0_setupsuite_failure_after_run_test.gtest.xml").result
    failed = [case for case in result.summary.cases if case.outcome == "failure"]
    assert len(failed) == 1
    assert failed[0].name == "suite set-up or tear-down", failed[0]
    assert not failed[0].classname.endswith("."), failed[0]


def test_gtest_trailing_dot_times_read_as_seconds(
    normalise: Callable[[Path], Normalised], tmp_path: Path
) -> None:
    """gtest >= 1.14 writes whole seconds as "0." and "2."; int() rejects them, we must not."""
    data = (SAMPLES / "gtest-1.17.0_mixed.gtest.xml").read_bytes()
    marker = b'name="Pass" file="t.cpp" line="4" status="run" result="completed" time="0."'
    assert marker in data
    whole = tmp_path / "whole_seconds.gtest.xml"
    whole.write_bytes(data.replace(marker, marker.replace(b'time="0."', b'time="2."')))
    result = normalise(whole).result
    assert result.element("Pass", f"{PACKAGE}.Suite1").get("time") == "2.000"
    times = {node.get("time") for node in result.root.iter("testcase")}
    assert times == {"0.000", "2.000"}
    original = normalise(SAMPLES / "gtest-1.17.0_mixed.gtest.xml").result
    assert {node.get("time") for node in original.root.iter("testcase")} == {"0.000"}


@pytest.mark.parametrize("name", GTEST_MIXED)
def test_gtest_disabled_test_is_skipped(normalise: Callable[[Path], Normalised], name: str) -> None:
    case = normalise(SAMPLES / name).result.case("DISABLED_Dis", f"{PACKAGE}.Suite1")
    assert case.outcome == "skipped"
    assert case.message


@pytest.mark.parametrize("name", GTEST_MIXED)
def test_gtest_failures_of_one_test_are_one_case_with_both_texts(
    normalise: Callable[[Path], Normalised], name: str
) -> None:
    result = normalise(SAMPLES / name).result
    case = result.case("Fail", f"{PACKAGE}.Suite1")
    assert case.outcome == "failure"
    for part in ('msg with <angle> & "quotes" and ]]> end', "Value of: false"):
        assert part in case.message
        assert part in case.text
    assert len(result.element("Fail", f"{PACKAGE}.Suite1").findall("failure")) == 1


@pytest.mark.parametrize("name", GTEST_MIXED)
def test_gtest_invalid_utf8_is_repaired_and_noted(
    normalise: Callable[[Path], Normalised], name: str
) -> None:
    result = normalise(SAMPLES / name).result
    assert "not valid text were written as" in result.properties["result_file_repairs"]
    case = result.case("Ctrl", f"{PACKAGE}.Suite1")
    assert "bad utf8 \\xff\\xfe end" in case.message
    assert case.outcome == "failure"


@pytest.mark.parametrize("name", GTEST_MIXED)
def test_gtest_typed_and_parameterised_cases_stay_apart(
    normalise: Callable[[Path], Normalised], name: str
) -> None:
    result = normalise(SAMPLES / name).result
    assert result.case("T1", f"{PACKAGE}.Ty/0").outcome == "passed"
    assert result.case("T1", f"{PACKAGE}.Ty/1").outcome == "passed"
    assert result.case("Param/0", f"{PACKAGE}.Inst/P").outcome == "passed"
    assert result.case("Param/1", f"{PACKAGE}.Inst/P").outcome == "failure"


# --- pytest --------------------------------------------------------------------------------


def test_pytest_failure_and_teardown_error_are_one_case_with_both_texts(
    normalise: Callable[[Path], Normalised],
) -> None:
    result = normalise(SAMPLES / "pytest-9.2_fail_plus_teardown_error.xml").result
    case = result.case("test_fail_and_teardown", f"{PACKAGE}.dbl.test_dbl")
    assert case.outcome == "failure"
    assert "assert False" in case.message
    assert "teardown broke" in case.message
    assert "dbl/test_dbl.py:7: AssertionError" in case.text
    assert "RuntimeError: teardown broke" in case.text


def test_pytest_rerun_attempts_are_one_case_with_the_worst_outcome(
    normalise: Callable[[Path], Normalised],
) -> None:
    result = normalise(SAMPLES / "pytest-9.2_rerunfailures.xml").result
    classname = f"{PACKAGE}.rr.test_flaky"
    assert result.case("test_flaky", classname).outcome == "passed"
    failed = result.case("test_always_fails", classname)
    assert failed.outcome == "failure"
    assert "AssertionError: always" in failed.message
    assert "rr/test_flaky.py:8: AssertionError" in failed.text


def test_pytest_families_give_the_same_cases(normalise: Callable[[Path], Normalised]) -> None:
    def cases(name: str) -> list[tuple[str, str, str]]:
        summary = normalise(SAMPLES / name).result.summary
        return [(case.classname, case.name, case.outcome) for case in summary.cases]

    xunit1 = cases("pytest-9.2_xunit1.xml")
    assert xunit1 == cases("pytest-9.2_xunit2.xml")
    # --junit-prefix=mypkg already put the package there: not prefixed a second time.
    assert ("mypkg.test_sample.TestClass", "test_param[a b]", "passed") in xunit1
    assert ("mypkg.test_sample", "test_xpass_strict", "failure") in xunit1


def test_pytest_collection_error_is_an_error_with_its_text(
    normalise: Callable[[Path], Normalised],
) -> None:
    case = normalise(SAMPLES / "pytest-9.2_collection_error.xml").result.summary.only
    assert case.outcome == "error"
    assert case.message == "collection failure"
    assert "No module named 'nonexistent_module_xyz'" in case.text


def test_pytest_captured_output_of_a_failing_case_is_kept(
    normalise: Callable[[Path], Normalised],
) -> None:
    result = normalise(SAMPLES / "pytest-9.2_xunit2_junit_logging_all.xml").result
    element = result.element("test_fail_out", f"{PACKAGE}.test_out")
    assert "fail stdout" in (element.findtext("system-out") or "")
    assert "fail stderr" in (element.findtext("system-err") or "")


# --- launch_testing ------------------------------------------------------------------------

LAUNCH = ("launch_testing_junitxml.xml", "launch_testing_junitxml_ctrlchar_INVALID.xml")


@pytest.mark.parametrize("name", LAUNCH)
def test_launch_testing_message_is_also_element_text(
    normalise: Callable[[Path], Normalised], name: str
) -> None:
    result = normalise(SAMPLES / name).result
    classname = f"{PACKAGE}.__main__.TestActive"
    for test, outcome, detail in (
        ("test_fail", "failure", "AssertionError: 1 != 2"),
        ("test_err", "error", "RuntimeError: boom"),
    ):
        case = result.case(test, classname)
        assert case.outcome == outcome
        assert detail in case.message
        assert detail in case.text
        assert "Traceback (most recent call last)" in case.text


@pytest.mark.parametrize("name", LAUNCH)
def test_launch_testing_runs_with_the_same_case_names_are_kept_apart(
    normalise: Callable[[Path], Normalised], name: str
) -> None:
    summary = normalise(SAMPLES / name).result.summary
    runs = [
        case
        for case in summary.cases
        if case.classname == f"{PACKAGE}.__main__.TestPost"
        and case.name.startswith("test_exit_codes")
    ]
    assert sorted(case.outcome for case in runs) == ["failure", "passed", "skipped"]
    assert len({case.name for case in runs}) == 3
    died = next(case for case in runs if case.outcome == "failure")
    assert "Launch stopped before the active tests finished" in died.text
    skipped = next(case for case in runs if case.outcome == "skipped")
    assert skipped.message == "skip decorator reason"


def test_launch_testing_raw_control_character_is_repaired_and_noted(
    normalise: Callable[[Path], Normalised],
) -> None:
    """The sample's raw character is U+0001 (an ANSI ESC is handled the same way)."""
    done = normalise(SAMPLES / "launch_testing_junitxml_ctrlchar_INVALID.xml")
    text = done.path.read_text("utf-8")
    assert "\x01" not in text
    assert "\x1b" not in text
    case = done.result.case("test_fail", f"{PACKAGE}.__main__.TestActive")
    shown_or_stripped = ("1 != 2 : bad \\x01 <&>", "1 != 2 : bad  <&>")
    assert any(form in case.message for form in shown_or_stripped), case.message
    assert any(form in case.text for form in shown_or_stripped), case.text
    assert "character" in done.result.properties["result_file_repairs"]


# --- unittest-xml-reporting ----------------------------------------------------------------


def test_xmlrunner_setupclass_error_gets_its_class_from_the_name(
    normalise: Callable[[Path], Normalised],
) -> None:
    case = normalise(SAMPLES / "xmlrunner-4.0_setUpClass_error.xml").result.summary.only
    assert case.classname == f"{PACKAGE}.test_suc.T"
    assert case.name == "setUpClass (test_suc.T)"
    assert case.outcome == "error"
    assert "RuntimeError: class setup broke" in case.text


@pytest.mark.parametrize(
    "name",
    [
        "xmlrunner-4.0_per_class_file.xml",
        "xmlrunner-4.0_setUpClass_error.xml",
        "xmlrunner-4.0_single_file.xml",
    ],
)
def test_xmlrunner_timestamp_suffix_is_gone(
    normalise: Callable[[Path], Normalised], name: str
) -> None:
    """xmlrunner appends its run's time (YYYYMMDDHHMMSS) to suite names; none is kept."""
    stamp = re.compile(r"-[0-9]{14}\b")
    assert stamp.search((SAMPLES / name).read_text("utf-8")), "control: the sample has one"
    text = normalise(SAMPLES / name).path.read_text("utf-8")
    assert not stamp.search(text)


def test_xmlrunner_unexpected_success_is_an_error_and_xfail_skipped(
    normalise: Callable[[Path], Normalised],
) -> None:
    result = normalise(SAMPLES / "xmlrunner-4.0_single_file.xml").result
    classname = f"{PACKAGE}.test_u.TestA"
    assert result.case("test_xpass", classname).outcome == "error"
    assert result.case("test_xfail", classname).outcome == "skipped"
    assert result.case("test_sub (i=1)", classname).outcome == "failure"
    assert result.case("test_b", f"{PACKAGE}.test_u.TestB").outcome == "passed"


# --- ctest ---------------------------------------------------------------------------------

CTEST = ("ctest-3.25.1_output-junit.xml", "ctest-4.4.4_output-junit.xml")


@pytest.mark.parametrize("name", CTEST)
def test_ctest_errors_counted_empty_output_dropped_disabled_skipped(
    normalise: Callable[[Path], Normalised], name: str
) -> None:
    result = normalise(SAMPLES / name).result
    suite = result.root.find("testsuite")
    assert suite is not None
    assert suite.get("errors") == "0"
    for test in ("timeout", "segv", "willfail"):
        element = result.element(test)
        assert element.find("system-out") is None, test
    disabled = result.case("disabled", f"{PACKAGE}.disabled")
    assert disabled.outcome == "skipped"
    for test in ("fail", "timeout", "regexfail", "segv"):
        assert result.case(test).outcome == "failure"
    if name.startswith("ctest-3."):  # 4.x writes only "Failed"
        assert "Regex=[ERROR]" in result.case("regexfail").text
    assert result.element("fail").findtext("system-out", "").startswith("failing <&> ]]> out")


# --- classname prefix ----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("name", "test", "classname"),
    [
        # already "mypkg." (pytest --junit-prefix): kept
        ("pytest-9.2_xunit2.xml", "test_pass", "mypkg.test_sample"),
        ("pytest-9.2_rerunfailures.xml", "test_flaky", "mypkg.rr.test_flaky"),
        # the package itself: "mypkg.<test name>", so it too starts with "mypkg."
        (
            "pytest-9.2_collection_error.xml",
            "dbl.test_collect_err",
            "mypkg.pytest-9.2_collection_error",
        ),
        (
            "ament_run_test_missing_result_tidied_ansi.xml",
            "ansi.missing_result",
            "mypkg.ament_run_test_missing_result_tidied_ansi",
        ),
        # anything else: prefixed once
        ("ament_run_test_missing_result.xml", "missing_result.missing_result", "mypkg.pkg"),
        ("gtest-1.17.0_mixed.gtest.xml", "Pass", "mypkg.Suite1"),
        ("launch_testing_junitxml.xml", "test_ok", "mypkg.__main__.TestActive"),
        ("pytest-9.2_xunit2_junit_logging_all.xml", "test_pass_out", "mypkg.test_out"),
        ("ctest-3.25.1_output-junit.xml", "pass", "mypkg.pass"),
    ],
)
def test_classname_has_the_package_prefix_once(
    normalise: Callable[[Path], Normalised], name: str, test: str, classname: str
) -> None:
    assert normalise(SAMPLES / name).result.case(test).classname == classname


def test_normalise_output_option_writes_the_same_file(env: dict[str, str], tmp_path: Path) -> None:
    out = tmp_path / "out.xml"
    source = SAMPLES / "pytest-9.2_fail_plus_teardown_error.xml"
    args = ["normalise", "--package-name", PACKAGE, str(source)]
    written = run_cli([*args, "-o", str(out)], env)
    printed = run_cli(args, env)
    assert (written.returncode, printed.returncode) == (1, 1), written.stderr + printed.stderr
    assert written.stdout == ""
    check_canonical(out, PACKAGE, "pytest-9.2_fail_plus_teardown_error")
    stamp = re.compile(r'timestamp="[^"]*"')
    assert stamp.sub("", out.read_text("utf-8")) == stamp.sub("", printed.stdout)

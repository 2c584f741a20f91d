"""``xunit.attempts``: every attempt of a rerun test on record: merged, bounded, valid everywhere.

Each merged suite is written by the real serialiser and checked by our schema with its
counts, by the junit-10 rules (and, in the outside tier, by the real junit-10.xsd), and
read back as xUnit: a flaky pass is a pass with ``flakyFailure`` beside it, a case that
failed every time is its ``failure`` with one ``rerunFailure`` per earlier attempt. How
one attempt element is written is ``test_serialise``'s; which shapes the schema takes,
``schemas/test_schemas``'.
"""

from __future__ import annotations

import random
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.xunit import (
    ATTEMPT_TAGS,
    CLASS,
    attempts_of,
    canonical_root,
    case_node,
    child_tags,
    counts_of,
    failed,
    huge,
    passed,
    properties_of,
    real_junit10,
    suite_of,
)
from lxml import etree

from ros_isolated_test.xunit import normalise, reader, serialise, validate
from ros_isolated_test.xunit.attempts import (
    ABSENT,
    ATTEMPT_TEXT_LIMIT,
    ATTEMPTS_KEPT,
    NOT_RUN_AGAIN,
    NOT_RUN_AGAIN_TYPE,
    RENAMED_PROPERTY,
    for_outcome,
    kept,
    merge_attempts,
)
from ros_isolated_test.xunit.model import Attempt, Case, Outcome, Suite
from ros_isolated_test.xunit.xml_text import TEXT_LIMIT

# --- the two shapes of the issue ---------------------------------------------------------------


def test_a_case_that_fails_then_passes_has_a_flaky_failure_and_no_failure() -> None:
    first = suite_of([failed(message="late node")])
    root = canonical_root(merge_attempts([first, suite_of([passed()])]))
    node = case_node(root, "a")
    assert child_tags(node) == ["system-out", "flakyFailure"]
    (flaky,) = attempts_of(node)
    assert (flaky.get("message"), flaky.get("type")) == ("late node", "AssertionError")
    assert flaky.findtext("stackTrace") == "Traceback: late node"
    assert flaky.findtext("system-out") == "out of late node"
    # A flaky pass counts as passed: no failure anywhere, and the suite did not fail.
    assert counts_of(root) == ("1", "0", "0", "0")
    assert root.find(".//failure") is None
    assert properties_of(root)["attempts"] == "2"
    assert properties_of(root)["flaky_cases"] == "1"
    assert not validate.render(merge_attempts([first, suite_of([passed()])])).failed


def test_control_without_the_merge_the_last_attempt_alone_keeps_no_history() -> None:
    """The flaky element comes from the merge, not from the serialiser of a passed case."""
    root = canonical_root(suite_of([passed()]))
    assert child_tags(case_node(root, "a")) == []


@pytest.mark.parametrize("reruns", [0, 1, 3])
def test_a_case_failing_every_time_keeps_all_attempts(reruns: int) -> None:
    attempts = [suite_of([failed(message=f"attempt {n}")]) for n in range(1, reruns + 2)]
    merged = merge_attempts(attempts)
    root = canonical_root(merged)
    node = case_node(root, "a")
    assert child_tags(node) == ["failure"] + ["rerunFailure"] * reruns + ["system-out"]
    # The failure is the last attempt's; the reruns are the earlier ones, oldest first.
    assert node[0].get("message") == f"attempt {reruns + 1}"
    messages = [child.get("message") for child in node.iter("rerunFailure")]
    assert messages == [f"attempt {n}" for n in range(1, reruns + 1)]
    assert len(node) - 1 == reruns + 1  # N+1 attempts on record (failure + N rerun*)
    assert counts_of(root) == ("1", "1", "0", "0")
    assert properties_of(root)["attempts"] == str(reruns + 1)
    assert properties_of(root)["flaky_cases"] == "0"
    assert validate.render(merged).failed


def test_errors_and_failures_keep_their_kind() -> None:
    error = Outcome.ERROR
    flaky = merge_attempts(
        [suite_of([failed(outcome=error)]), suite_of([failed()]), suite_of([passed()])]
    )
    assert child_tags(case_node(canonical_root(flaky), "a")) == [
        "system-out",
        "flakyError",
        "flakyFailure",
    ]
    rerun = merge_attempts(
        [suite_of([failed(outcome=error)]), suite_of([failed()]), suite_of([failed(outcome=error)])]
    )
    root = canonical_root(rerun)
    assert child_tags(case_node(root, "a")) == ["error", "rerunError", "rerunFailure", "system-out"]
    assert counts_of(root) == ("1", "0", "1", "0")


def test_a_failure_after_a_pass_is_a_failure_with_the_earlier_failures_only() -> None:
    attempts = [suite_of([failed(message="one")]), suite_of([passed()]), suite_of([failed()])]
    node = case_node(canonical_root(merge_attempts(attempts)), "a")
    assert child_tags(node) == ["failure", "rerunFailure", "system-out"]
    assert node[1].get("message") == "one"


def test_a_case_that_passed_every_time_has_no_attempts_and_the_others_are_counted() -> None:
    attempts = [
        suite_of([passed("steady"), failed("wobbly"), passed("skip")]),
        suite_of(
            [passed("steady"), passed("wobbly"), Case(CLASS, "skip", outcome=Outcome.SKIPPED)]
        ),
    ]
    root = canonical_root(merge_attempts(attempts))
    assert child_tags(case_node(root, "steady")) == []
    assert child_tags(case_node(root, "wobbly")) == ["system-out", "flakyFailure"]
    assert child_tags(case_node(root, "skip")) == ["skipped"]
    assert counts_of(root) == ("3", "0", "0", "1")


def test_a_skipped_case_after_a_failure_is_flaky_and_skipped() -> None:
    skipped = Case(CLASS, "a", outcome=Outcome.SKIPPED, message="no GPU")
    merged = merge_attempts([suite_of([failed()]), suite_of([skipped])])
    root = canonical_root(merged)
    assert child_tags(case_node(root, "a")) == ["skipped", "flakyFailure"]
    assert merged.cases[0].flaky
    assert counts_of(root) == ("1", "0", "0", "1")


def test_flaky_cases_counts_only_cases_that_passed_after_failing() -> None:
    """One meaning of flaky everywhere (``report``'s): a skip after failing is a skip."""
    skipped = Case(CLASS, "a", outcome=Outcome.SKIPPED, message="no GPU")
    merged = merge_attempts(
        [suite_of([failed("a"), failed("b")]), suite_of([skipped, passed("b")])]
    )
    root = canonical_root(merged)  # checked: the property agrees with the cases
    assert child_tags(case_node(root, "a")) == ["skipped", "flakyFailure"]
    assert properties_of(root)["flaky_cases"] == "1"  # b alone
    assert validate.problems(root) == []
    # The control: the validator still catches a property that disagrees with the cases.
    prop = root.find(".//property[@name='flaky_cases']")
    assert prop is not None
    prop.set("value", "2")
    assert validate.problems(root) == [f"suite {merged.name}: property flaky_cases=2, cases say 1"]


# --- cases that come and go --------------------------------------------------------------------


def test_a_case_absent_from_the_last_attempt_is_kept_skipped_with_its_failures() -> None:
    """The runner's own case of a timed-out first attempt, then the test's real cases.

    As ``ResultFile.case`` makes it: in the suite's own class, named after the test.
    """
    timeout = Case.saying("pkg.test", "test", Outcome.FAILURE, "The test timed out after 60 s")
    first = suite_of([timeout], system_out="console of the first attempt")
    merged = merge_attempts([first, suite_of([passed("real")])])
    root = canonical_root(merged)
    assert [node.get("name") for node in root.iter("testcase")] == ["real", "test"]
    node = case_node(root, "test")
    assert child_tags(node) == ["skipped", "flakyFailure"]
    expected = ABSENT.format(total=2, seen=1, outcome="failure")
    assert node[0].get("message") == expected
    assert node[1].get("message") == "The test timed out after 60 s"
    # The lone case of an attempt takes the attempt's console: where the runner put it.
    assert node[1].findtext("system-out") == "console of the first attempt"
    assert counts_of(root) == ("2", "0", "0", "1")
    assert not merged.failed


@pytest.mark.parametrize("outcome", [Outcome.FAILURE, Outcome.ERROR])
def test_a_test_case_that_failed_and_then_was_not_run_stays_failed(outcome: Outcome) -> None:
    """Issue 30, item 5: no attempt after its failure ran it, so it never passed."""
    first = suite_of([failed("a", "boom", outcome), passed("b")])
    merged = merge_attempts([first, suite_of([passed("b")])])
    root = canonical_root(merged)
    node = case_node(root, "a")
    assert child_tags(node) == [outcome.value, f"rerun{outcome.value.title()}"]
    assert node[0].get("message") == NOT_RUN_AGAIN.format(total=2, seen=1, outcome=outcome.value)
    assert node[0].get("message", "").startswith("Failed, then not run: ")
    assert node[0].get("type") == NOT_RUN_AGAIN_TYPE
    assert node[1].get("message") == "boom"  # the failure itself, kept as the attempt
    failures, errors = (1, 0) if outcome is Outcome.FAILURE else (0, 1)
    assert counts_of(root) == ("2", str(failures), str(errors), "0")
    assert merged.failed and validate.render(merged).failed
    assert not merged.cases[1].flaky
    assert properties_of(root)["flaky_cases"] == "0"


def test_control_the_same_case_run_again_and_passing_is_a_flaky_pass() -> None:
    first = suite_of([failed("a", "boom"), passed("b")])
    merged = merge_attempts([first, suite_of([passed("b"), passed("a")])])
    assert child_tags(case_node(canonical_root(merged), "a")) == ["system-out", "flakyFailure"]
    assert not merged.failed


def test_a_case_that_passed_after_failing_and_then_was_not_run_is_skipped() -> None:
    """Its last run passed: not a failure, and not a pass of the last attempt either."""
    attempts = [suite_of([failed("a"), passed("b")]), suite_of([passed("a"), passed("b")])]
    merged = merge_attempts([*attempts, suite_of([passed("b")])])
    node = case_node(canonical_root(merged), "a")
    assert child_tags(node) == ["skipped", "flakyFailure"]
    assert node[0].get("message") == ABSENT.format(total=3, seen=2, outcome="passed")
    assert not merged.failed


def test_the_runners_own_cases_about_an_attempt_are_answered_by_a_later_one(
    tmp_path: Path,
) -> None:
    """The exit, a damaged file, a lost output file: attempt 1's, its ending passed later.

    Made as the runner makes them, in the suite's own class; the same names in a class
    of the test's own stay failed.
    """
    (tmp_path / "test.xml").write_text("this is not xml\n")
    damaged = normalise.damage_case(reader.read(tmp_path / "test.xml"), "pkg", "test")
    exit_case = normalise.exit_case("pkg.test", "exited with code 1", all_passed=True)
    output = Case.saying("pkg.test", "output file", Outcome.ERROR, "No space left on device")
    own = [damaged, exit_case, output]
    merged = merge_attempts([suite_of([*own, passed("b")]), suite_of([passed("b")])])
    root = canonical_root(merged)
    for name in ("result file", "test process exit", "output file"):
        assert child_tags(case_node(root, name))[0] == "skipped", name
    assert not merged.failed
    theirs = [Case.saying(CLASS, case.name, case.outcome, case.message) for case in own]
    again = merge_attempts([suite_of([*theirs, passed("b")]), suite_of([passed("b")])])
    assert counts_of(canonical_root(again)) == ("4", "1", "2", "0")


def test_a_passed_case_absent_from_the_last_attempt_is_kept_skipped_without_attempts() -> None:
    attempts = [suite_of([passed("gone"), failed("a")]), suite_of([passed("a")])]
    root = canonical_root(merge_attempts(attempts))
    node = case_node(root, "gone")
    assert child_tags(node) == ["skipped"]
    assert node[0].get("message") == ABSENT.format(total=2, seen=1, outcome="passed")
    # A multi-case attempt's console is not pinned on one of its cases.
    assert (
        attempts_of(case_node(root, "a"))[0].find("system-out") is not None
    )  # the case's own output
    lone_output = merge_attempts(
        [suite_of([failed("a"), passed("b")], system_out="console"), suite_of([passed("a")])]
    )
    assert "console" not in serialise.serialize(lone_output).decode()


def test_a_case_that_appears_in_a_later_attempt_has_no_history() -> None:
    attempts = [suite_of([failed("a")]), suite_of([failed("a"), passed("b")])]
    root = canonical_root(merge_attempts(attempts))
    assert child_tags(case_node(root, "b")) == []
    assert child_tags(case_node(root, "a")) == ["failure", "rerunFailure", "system-out"]


def test_a_case_seen_in_some_earlier_attempts_only_keeps_those_failures() -> None:
    attempts = [
        suite_of([failed("a", "first")]),
        suite_of([passed("b")]),
        suite_of([failed("a", "third"), passed("b")]),
        suite_of([passed("a"), passed("b")]),
    ]
    node = case_node(canonical_root(merge_attempts(attempts)), "a")
    assert [child.get("message") for child in attempts_of(node)] == ["first", "third"]


# --- what the merged suite says about the run --------------------------------------------------


def test_properties_keep_each_earlier_attempts_differing_values() -> None:
    attempts = [
        suite_of([failed()], properties={"ros_domain_id": "3", "command": "t", "exit_code": "1"}),
        suite_of([passed()], properties={"ros_domain_id": "8", "command": "t", "exit_code": "0"}),
    ]
    properties = properties_of(canonical_root(merge_attempts(attempts)))
    assert properties["ros_domain_id"] == "8"
    assert properties["attempt_1.ros_domain_id"] == "3"
    assert properties["attempt_1.exit_code"] == "1"
    assert "attempt_1.command" not in properties  # the same in every attempt: said once
    assert properties["attempts"] == "2"


def test_suite_time_is_every_attempts_and_the_timestamp_the_first() -> None:
    first = suite_of([failed()], time=2.0, timestamp="2026-01-01T10:00:00")
    last = suite_of([passed()], time=3.5, timestamp="2026-01-01T10:00:09")
    merged = merge_attempts([first, last])
    assert (merged.time, merged.timestamp) == (5.5, "2026-01-01T10:00:00")


def test_a_single_attempt_is_itself_with_the_attempt_count() -> None:
    suite = suite_of([failed(), passed("b")], properties={"exit_code": "1"})
    merged = merge_attempts([suite])
    assert [case.attempts for case in merged.cases] == [[], []]
    assert merged.properties == {"exit_code": "1", "attempts": "1", "flaky_cases": "0"}


def test_no_attempt_is_a_programming_error() -> None:
    with pytest.raises(ValueError, match="at least one attempt"):
        merge_attempts([])


def test_the_inputs_are_not_changed() -> None:
    first, last = suite_of([failed()]), suite_of([passed()], properties={"x": "1"})
    merge_attempts([first, last])
    assert last.cases[0].attempts == [] and last.properties == {"x": "1"}


def test_a_producers_own_attempts_are_kept_in_order_and_renamed_for_the_final_outcome() -> None:
    """pytest-rerunfailures inside one attempt: its reruns come before that attempt's end."""
    inner = failed(message="second try")
    inner.attempts = [Attempt("rerunFailure", "first try", "E")]
    last = passed()
    last.attempts = [Attempt("flakyError", "third try", "E")]
    node = case_node(canonical_root(merge_attempts([suite_of([inner]), suite_of([last])])), "a")
    assert child_tags(node) == ["system-out", "flakyFailure", "flakyFailure", "flakyError"]
    assert [child.get("message") for child in attempts_of(node)] == [
        "first try",
        "second try",
        "third try",
    ]


def test_for_outcome_names_attempts_for_a_failed_or_a_passed_end() -> None:
    attempts = [Attempt("flakyError"), Attempt("rerunFailure")]
    assert [a.kind for a in for_outcome(attempts, Outcome.FAILURE)] == [
        "rerunError",
        "rerunFailure",
    ]
    assert [a.kind for a in for_outcome(attempts, Outcome.PASSED)] == [
        "flakyError",
        "flakyFailure",
    ]


# --- bounds: reruns cannot blow up the file ------------------------------------------------------


def test_each_attempts_text_is_bounded_keeping_both_ends() -> None:
    big = "BEGIN" + "x" * (4 * TEXT_LIMIT) + "END"
    attempts = [suite_of([huge(big)])]
    root = canonical_root(merge_attempts([*attempts, suite_of([passed()])]))
    (flaky,) = attempts_of(case_node(root, "a"))
    for value in (
        flaky.get("message"),
        flaky.findtext("stackTrace"),
        flaky.findtext("system-out"),
        flaky.findtext("system-err"),
    ):
        assert value is not None
        assert value.startswith("BEGIN") and value.endswith("END")
        assert "characters cut" in value
        assert len(value) < ATTEMPT_TEXT_LIMIT + 100


def test_only_the_oldest_and_newest_attempts_are_kept_and_the_cut_is_said() -> None:
    count = 50
    attempts = [suite_of([failed(message=f"attempt {n}")]) for n in range(1, count + 1)]
    merged = merge_attempts(attempts)
    assert len(merged.cases[0].attempts) == count - 1  # the model keeps all
    node = case_node(canonical_root(merged), "a")
    reruns = list(node.iter("rerunFailure"))
    assert len(reruns) == ATTEMPTS_KEPT
    half = ATTEMPTS_KEPT // 2
    messages = [child.get("message") for child in reruns]
    assert messages == [f"attempt {n}" for n in range(1, half + 1)] + [
        f"attempt {n}" for n in range(count - half, count)
    ]
    cut = count - 1 - ATTEMPTS_KEPT
    after_cut = reruns[half].findtext("stackTrace") or ""
    assert after_cut.startswith(f"[... {cut} more attempt(s) not kept ...]\n")
    assert after_cut.endswith(f"attempt {count - half}")
    assert properties_of(canonical_root(merged))["attempts"] == str(count)
    # Properties of earlier attempts follow the same bound.
    many = [suite_of([failed()], properties={"ros_domain_id": str(n)}) for n in range(1, count + 1)]
    kept_properties = [key for key in merge_attempts(many).properties if key.startswith("attempt_")]
    assert len(kept_properties) == ATTEMPTS_KEPT


def test_a_hundred_reruns_of_huge_output_cost_about_ten() -> None:
    big = "y" * (2 * TEXT_LIMIT)

    def size(count: int) -> int:
        attempts = [suite_of([huge(big)]) for _ in range(count)]
        return len(serialise.serialize(merge_attempts(attempts)))

    ten, hundred = size(ATTEMPTS_KEPT + 1), size(100)
    assert hundred < ten * 1.05
    # Ten attempts cost at most about the final outcome's own text and output (3 x 64 KiB).
    assert ten < 2 * 3 * TEXT_LIMIT + 3 * ATTEMPTS_KEPT * ATTEMPT_TEXT_LIMIT


def test_kept_leaves_a_short_list_alone() -> None:
    attempts = [Attempt("flakyFailure", str(n)) for n in range(ATTEMPTS_KEPT)]
    assert kept(attempts) is attempts


# --- GitLab's keys and types across attempts ---------------------------------------------------


def test_a_gitlab_type_with_edge_spaces_is_caught_when_merged_as_an_attempt() -> None:
    """A canonical ``<failure type=" symbol">`` becomes an attempt, written trimmed."""
    first = failed()
    first.type = " symbol"
    root = canonical_root(merge_attempts([suite_of([first]), suite_of([passed()])]))
    [attempt] = attempts_of(case_node(root, "a"))
    assert attempt.get("type") == "symbol (producer type)"
    alone = case_node(canonical_root(suite_of([first])), "a").find("failure")
    assert alone is not None
    assert alone.get("type") == "symbol (producer type)"
    # Control: a type GitLab leaves alone is written as given, trimmed.
    first.type = " AssertionError "
    root = canonical_root(merge_attempts([suite_of([first]), suite_of([passed()])]))
    assert [node.get("type") for node in attempts_of(case_node(root, "a"))] == ["AssertionError"]


def _gitlab_keys(root: etree._Element) -> list[str]:
    return [
        f"{suite.get('name')}_{node.get('classname')}_{node.get('name')}"
        for suite in root.iter("testsuite")
        for node in suite.iter("testcase")
    ]


def test_cases_of_different_attempts_never_share_a_gitlab_key() -> None:
    """(pkg.a, b_c) only in attempt 1 and (pkg.a_b, c) in the last are two cases."""
    failing = Case("pkg.a", "b_c", outcome=Outcome.FAILURE, message="m", text="t", type="E")
    last = suite_of([Case("pkg.a_b", "c")])
    merged = merge_attempts([suite_of([failing, Case("pkg.a_b", "c")]), last])
    assert [(case.classname, case.name) for case in merged.cases] == [
        ("pkg.a_b", "c"),
        ("pkg.a", "b_c [2]"),
    ]
    keys = _gitlab_keys(canonical_root(merged))
    assert len(set(keys)) == len(keys) == 2
    assert "renamed" in merged.properties[RENAMED_PROPERTY]
    # Control: cases whose keys differ keep their names and the merge reports nothing.
    other = Case("pkg.a", "b", outcome=Outcome.FAILURE, message="m", text="t", type="E")
    merged = merge_attempts([suite_of([other]), last])
    assert [case.name for case in merged.cases] == ["c", "b"]
    assert RENAMED_PROPERTY not in merged.properties


# --- any history at all ------------------------------------------------------------------------


def _random_history(rng: random.Random) -> list[Suite]:
    outcomes = list(Outcome)
    names = ["a", "b", "c", "d"]
    attempts = []
    for _ in range(rng.randint(1, 6)):
        cases = []
        for name in rng.sample(names, rng.randint(0, len(names))):
            outcome = rng.choice(outcomes)
            case = Case(CLASS, name, outcome=outcome, message=rng.choice(["", "m", " "]))
            case.type = rng.choice(["", "T", " "])
            case.attempts = [
                Attempt(rng.choice(("flakyFailure", "rerunError")), "inner")
                for _ in range(rng.randint(0, 2))
            ]
            case.attempts = for_outcome(case.attempts, outcome)
            cases.append(case)
        attempts.append(suite_of(cases, system_out=rng.choice(["", "console"])))
    return attempts


def test_random_histories_always_merge_into_valid_files_with_honest_counts() -> None:
    rng = random.Random(14)
    for _ in range(300):
        attempts = _random_history(rng)
        merged = merge_attempts(attempts)
        root = canonical_root(merged)
        # A case the last attempt lacks: failed if it failed when last seen, else skipped.
        seen = {case.name: case.outcome for suite in attempts for case in suite.cases}
        seen = {name: value if value.failed else Outcome.SKIPPED for name, value in seen.items()}
        last = seen | {case.name: case.outcome for case in attempts[-1].cases}
        for node in root.iter("testcase"):
            tags = child_tags(node)
            outcome = last[str(node.get("name"))]
            finals = [tag for tag in tags if tag in ("failure", "error", "skipped")]
            assert finals == ([] if outcome is Outcome.PASSED else [outcome.value]), tags
            prefix = "rerun" if outcome.failed else "flaky"
            assert all(tag.startswith(prefix) for tag in tags if tag in ATTEMPT_TAGS), tags
        flaky = sum(1 for case in merged.cases if case.flaky and case.outcome is Outcome.PASSED)
        assert properties_of(root)["flaky_cases"] == str(flaky)
        assert properties_of(root)["attempts"] == str(len(attempts))


# --- the outside tier: the real junit-10.xsd ----------------------------------------------------


@pytest.fixture(scope="module")
def junit10_xsd() -> etree.XMLSchema:
    """The schema Jenkins' xunit-plugin validates "JUnit" input with."""
    return real_junit10()


@capabilities.OUTSIDE
def test_real_junit10_accepts_every_merged_file(junit10_xsd: etree.XMLSchema) -> None:
    rng = random.Random(10)
    for _ in range(200):
        root = canonical_root(merge_attempts(_random_history(rng)))
        assert junit10_xsd.validate(root), junit10_xsd.error_log
    big = [suite_of([failed(message="x" * 3 * TEXT_LIMIT)]) for _ in range(30)]
    assert junit10_xsd.validate(canonical_root(merge_attempts(big))), junit10_xsd.error_log

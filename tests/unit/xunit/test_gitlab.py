"""``xunit.gitlab``: GitLab's JUnit import rules, and how a file is kept safe from them.

GitLab keeps one case per ``<classname>_<name>`` key and converts ``type`` values it
knows; each rule is checked on cases directly, with a case it must leave alone beside it.
"""

from __future__ import annotations

from ros_isolated_test.xunit.gitlab import (
    GITLAB_CONVERTED_TYPES,
    TYPE_LIMIT,
    distinct_gitlab_keys,
    gitlab_safe_type,
    gitlab_safe_types,
    written_type,
)
from ros_isolated_test.xunit.model import Attempt, Case, Outcome


def _failed(classname: str, name: str, type: str = "") -> Case:
    return Case(classname, name, outcome=Outcome.FAILURE, message="m", type=type)


def test_a_converted_type_keeps_what_the_producer_said() -> None:
    for value in GITLAB_CONVERTED_TYPES:
        assert gitlab_safe_type(value) == f"{value} (producer type)"
    for value in ("string", "AssertionError", "YAML", "yaml2"):  # matched exactly
        assert gitlab_safe_type(value) == value


def test_a_type_is_checked_as_written_after_trimming() -> None:
    """``"yaml "`` would be written ``"yaml"``, which drops the whole file in GitLab."""
    assert written_type(" yaml \n") == "yaml (producer type)"
    assert written_type(" AssertionError \n") == "AssertionError"
    assert written_type("   ", "InternalError") == "InternalError"
    half = "E" * (TYPE_LIMIT // 2)
    assert written_type("E" * TYPE_LIMIT * 2) == f"{half} [...] {half}"
    assert written_type("E" * TYPE_LIMIT) == "E" * TYPE_LIMIT, "at the limit: kept whole"


def test_types_of_cases_and_attempts_are_made_safe_and_said() -> None:
    case = _failed("pkg.C", "t", type="symbol")
    case.attempts.append(Attempt("rerunFailure", type=" integer "))
    kept = _failed("pkg.C", "u", type="ValueError")
    said = gitlab_safe_types([case, kept])
    assert case.type == "symbol (producer type)"
    assert case.attempts[0].type == "integer (producer type)"
    assert kept.type == "ValueError"
    assert said == (
        "2 type attribute(s) GitLab's XML converter would act on (integer, symbol) "
        "were written as '<type> (producer type)'"
    )


def test_safe_types_say_nothing_and_change_nothing() -> None:
    cases = [_failed("pkg.C", "t", type="AssertionError"), Case("pkg.C", "u")]
    assert gitlab_safe_types(cases) == ""
    assert [case.type for case in cases] == ["AssertionError", ""]


def test_cases_whose_gitlab_keys_collide_are_renamed_visibly() -> None:
    """``pkg.a`` + ``b_c`` and ``pkg.a_b`` + ``c`` are one case to GitLab, two elsewhere."""
    first, second = Case("pkg.a", "b_c"), Case("pkg.a_b", "c")
    said = distinct_gitlab_keys([first, second])
    assert (first.name, second.name) == ("b_c", "c [2]")
    assert said == (
        "1 test case(s) renamed whose GitLab key (classname_name) another case already "
        "had: pkg.a_b 'c' as 'c [2]'"
    )


def test_distinct_keys_are_left_alone() -> None:
    cases = [Case("pkg.a", "b"), Case("pkg.a", "c"), Case("pkg.b", "b")]
    assert distinct_gitlab_keys(cases) == ""
    assert [case.name for case in cases] == ["b", "c", "b"]


def test_a_new_name_never_takes_one_another_case_already_has() -> None:
    """The number skips past a name some later case carries itself."""
    cases = [Case("pkg.a", "b_c"), Case("pkg.a_b", "c"), Case("pkg.a_b", "c [2]")]
    distinct_gitlab_keys(cases)
    names = [(case.classname, case.name) for case in cases]
    assert len({f"{classname}_{name}" for classname, name in names}) == 3
    assert names[1] == ("pkg.a_b", "c [3]")


def test_a_long_list_of_renames_is_cut_after_five() -> None:
    cases = [Case("pkg.a", f"b_{index}") for index in range(7)]
    cases += [Case("pkg.a_b", f"{index}") for index in range(7)]
    said = distinct_gitlab_keys(cases)
    assert said.startswith("7 test case(s) renamed")
    assert said.count(" as ") == 5 and said.endswith("; ...")

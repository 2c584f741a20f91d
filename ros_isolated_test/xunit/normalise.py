"""Turning what a test left behind into canonical test cases.

Each producer gets something wrong for some reader (a real sample of each is in
tests/data/xunit; tests/e2e/test_normalise_samples.py says what is odd in it); the fixes
are generic where they can be and keyed to a producer's shape where not: gtest's
nameless ad-hoc failures and ``"0."`` times, pytest's duplicate cases, launch_testing's
text-only-in-message, xmlrunner's timestamped suite names, ctest's missing ``errors``
and empty output, gtest and ctest disabled tests shown as passed. Some fixes are for one
reader: GitLab's case key and its XML type converter (their rules: ``gitlab``), Jenkins
dropping a suite without cases (``no_cases``).
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable

from ros_isolated_test.text import bounded
from ros_isolated_test.xunit.builder import MAX_OUTCOMES
from ros_isolated_test.xunit.gitlab import distinct_gitlab_keys, gitlab_safe_types
from ros_isolated_test.xunit.model import Attempt, Case, Outcome
from ros_isolated_test.xunit.raw import RawCase, RawOutcome, ReadResult
from ros_isolated_test.xunit.xml_text import TEXT_LIMIT, name_token

_XMLRUNNER_SUFFIX = re.compile(r"-[0-9]{14}$")
_SETUP_CLASS = re.compile(r"^(setUpClass|tearDownClass|setUpModule|tearDownModule) \((.+)\)$")
_PRIMARY = {"failure": Outcome.FAILURE, "error": Outcome.ERROR, "skipped": Outcome.SKIPPED}


def prefixed(package: str | None, classname: str) -> str:
    """``<package>.`` exactly once in front of ``classname``."""
    if not package or classname.startswith(f"{package}."):
        return classname
    return f"{package}.{classname}"


def seconds(value: str | None) -> float:
    """A producer's time as seconds: ``"0."`` and ``"1,234.5"`` read, nonsense reads as 0."""
    if not value:
        return 0.0
    try:
        number = float(value.strip().replace(",", ""))
    except ValueError:
        return 0.0
    return number if math.isfinite(number) and number >= 0 else 0.0


def cases_from(read: ReadResult, package: str | None, fallback: str) -> list[Case]:
    """Every case the file holds, fixed and merged; damage becomes an error case.

    ``fallback`` names cases whose producer gave no class name (the test's name).
    """
    cases = [_case(raw, package, fallback, index) for index, raw in enumerate(read.cases, 1)]
    _qualify_repeats_across_suites(cases, [raw.suite for raw in read.cases])
    if read.dropped:
        cases.append(_dropped(read, package, fallback))
    claims = unreported(read)
    if read.problems:
        # The damage explains what its counts miss: one error case, not one per symptom.
        cases.append(damage_case(read, package, fallback, claims))
    elif claims:
        message = (
            f"The result file's own counts claim {' and '.join(claims)} than its test "
            "cases show; the producer reported them nowhere else."
        )
        cases.append(
            Case.saying(
                prefixed(package, fallback),
                "unreported test cases",
                Outcome.ERROR,
                message,
                "CountMismatch",
            )
        )
    cases = merge_duplicates(cases)
    renamed = distinct_gitlab_keys(cases)
    if renamed:
        read.repairs.append(renamed)
    retyped = gitlab_safe_types(cases)
    if retyped:
        read.repairs.append(retyped)
    if not cases:
        cases.append(no_cases(prefixed(package, fallback)))
    return cases


def unreported(read: ReadResult) -> list[str]:
    """What the producer's own counts claim beyond what its cases show, per kind.

    Tests, failures and errors (together: producers mix them up), and skips (with
    ``disabled``, which gtest and ctest count apart) are all treated alike: a claim no
    element shows is reported, never silently dropped; more elements than claimed
    (pytest's duplicate cases and reruns) is normal and not reported.
    """
    kept_skips = sum(1 for raw in read.cases if _skipped(raw))
    claims = (
        ("test case(s)", _claimed(read, "tests"), len(read.cases) + sum(read.dropped.values())),
        ("failure(s) or error(s)", _claimed(read, "failures", "errors"), _failed_elements(read)),
        (
            "skipped test(s)",
            _claimed(read, "skipped", "disabled"),
            kept_skips + read.dropped["skipped"],
        ),
    )
    return [f"{claimed - shown} more {what}" for what, claimed, shown in claims if claimed > shown]


def _skipped(raw: RawCase) -> bool:
    if any(item.tag == "skipped" for item in raw.outcomes):
        return True
    return raw.attrs.get("status") == "disabled" or raw.attrs.get("result") == "suppressed"


#: The type of :func:`no_cases`'s case.
NO_CASES_TYPE = "NoTestCases"


def no_cases(classname: str) -> Case:
    """The one case of a result that holds none, so every reader shows that nothing ran.

    Jenkins drops a suite without a ``<testcase>`` and others show an empty, passing
    suite. A skip is shown by all of them and fails nothing by itself: the test's exit
    decides (pytest's 5, "no tests collected", fails the run through the exit case).
    """
    message = (
        "The result file reports no test cases: nothing was tested. An empty test "
        "selection or discovery is usually a mistake in the test's configuration."
    )
    return Case.saying(classname, "no test cases", Outcome.SKIPPED, message, NO_CASES_TYPE)


def _count(attrs: dict[str, str], *names: str) -> int:
    total = 0
    for name in names:
        try:
            total += max(int(float(attrs.get(name, "0") or "0")), 0)
        except (ValueError, OverflowError):
            continue
    return total


def _claimed(read: ReadResult, *names: str) -> int:
    """What the producer's own counts say: the root's or the suites' total, the larger."""
    root = _count(read.root_attrs, *names) if read.is_xunit else 0
    suites = sum(_count(suite.attrs, *names) for suite in read.suites)
    return max(root, suites)


def _failed_elements(read: ReadResult) -> int:
    failed = sum(
        1 for raw in read.cases if any(item.tag in ("failure", "error") for item in raw.outcomes)
    )
    return failed + read.dropped["failure"] + read.dropped["error"]


def _qualify_repeats_across_suites(cases: list[Case], suites: list[str]) -> None:
    """Name a case repeated in another suite after that suite, so it is kept, not merged.

    Such a repeat is another run (launch_testing's parametrised runs), not a duplicate.
    """
    owner: dict[tuple[str, str], str] = {}
    for case, suite in zip(cases, suites, strict=False):
        first = owner.setdefault((case.classname, case.name), suite)
        if first != suite:
            case.name = f"{case.name} [{suite}]"


def damage_case(
    read: ReadResult, package: str | None, fallback: str, claims: Iterable[str] = ()
) -> Case:
    """What was wrong with the file, as an error case, so no reader misses it."""
    kept = len(read.cases)
    detail = "; ".join(read.problems)
    message = f"Invalid result file {read.path.name}, not fully readable: {detail}."
    if kept:
        message += f" {kept} test case(s) before the damage were kept."
    missing = " and ".join(claims)
    if missing:
        message += f" Its own counts claim {missing} than the kept test cases show."
    return Case.saying(
        prefixed(package, fallback), "result file", Outcome.ERROR, message, "BrokenResultFile"
    )


def _dropped(read: ReadResult, package: str | None, fallback: str) -> Case:
    total = sum(read.dropped.values())
    failed = read.dropped["failure"] + read.dropped["error"]
    worst = max((_PRIMARY.get(kind, Outcome.PASSED) for kind in read.dropped), key=_rank)
    message = f"{total} further test case(s) were not kept, to keep the file small: " + ", ".join(
        f"{count} {kind}" for kind, count in sorted(read.dropped.items())
    )
    return Case(
        classname=prefixed(package, fallback),
        name="further test cases",
        outcome=worst if failed or worst is Outcome.SKIPPED else Outcome.PASSED,
        message=message if worst is not Outcome.PASSED else "",
        text=message if worst is not Outcome.PASSED else "",
        system_out=message if worst is Outcome.PASSED else "",
    )


def _rank(outcome: Outcome) -> int:
    return outcome.rank


def _case(raw: RawCase, package: str | None, fallback: str, index: int) -> Case:
    attrs = raw.attrs
    # One line, bounded: as written, so merging sees the names the file will carry.
    name = name_token(attrs.get("name", ""), "")
    classname = name_token(attrs.get("classname", ""), "")
    suite = _XMLRUNNER_SUFFIX.sub("", raw.suite.strip())
    setup = _SETUP_CLASS.match(name)
    if not classname and setup:
        # xmlrunner reports a setUpClass error with the class only inside the name.
        classname = _XMLRUNNER_SUFFIX.sub("", setup.group(2))
    if not name and (not classname or classname.endswith(".")) and raw.outcomes:
        # gtest's ad-hoc failures: an environment or suite set-up/tear-down failed. Its
        # empty classname may already carry upstream run_test.py's "<package>." prefix.
        name = (
            "global environment set-up or tear-down"
            if suite == "NonTestSuiteFailure"
            else "suite set-up or tear-down"
        )
        classname = suite
    classname = classname.rstrip(".") or suite or fallback
    if package and classname == package:
        # ament's own results and pytest's collection errors name only the package.
        classname = f"{package}.{fallback}"
    name = name or f"unnamed test case {index}"
    case = Case(
        classname=prefixed(package, classname),
        name=name,
        time=seconds(attrs.get("time")),
        system_out=raw.system_out if raw.system_out.strip() else "",
        system_err=raw.system_err if raw.system_err.strip() else "",
    )
    _set_outcome(case, raw)
    if not raw.complete and not case.outcome.failed:
        case.outcome = Outcome.ERROR
        case.message = case.text = "The result file ends inside this test case."
        case.type = "BrokenResultFile"
    return case


def _set_outcome(case: Case, raw: RawCase) -> None:
    primary = [item for item in raw.outcomes if item.tag in _PRIMARY]
    notes = [item for item in raw.outcomes if item.tag not in _PRIMARY]
    status = raw.attrs.get("status", "")
    if not primary and (status == "disabled" or raw.attrs.get("result") == "suppressed"):
        # gtest DISABLED_ and ctest DISABLED tests: xunit-viewer shows them as passed.
        case.outcome = Outcome.SKIPPED
        case.message = case.text = "disabled"
        return
    if primary:
        case.outcome = max((_PRIMARY[item.tag] for item in primary), key=_rank)
        ordered = sorted(primary, key=lambda item: -_PRIMARY[item.tag].rank)
        case.type = ordered[0].attrs.get("type", "")
        case.message = _join(_message(item) for item in ordered)
        case.text = _join(_text(item) for item in ordered)
        if case.outcome.failed:
            case.message = case.message or case.text or "failed (no message was given)"
            case.text = case.text or case.message
        elif case.message and not case.text:
            case.text = case.message
    # Surefire's rerun/flaky elements: earlier attempts, not the outcome.
    for item in notes:
        case.attempts.append(
            Attempt(
                _attempt_kind(item.tag, case.outcome),
                message=_message(item),
                type=item.attrs.get("type", ""),
                text=_text(item),
                system_out=item.system_out if item.system_out.strip() else "",
                system_err=item.system_err if item.system_err.strip() else "",
            )
        )


def _attempt_kind(tag: str, final: Outcome) -> str:
    """An earlier attempt's element, named after the final outcome as Surefire means it.

    ``flaky*`` when the case finally passed, ``rerun*`` when it failed, whatever the
    producer wrote and after duplicates are merged: Jenkins reads them so.
    """
    kind = "Error" if tag.endswith("Error") else "Failure"
    return f"rerun{kind}" if final.failed else f"flaky{kind}"


def _message(item: RawOutcome) -> str:
    return item.attrs.get("message", "").strip()


def _text(item: RawOutcome) -> str:
    return item.text.strip()


def _join(parts: Iterable[str]) -> str:
    kept: list[str] = []
    for part in parts:
        if part and part not in kept:
            kept.append(part)
    return bounded("\n\n".join(kept), TEXT_LIMIT)


def merge_duplicates(cases: list[Case]) -> list[Case]:
    """One case per (classname, name): GitLab keeps only the first, xunit-viewer merges.

    pytest writes a failing test with a teardown error twice, and each rerun attempt
    once; the merged case has the worst outcome and every message.
    """
    merged: dict[tuple[str, str], Case] = {}
    for case in cases:
        key = (case.classname, case.name)
        first = merged.get(key)
        if first is None:
            merged[key] = case
            continue
        if case.outcome.rank > first.outcome.rank:
            first.outcome, first.type = case.outcome, case.type
            first.message = _join([case.message, first.message])
            first.text = _join([case.text, first.text])
        elif case.outcome.rank == first.outcome.rank or case.outcome.failed:
            first.message = _join([first.message, case.message])
            first.text = _join([first.text, case.text])
        first.time = max(first.time, case.time)
        # Bounded as the reader bounds one case's elements: many duplicates must not
        # make one case of unbounded size.
        first.attempts += case.attempts[: max(MAX_OUTCOMES - len(first.attempts), 0)]
        for attempt in first.attempts:
            attempt.kind = _attempt_kind(attempt.kind, first.outcome)
        first.system_out = _join([first.system_out, case.system_out])
        first.system_err = _join([first.system_err, case.system_err])
    return list(merged.values())


def exit_case(classname: str, reason: str, all_passed: bool) -> Case:
    """The test's exit, as a failed case, when it contradicts or adds to the cases.

    A test that exits 1 while every case it reported passed, or one that dies of a
    signal or a timeout after writing its file, is not a passing test.
    """
    message = f"The test process {reason}"
    message += ", although every test case it reported passed." if all_passed else "."
    return Case.saying(classname, "test process exit", Outcome.FAILURE, message, "ExitStatus")

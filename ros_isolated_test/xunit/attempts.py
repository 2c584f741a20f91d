"""Every attempt of a rerun test in one suite: the last attempt's word, earlier failures kept.

A rerun that overwrites the failed attempt's file hides the flake. Here each case of the
last attempt carries the failures of the earlier ones in Surefire's shape, which Jenkins
and junitparser read: ``flaky*`` when the case finally passed (or was skipped),
``rerun*`` when it failed every time. A case that failed and that no later attempt ran
never passed: it stays a failure ("failed, then not run"). What is kept is bounded
(:func:`kept`), so a hundred reruns cost a result file about as much as ten.
"""

from __future__ import annotations

import re

from ros_isolated_test import names
from ros_isolated_test.xunit.gitlab import distinct_gitlab_keys
from ros_isolated_test.xunit.model import Attempt, Case, Outcome, Suite

TYPE_CHECKING = False
if TYPE_CHECKING:
    from collections.abc import Sequence

#: Suite property: how many attempts ran.
ATTEMPTS_PROPERTY = names.ATTEMPTS
#: Suite property: how many cases passed after failing at least once (flaky, as ``report``
#: counts it; a case skipped after failing is a skip).
FLAKY_PROPERTY = names.FLAKY_CASES
#: Suite property: which cases were renamed so no two share a GitLab key (if any were).
RENAMED_PROPERTY = names.RENAMED_CASES
#: Earlier attempts kept per case: the oldest half and the newest half, the middle counted.
ATTEMPTS_KEPT = 10
#: Characters kept of each attempt's message, text, system-out and system-err: the final
#: outcome keeps 64 KiB of each, so ten attempts cost about as much as the case itself.
ATTEMPT_TEXT_LIMIT = 8 * 1024
#: How :func:`kept` says, at the start of the first attempt after the cut, how many it cut.
CUT_NOTE = "[... {cut} more attempt(s) not kept ...]"
_CUT_NOTE = re.compile(r"^\[\.\.\. ([0-9]{1,9}) more attempt\(s\) not kept \.\.\.\]")
#: How a case of an earlier attempt that the last attempt no longer has is kept (skipped).
ABSENT = "Not in the last attempt ({total} of {total}): last seen in attempt {seen}, {outcome}."
#: How a test's case that failed and that no later attempt ran is kept: still failed.
NOT_RUN_AGAIN = (
    "Failed, then not run: {outcome} in attempt {seen}, not in any later attempt "
    "(the last is {total}), so it never passed."
)
#: The ``type`` of such a case, by which ``report`` names it.
NOT_RUN_AGAIN_TYPE = "FailedThenNotRun"
#: The runner's own cases about how an attempt ended (``normalise``: the exit, a damaged
#: file, counts it claimed; ``session``: a lost output file), besides the one named after
#: the test (a timeout, no result file). A later attempt that ended well answers them.
ATTEMPT_CASES = frozenset(
    ("test process exit", "result file", "unreported test cases", "output file")
)


def merge_attempts(attempts: Sequence[Suite]) -> Suite:
    """One suite for a test's ``attempts`` (each one's canonical suite, oldest first).

    The cases are the last attempt's, each carrying the earlier attempts' failures; a
    case the last attempt lacks is kept after them. A test's case whose last outcome was
    a failure or an error never passed: it stays one, saying so (:data:`NOT_RUN_AGAIN`),
    its failures as ``rerun*``, and fails the merged file (Surefire calls a test flaky
    only once a rerun of it passed). Any other is kept as skipped (:data:`ABSENT`), its
    failures as flaky ones: one that passed and then did not run, or the runner's own
    case about how an attempt ended (timed out, exited 1), which the later attempts' own
    ending answers. Counts are the cases', so a flaky pass counts as passed. Properties
    are the last attempt's, plus ``attempts``, ``flaky_cases`` and ``attempt_<k>.<name>``
    for each property an earlier attempt ``k`` had with another value (its domain ID,
    exit code, duration). Cases of different attempts whose GitLab keys collide are
    renamed as ``normalise`` renames one file's, said in ``renamed_cases``.
    """
    if not attempts:
        raise ValueError("merge_attempts needs the suite of at least one attempt")
    last = attempts[-1]
    total = len(attempts)
    earlier: dict[tuple[str, str], list[tuple[int, Case, Suite]]] = {}
    for number, suite in enumerate(attempts[:-1], start=1):
        for case in suite.cases:
            earlier.setdefault((case.classname, case.name), []).append((number, case, suite))
    cases = [_merged(case, earlier.pop((case.classname, case.name), [])) for case in last.cases]
    for seen in earlier.values():
        number, case, suite = seen[-1]
        values = {"total": total, "seen": number, "outcome": case.outcome.value}
        named = (case.classname, case.name)
        if case.outcome.failed and not _about_the_attempt(case, suite):
            message = NOT_RUN_AGAIN.format(**values)
            absent = Case.saying(*named, case.outcome, message, NOT_RUN_AGAIN_TYPE)
        else:
            absent = Case.saying(*named, Outcome.SKIPPED, ABSENT.format(**values))
        cases.append(_merged(absent, seen))
    properties = dict(last.properties)
    if len({f"{case.classname}_{case.name}" for case in cases}) < len(cases):
        # Cases of different attempts may share a GitLab key (rare).
        properties[RENAMED_PROPERTY] = distinct_gitlab_keys(cases)
    for number in _kept_numbers(total - 1):
        for key, value in attempts[number - 1].properties.items():
            if last.properties.get(key) != value:
                properties[f"attempt_{number}.{key}"] = value
    properties[ATTEMPTS_PROPERTY] = str(total)
    properties[FLAKY_PROPERTY] = str(sum(1 for case in cases if _passed_after_failing(case)))
    return Suite(
        name=last.name,
        cases=cases,
        time=sum(suite.time for suite in attempts),
        timestamp=attempts[0].timestamp,
        hostname=last.hostname,
        properties=properties,
        system_out=last.system_out,
        system_err=last.system_err,
    )


def _passed_after_failing(case: Case) -> bool:
    """Flaky as every count means it: passed in the end, with failed attempts before."""
    return case.flaky and case.outcome is Outcome.PASSED


def kept(attempts: list[Attempt], limit: int = ATTEMPTS_KEPT) -> list[Attempt]:
    """At most ``limit`` attempts: the oldest and newest halves, the cut said in the text.

    The first attempt after the cut starts its text with how many were dropped, so a
    reader sees the case ran more often than the elements show.
    """
    if len(attempts) <= limit:
        return attempts
    head = limit // 2
    tail = limit - head
    cut = len(attempts) - limit
    first = attempts[-tail]
    note = CUT_NOTE.format(cut=cut)
    marked = Attempt(
        first.kind,
        first.message,
        first.type,
        f"{note}\n{first.text or first.message}",
        first.system_out,
        first.system_err,
    )
    return [*attempts[:head], marked, *attempts[len(attempts) - tail + 1 :]]


def attempt_count(attempts: list[Attempt]) -> int:
    """How many attempts ``attempts`` stand for: each, plus those a cut note says were cut.

    Read back from a file, only the kept ones are there; the note keeps the count true.
    """
    cut = 0
    for attempt in attempts:
        match = _CUT_NOTE.match(attempt.text)
        if match:
            cut += int(match.group(1))
    return len(attempts) + cut


def _kept_numbers(count: int) -> list[int]:
    """Numbers (1-based) of the earlier attempts whose properties are kept, as :func:`kept`."""
    numbers = list(range(1, count + 1))
    if count <= ATTEMPTS_KEPT:
        return numbers
    head = ATTEMPTS_KEPT // 2
    return numbers[:head] + numbers[count - (ATTEMPTS_KEPT - head) :]


def _about_the_attempt(case: Case, suite: Suite) -> bool:
    """Whether ``case`` is the runner's own word on how the attempt of ``suite`` ended.

    The runner puts those in the suite's own class (``<package>.<test name>``), named
    after the test or as :data:`ATTEMPT_CASES` says; the test's own cases have theirs.
    """
    if case.classname != suite.name:
        return False
    return case.name in ATTEMPT_CASES or suite.name.endswith(f".{case.name}")


def _merged(case: Case, seen: list[tuple[int, Case, Suite]]) -> Case:
    """``case`` (not changed) with the failures of its earlier appearances, oldest first."""
    history: list[Attempt] = []
    for _, before, suite in seen:
        history.extend(before.attempts)
        if before.outcome.failed:
            history.append(_attempt_of(before, suite))
    history.extend(case.attempts)
    merged = Case(
        case.classname,
        case.name,
        time=case.time,
        outcome=case.outcome,
        message=case.message,
        text=case.text,
        type=case.type,
        system_out=case.system_out,
        system_err=case.system_err,
    )
    merged.attempts = for_outcome(history, case.outcome)
    return merged


def _attempt_of(case: Case, suite: Suite) -> Attempt:
    """A failed case as an attempt, keeping its output.

    A lone case (the runner's own: a timeout, a crash) takes the suite's output, where
    the runner put the test's console.
    """
    alone = len(suite.cases) == 1
    suffix = "Error" if case.outcome is Outcome.ERROR else "Failure"
    return Attempt(
        f"rerun{suffix}",
        case.message,
        case.type,
        case.text,
        case.system_out or (suite.system_out if alone else ""),
        case.system_err or (suite.system_err if alone else ""),
    )


def for_outcome(attempts: list[Attempt], outcome: Outcome) -> list[Attempt]:
    """``attempts`` named as the final ``outcome`` has them.

    ``rerun*`` when it failed, else ``flaky*``: the only pairs the schema allows. An
    error stays an error and a failure a failure.
    """
    prefix = "rerun" if outcome.failed else "flaky"
    named: list[Attempt] = []
    for attempt in attempts:
        suffix = "Error" if attempt.kind.endswith("Error") else "Failure"
        kind = f"{prefix}{suffix}"
        named.append(
            attempt
            if kind == attempt.kind
            else Attempt(
                kind,
                attempt.message,
                attempt.type,
                attempt.text,
                attempt.system_out,
                attempt.system_err,
            )
        )
    return named

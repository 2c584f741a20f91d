"""What each producer's elements mean: parser events turned into the raw model, bounded.

The parser's target. It knows the shapes producers write (``testsuites``, ``testsuite``
and ``testcase`` with their failure, error and skipped elements; the ``status`` and
``result`` attributes of gtest's and ctest's disabled tests; a suite's ``<property>``
elements, and of a case's only its identity and time (``shard.identity``); Surefire's
rerun and flaky elements, with an attempt's own output) and keeps only what the
normaliser reads. Apart from the stages before it (``sanitiser``,
``safe_parser``) because it sees elements, never bytes: its bounds are on what is kept
(cases, outcomes, texts, names, depth, what entities add).
"""

from __future__ import annotations

from typing import cast

from ros_isolated_test.shard.identity import PROPERTY as IDENTITY_PROPERTY
from ros_isolated_test.shard.identity import SECONDS_PROPERTY
from ros_isolated_test.text import BoundedText, bounded
from ros_isolated_test.xunit.raw import RawCase, RawOutcome, RawSuite, ReadResult
from ros_isolated_test.xunit.xml_text import TEXT_LIMIT

#: Every test case is kept up to this many: no real suite has that many in one test.
MAX_CASES = 100_000
#: Beyond MAX_CASES, every failed, errored or skipped case is still kept, by name with a
#: short text, up to this many more (only a hostile file has more); passed cases beyond
#: MAX_CASES, and any beyond this, are counted in one summary case.
MAX_FURTHER_CASES = 10_000
#: Texts shrink as they add up, so the canonical file stays bounded however many cases
#: there are: TEXT_LIMIT characters each until all texts together reach TEXT_BUDGET,
#: SMALL_TEXT_LIMIT until twice that, TINY_TEXT_LIMIT after (and beyond MAX_CASES).
TEXT_BUDGET = 2 * 1024 * 1024
SMALL_TEXT_LIMIT = 200
TINY_TEXT_LIMIT = 40
#: Names likewise: NAME_LIMIT characters each until names reach NAME_BUDGET, then
#: SHORT_NAME_LIMIT (head and tail, so names still tell cases apart).
NAME_LIMIT = 256
NAME_BUDGET = 2 * 1024 * 1024
SHORT_NAME_LIMIT = 64
#: Failure, error and skipped elements kept per case (one of each kind always is), and
#: test suites whose own counts are kept: more only in a hostile file.
MAX_OUTCOMES = 16
MAX_SUITES = 10_000
#: Properties kept per suite: ours writes a few dozen.
MAX_PROPERTIES = 256
_PROPERTY_KEYS = frozenset({"name", "value"})
#: Elements nested deeper than this stop reading. Real producers nest four or five levels
#: (testsuites, testsuite, testcase, failure); the parser keeps a few words per open
#: element, so an unbounded depth costs memory in proportion to the file.
MAX_DEPTH = 1000
#: The attributes the normaliser reads; the others are not kept.
_CASE_KEYS = frozenset({"name", "classname", "time", "status", "result"})
_OUTCOME_KEYS = frozenset({"message", "type"})

_ATTEMPT_TAGS = frozenset({"rerunFailure", "rerunError", "flakyFailure", "flakyError"})
_IN_PROPERTIES = ["testsuite", "properties"]
_IN_CASE_PROPERTIES = ["testcase", "properties"]
OUTCOME_TAGS = frozenset({"failure", "error", "skipped"}) | _ATTEMPT_TAGS
#: What entities may add to the text and markup the parser reports: ENTITY_BUDGET
#: characters, and beyond that EXPANSION_FACTOR times what the parser was given. That
#: is libxml2's own bound since 2.11; older ones (Ubuntu 24.04's 2.9.14) stream an entity
#: bomb through a target parser in bounded memory, but for as long as it expands.
ENTITY_BUDGET = 1024 * 1024
EXPANSION_FACTOR = 5

#: Text pieces are gathered up to this many characters (or pieces) before they are cut.
_GATHER_CHARS = 64 * 1024
_GATHER_PIECES = 4096


class _Gathered:
    """A :class:`BoundedText` fed in batches.

    The parser reports the text around every entity or character reference as a piece
    of its own, and each ``BoundedText.add`` copies the kept tail: 30 million ``&amp;``
    took a minute one by one, seconds in batches.
    """

    def __init__(self, limit: int) -> None:
        self.text = BoundedText(limit)
        self.pieces: list[str] = []
        self.size = 0

    def add(self, piece: str) -> None:
        self.pieces.append(piece)
        self.size += len(piece)
        if self.size >= _GATHER_CHARS or len(self.pieces) >= _GATHER_PIECES:
            self._flush()

    def _flush(self) -> None:
        if self.pieces:
            self.text.add("".join(self.pieces))
            self.pieces, self.size = [], 0

    def value(self) -> str:
        self._flush()
        return self.text.value()


class _Budget:
    """How many characters a text or name may keep, shrinking as they add up."""

    def __init__(self) -> None:
        self.used = 0
        self.names = 0

    def limit(self, small: bool = False) -> int:
        if small or self.used >= 2 * TEXT_BUDGET:
            return TINY_TEXT_LIMIT
        return TEXT_LIMIT if self.used < TEXT_BUDGET else SMALL_TEXT_LIMIT

    def text(self, small: bool = False) -> _Gathered:
        return _Gathered(self.limit(small))

    def take(self, text: _Gathered) -> str:
        value = text.value()
        self.used += len(value)
        return value

    def attrs(
        self, attrib: object, keys: frozenset[str] | None = None, small: bool = False
    ) -> dict[str, str]:
        limit = self.limit(small)
        name_limit = NAME_LIMIT if self.names < NAME_BUDGET else SHORT_NAME_LIMIT
        result: dict[str, str] = {}
        for key, value in dict(attrib).items():  # type: ignore[call-overload]
            name = _local(str(key))
            if keys is not None and name not in keys:
                continue
            if name in ("name", "classname"):
                kept = bounded(str(value), name_limit)
                self.names += len(kept)
            else:
                kept = bounded(str(value), limit)
                self.used += len(kept)
            result[name] = kept
        return result


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


class Stop(Exception):
    """Raised from a parser event, with the problem: lxml stops the parser and re-raises it."""


class Builder:
    """Parser target: turns element events into the raw model, with bounded memory."""

    def __init__(self, result: ReadResult) -> None:
        self.result = result
        self.budget = _Budget()
        self.stack: list[str] = []
        self.suites: list[RawSuite] = []
        self.case: RawCase | None = None
        self.further = False  # the open case is beyond MAX_CASES
        self.kept_further = 0
        self.counting: str | None = None  # outcome of a case only counted
        self.in_counted_case = False
        self.text: _Gathered | None = None
        self.outcome_attrs: dict[str, str] = {}
        #: The output of an attempt inside a rerun or flaky element, apart from its text.
        self.attempt_output: _Gathered | None = None
        self.outcome_output: dict[str, str] = {}
        self.root_closed = False
        self.dropped_outcomes = 0
        self.dropped_suites = 0
        #: Characters given to the parser, and reported by it as names, attribute values
        #: and text: without entities never more than given. Counted only once a DOCTYPE
        #: reached the parser: without one, no entity can expand.
        self.fed = 0
        self.reported = 0
        self.count_expansion = False

    def _report(self, size: int) -> None:
        """Count what the parser reported; stop once entities added too much to it."""
        self.reported += size
        added = self.reported - self.fed
        if added > ENTITY_BUDGET and added > EXPANSION_FACTOR * self.fed:
            raise Stop(
                f"entity references expand to over {EXPANSION_FACTOR} times what the file "
                "holds (an entity bomb?): reading stopped there"
            )

    def start(self, tag: str, attrib: object) -> None:
        if len(self.stack) >= MAX_DEPTH:
            raise Stop(
                f"elements nest deeper than {MAX_DEPTH} levels: not a result file; "
                "reading stopped there"
            )
        name = _local(tag)
        if self.count_expansion:
            values = cast("dict[str, str]", attrib).values()
            self._report(len(name) + 2 + sum(map(len, values)))
        self.stack.append(name)
        if len(self.stack) == 1:
            self.result.root_attrs = self.budget.attrs(attrib)
            self.result.root_tag = name
        parent = self.stack[-2] if len(self.stack) > 1 else None
        if name == "testsuite":
            attrs = self.budget.attrs(attrib, small=len(self.result.suites) >= MAX_SUITES)
            suite = RawSuite(attrs.get("name", ""), attrs)
            self.suites.append(suite)
            if len(self.result.suites) < MAX_SUITES:
                self.result.suites.append(suite)
            else:
                self.dropped_suites += 1
        elif name == "property" and self.case is None and self.stack[-3:-1] == _IN_PROPERTIES:
            self._property(attrib)
        elif name == "property" and self.case is not None:
            if self.stack[-3:-1] == _IN_CASE_PROPERTIES:
                self._case_property(self.case, attrib)
        elif name == "testcase" and self.case is None and not self.in_counted_case:
            self._start_case(attrib)
        elif self.in_counted_case and parent == "testcase" and name in OUTCOME_TAGS:
            self.counting = _worse(self.counting or "passed", name)
        elif self.case is not None and parent == "testcase":
            if name in OUTCOME_TAGS:
                self._start_outcome(name, attrib)
            elif name in ("system-out", "system-err"):
                self.text = self.budget.text(self.further)
        elif self.case is not None and parent in _ATTEMPT_TAGS and self.text is not None:
            if name in ("system-out", "system-err"):
                self.attempt_output = self.budget.text(self.further)
        elif self.case is None and parent == "testsuite" and name in ("system-out", "system-err"):
            self.text = self.budget.text()

    def _property(self, attrib: object) -> None:
        properties = self.suites[-1].properties if self.suites else None
        if properties is None or len(properties) >= MAX_PROPERTIES:
            return
        attrs = self.budget.attrs(attrib, _PROPERTY_KEYS)
        if "name" in attrs:
            properties.setdefault(attrs["name"], attrs.get("value", ""))

    def _case_property(self, case: RawCase, attrib: object) -> None:
        """A case's property: only its identity and time are kept (the first of each)."""
        attrs = self.budget.attrs(attrib, _PROPERTY_KEYS, self.further)
        name = attrs.get("name")
        if name == IDENTITY_PROPERTY and not case.identity:
            case.identity = attrs.get("value", "")
        elif name == SECONDS_PROPERTY and not case.seconds:
            case.seconds = attrs.get("value", "")

    def _start_case(self, attrib: object) -> None:
        suite_name = self.suites[-1].name if self.suites else ""
        self.further = len(self.result.cases) >= MAX_CASES
        if self.further and self.kept_further >= MAX_FURTHER_CASES:
            self.in_counted_case = True
            self.counting = "passed"
            return
        self.case = RawCase(self.budget.attrs(attrib, _CASE_KEYS, self.further), suite_name)

    def _start_outcome(self, name: str, attrib: object) -> None:
        assert self.case is not None
        outcomes = self.case.outcomes
        if len(outcomes) >= MAX_OUTCOMES and any(item.tag == name for item in outcomes):
            self.dropped_outcomes += 1
            return
        self.outcome_attrs = self.budget.attrs(attrib, _OUTCOME_KEYS, self.further)
        self.outcome_output = {}
        self.text = self.budget.text(self.further)

    def data(self, data: str | bytes) -> None:
        if self.count_expansion:
            self._report(len(data))
        target = self.attempt_output or self.text
        if target is not None:
            target.add(data if isinstance(data, str) else data.decode("utf-8", "replace"))

    def end(self, tag: str) -> None:
        name = _local(tag)
        if self.stack:
            self.stack.pop()
        parent = self.stack[-1] if self.stack else None
        if self.attempt_output is not None and name in ("system-out", "system-err"):
            self.outcome_output[name] = self.budget.take(self.attempt_output)
            self.attempt_output = None
            return
        if name == "testcase" and self.in_counted_case and parent != "testcase":
            self.result.dropped[self.counting or "passed"] += 1
            self.in_counted_case = False
            self.counting = None
        elif name == "testcase" and self.case is not None and parent != "testcase":
            self._end_case(self.case)
            self.case = None
        elif self.text is not None and parent == "testcase" and self.case is not None:
            value = self.budget.take(self.text)
            if name in OUTCOME_TAGS:
                output = self.outcome_output
                self.case.outcomes.append(
                    RawOutcome(
                        name,
                        self.outcome_attrs,
                        value,
                        output.get("system-out", ""),
                        output.get("system-err", ""),
                    )
                )
            elif name == "system-out":
                self.case.system_out = value
            elif name == "system-err":
                self.case.system_err = value
        elif self.text is not None and parent == "testsuite" and self.suites:
            value = self.budget.take(self.text)
            if name == "system-out":
                self.suites[-1].system_out = value
            else:
                self.suites[-1].system_err = value
        if name in OUTCOME_TAGS or name in ("system-out", "system-err"):
            self.text = None
        if name == "testsuite" and self.suites:
            self.suites.pop()
        if not self.stack:
            self.root_closed = True

    def _end_case(self, case: RawCase) -> None:
        """Keep the case; beyond MAX_CASES only if it did not pass (passed ones are counted)."""
        if self.further and not _noteworthy(case):
            self.result.dropped["passed"] += 1
            return
        self.kept_further += self.further
        self.result.cases.append(case)

    def comment(self, text: str | bytes) -> None:
        return None

    def close(self) -> None:
        return None

    def finish(self) -> None:
        """Say what a hostile file lost; keep a case the file ended inside, marked."""
        if self.case is not None:
            if self.text is not None and self.stack and self.stack[-1] in OUTCOME_TAGS:
                value = self.budget.take(self.text)
                self.case.outcomes.append(RawOutcome(self.stack[-1], self.outcome_attrs, value))
            self.case.complete = False
            self.result.cases.append(self.case)
            self.case = None
        if self.dropped_outcomes:
            self.result.repairs.append(
                f"{self.dropped_outcomes} failure, error or skipped element(s) beyond "
                f"{MAX_OUTCOMES} in one test case were not kept"
            )
        if self.dropped_suites:
            self.result.repairs.append(
                f"the own counts of {self.dropped_suites} test suite(s) beyond the first "
                f"{MAX_SUITES} were not checked"
            )


def _noteworthy(case: RawCase) -> bool:
    """Whether a case failed, errored, was skipped or was cut off: kept by name always."""
    disabled = case.attrs.get("status") == "disabled" or case.attrs.get("result") == "suppressed"
    primary = any(item.tag in ("failure", "error", "skipped") for item in case.outcomes)
    return disabled or primary or not case.complete


_RANK = {"passed": 0, "skipped": 1, "error": 2, "failure": 3}


def _worse(current: str, tag: str) -> str:
    kind = "failure" if "Failure" in tag or tag == "failure" else tag
    kind = "error" if "Error" in tag else kind
    return kind if _RANK.get(kind, 0) > _RANK.get(current, 0) else current

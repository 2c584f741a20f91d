"""The canonical result, as data: what ``schemas/junit.xsd`` describes, before it is XML.

Plain classes, not dataclasses: this module is on every test's path, and importing
``dataclasses`` (which pulls in ``inspect``) would cost more than the runner's own work.
"""

from __future__ import annotations

from enum import Enum


class Outcome(Enum):
    """A test case's one outcome; ``rank`` orders them from passed to failed."""

    PASSED = "passed"
    SKIPPED = "skipped"
    ERROR = "error"
    FAILURE = "failure"

    @property
    def rank(self) -> int:
        """Higher is worse: merged duplicates take the worst outcome."""
        return list(Outcome).index(self)

    @property
    def failed(self) -> bool:
        """Whether this outcome fails the run."""
        return self in (Outcome.ERROR, Outcome.FAILURE)


class Attempt:
    """One earlier failed run of a case, kept so a rerun cannot hide a flake.

    ``kind`` is the element it becomes inside ``<testcase>``: ``flakyFailure`` /
    ``flakyError`` when the case finally passed, ``rerunFailure`` / ``rerunError`` when
    it failed every time (Surefire's shape, which Jenkins shows). junit-10 requires
    ``type``; the serialiser writes a placeholder when it is empty.
    """

    __slots__ = ("kind", "message", "system_err", "system_out", "text", "type")

    def __init__(
        self,
        kind: str,
        message: str = "",
        type: str = "",
        text: str = "",
        system_out: str = "",
        system_err: str = "",
    ) -> None:
        if kind not in ATTEMPT_KINDS:
            raise ValueError(f"attempt kind {kind!r} is not one of {ATTEMPT_KINDS}")
        self.kind = kind
        self.message = message
        self.type = type
        self.text = text
        self.system_out = system_out
        self.system_err = system_err

    def __repr__(self) -> str:
        return f"Attempt({self.kind!r}, {self.message!r})"


ATTEMPT_KINDS = ("flakyFailure", "flakyError", "rerunFailure", "rerunError")


class Case:
    """One test case; ``classname`` already carries the ``<package>.`` prefix."""

    __slots__ = (
        "attempts",
        "classname",
        "message",
        "name",
        "outcome",
        "system_err",
        "system_out",
        "text",
        "time",
        "type",
    )

    def __init__(
        self,
        classname: str,
        name: str,
        time: float = 0.0,
        outcome: Outcome = Outcome.PASSED,
        message: str = "",
        text: str = "",
        type: str = "",
        system_out: str = "",
        system_err: str = "",
        attempts: list[Attempt] | None = None,
    ) -> None:
        self.classname = classname
        self.name = name
        self.time = time
        self.outcome = outcome
        self.message = message
        self.text = text
        self.type = type
        self.system_out = system_out
        self.system_err = system_err
        self.attempts: list[Attempt] = attempts if attempts is not None else []

    @property
    def flaky(self) -> bool:
        """Passed in the end after failing at least once: not a failure, but shown."""
        return not self.outcome.failed and any(a.kind.startswith("flaky") for a in self.attempts)

    @classmethod
    def saying(
        cls, classname: str, name: str, outcome: Outcome, message: str, type: str = ""
    ) -> Case:
        """A case of the runner's own, whose message is also its text (readers differ)."""
        return cls(classname, name, outcome=outcome, message=message, text=message, type=type)

    def __repr__(self) -> str:
        return f"Case({self.classname!r}, {self.name!r}, outcome={self.outcome.name})"


class Suite:
    """One test (one result file): its cases, and how the runner ran it."""

    __slots__ = (
        "cases",
        "hostname",
        "name",
        "properties",
        "system_err",
        "system_out",
        "time",
        "timestamp",
    )

    def __init__(
        self,
        name: str,
        cases: list[Case],
        time: float,
        timestamp: str,
        hostname: str,
        properties: dict[str, str] | None = None,
        system_out: str = "",
        system_err: str = "",
    ) -> None:
        self.name = name
        self.cases = cases
        self.time = time
        self.timestamp = timestamp
        self.hostname = hostname
        self.properties: dict[str, str] = properties if properties is not None else {}
        self.system_out = system_out
        self.system_err = system_err

    def count(self, outcome: Outcome) -> int:
        """Cases with ``outcome``: counts are always recomputed, never copied."""
        return sum(1 for case in self.cases if case.outcome is outcome)

    @property
    def failed(self) -> bool:
        """Whether any case failed or errored."""
        return any(case.outcome.failed for case in self.cases)

"""The canonical result, as data: what ``schemas/junit.xsd`` describes, before it is XML."""

from __future__ import annotations

from dataclasses import dataclass, field
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


@dataclass
class Case:
    """One test case; ``classname`` already carries the ``<package>.`` prefix."""

    classname: str
    name: str
    time: float = 0.0
    outcome: Outcome = Outcome.PASSED
    message: str = ""
    text: str = ""
    type: str = ""
    system_out: str = ""
    system_err: str = ""

    @classmethod
    def saying(
        cls, classname: str, name: str, outcome: Outcome, message: str, type: str = ""
    ) -> Case:
        """A case of the runner's own, whose message is also its text (readers differ)."""
        return cls(classname, name, outcome=outcome, message=message, text=message, type=type)


@dataclass
class Suite:
    """One test (one result file): its cases, and how the runner ran it."""

    name: str
    cases: list[Case]
    time: float
    timestamp: str
    hostname: str
    properties: dict[str, str] = field(default_factory=dict)
    system_out: str = ""
    system_err: str = ""

    def count(self, outcome: Outcome) -> int:
        """Cases with ``outcome``: counts are always recomputed, never copied."""
        return sum(1 for case in self.cases if case.outcome is outcome)

    @property
    def failed(self) -> bool:
        """Whether any case failed or errored."""
        return any(case.outcome.failed for case in self.cases)

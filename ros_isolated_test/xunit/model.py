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


class Case:
    """One test case; ``classname`` already carries the ``<package>.`` prefix."""

    __slots__ = (
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

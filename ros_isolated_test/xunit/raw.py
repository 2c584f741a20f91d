"""The raw model: what one result file says, as its producer wrote it, before normalising.

Apart from the reading so that each stage (the sanitiser, the builder) and every reader of
a result (``normalise``, ``report.tree``, ``report.html_report``) names these records
without importing the reading itself.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path


@dataclass(slots=True)
class RawOutcome:
    """A failure, error or skipped element as the producer wrote it.

    Surefire's rerun and flaky elements hold an attempt's own output as children.
    """

    tag: str
    attrs: dict[str, str]
    text: str
    system_out: str = ""
    system_err: str = ""


@dataclass(slots=True)
class RawCase:
    """A testcase element as the producer wrote it, texts already bounded."""

    attrs: dict[str, str]
    suite: str
    outcomes: list[RawOutcome] = field(default_factory=list)
    system_out: str = ""
    system_err: str = ""
    #: False when the file ended (or reading stopped) inside this case.
    complete: bool = True
    #: The test's identity across machines (``<package>/<node id>``), from the case's
    #: ``ros_isolated_test_identity`` property that the pytest plugin adds: kept here
    #: only, for ``report --durations`` and a split's merge (the canonical schema has no
    #: testcase properties). "" when the case has none.
    identity: str = ""
    #: Its ``ros_isolated_test_seconds`` property (the plugin's time of the item, to the
    #: microsecond), as written; "" when the case has none.
    seconds: str = ""


@dataclass(slots=True)
class RawSuite:
    """A testsuite element: only what the normaliser uses."""

    name: str
    attrs: dict[str, str]
    system_out: str = ""
    system_err: str = ""
    #: Its ``<property>`` elements (the runner's record of how it ran the test: the
    #: report's timeline), the first MAX_PROPERTIES, values bounded like attributes.
    properties: dict[str, str] = field(default_factory=dict)


@dataclass
class ReadResult:
    """Everything that could be read from one result file, and what was wrong with it."""

    path: Path
    root_tag: str | None = None
    root_attrs: dict[str, str] = field(default_factory=dict)
    suites: list[RawSuite] = field(default_factory=list)
    cases: list[RawCase] = field(default_factory=list)
    #: Outcomes (``passed``, ``failure``, ...) of cases only counted (see MAX_CASES).
    dropped: Counter[str] = field(default_factory=Counter)
    #: What was wrong and damaged the content: reported as an error case.
    problems: list[str] = field(default_factory=list)
    #: What was wrong but repaired without loss of meaning: reported as a property.
    repairs: list[str] = field(default_factory=list)
    size: int = 0

    @property
    def is_xunit(self) -> bool:
        """Whether the root is one that xUnit readers accept."""
        return self.root_tag in ("testsuite", "testsuites")

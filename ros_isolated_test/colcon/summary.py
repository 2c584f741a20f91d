"""What ``colcon test`` ends with: one line, and the page of the packages just tested.

The same reading and page as ``ros-isolated-test report --html`` (``report``), over the
result folders of the packages the run tested, written into colcon's log folder of that
run (``log/latest_test/`` leads to it). The line counts tests run, failed (failures and
errors), flaky, and the distinct domain IDs the results say they ran on. With
``ROS_ISOLATED_TEST_SHARD`` set, the page and the line are this machine's share, as
``report`` takes them there.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path

from ros_isolated_test import names
from ros_isolated_test.report import html_report
from ros_isolated_test.report.shard import Split
from ros_isolated_test.report.tree import FileRead
from ros_isolated_test.shard.spec import ShardSettingError

#: The page's name in the run's log folder.
PAGE = "ros_isolated_test.html"
PREFIX = "ros-isolated-test:"


class DomainIds:
    """The distinct domain IDs the result files say their tests held (ours, isolated).

    Only result files with cases count: a pytest session with ``ROS_ISOLATED_TEST_SHARD`` set
    whose items are all another machine's still holds an ID, and says so, for none.
    """

    def __init__(self) -> None:
        self.ids: set[int] = set()

    def add(self, item: FileRead) -> None:
        # A session that ran none of its tests (another machine's share) held an ID for none.
        if item.read is None or not (item.read.cases or item.read.dropped):
            return
        for suite in item.read.suites:
            if suite.properties.get(names.ISOLATION_PROPERTY) == "disabled":
                continue
            for name, value in suite.properties.items():
                if name.split(".", 1)[0].endswith("ros_domain_id") and value.isdigit():
                    self.ids.add(int(value))


def result_paths(bases: Iterable[Path]) -> list[Path]:
    """The folders holding the tested packages' result files, each once, in order."""
    return sorted({base for base in bases if base.exists()})


def summarise(paths: list[Path], log_path: Path | None, environ: Mapping[str, str]) -> str:
    """Write the page (when colcon logs) and return the one line that names it."""
    from ros_isolated_test.runner import settings

    try:
        share = settings.machine_share(environ)
    except ShardSettingError as error:
        return f"{PREFIX} no summary: {error}"
    split = Split(share)
    domains = DomainIds()
    page = (log_path / PAGE) if log_path is not None else Path("/dev/null")
    try:
        total = html_report.write(paths, page, domains.add, split)
    except OSError as error:
        return f"{PREFIX} cannot write the page {page}: {error.strerror or error}"
    failed = total.failures + total.errors
    line = (
        f"{PREFIX} {total.tests} tests run, {failed} failed, {total.flaky} flaky, "
        f"on {len(domains.ids)} domain IDs"
    )
    if share is not None:
        line += f" (this machine's share {share})"
    if split.problems:
        line += f"; {split.problems[0]}"
    if log_path is None:
        return f"{line}; no page: colcon's log is off (--log-base /dev/null)"
    return f"{line}; page: {page}"

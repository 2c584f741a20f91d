"""What ``colcon test`` ends with: one line, and the page of the packages just tested.

The same reading and page as ``ros-isolated-test report --html`` (``report``), over the
result folders of the packages the run tested, written into colcon's log folder of that
run (``log/latest_test/`` leads to it). The line counts tests run, failed (failures and
errors), flaky, and the distinct domain IDs the results say they ran on. With
``ROS_ISOLATED_TEST_SHARD`` set, the page and the line are this machine's share, as
``report`` takes them there. Each run is recorded into the workspace's test history
(``history``), and the page says of each failure whether it is new, known flaky or
broken since a run, with each test's outcome strip.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path

from ros_isolated_test import names
from ros_isolated_test.report import html_report
from ros_isolated_test.report.html_parts import Past
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


def summarise(
    paths: list[Path],
    log_path: Path | None,
    environ: Mapping[str, str],
    workspace: Path | None = None,
) -> str:
    """Write the page (when colcon logs) and return the one line that names it.

    With ``workspace`` (colcon's folder), the run is recorded into its test history
    first and the page says what the runs before say of each failure (:func:`history`);
    a warning about the database is a line of its own before the summary line.
    """
    from ros_isolated_test.runner import settings

    try:
        share = settings.machine_share(environ)
    except ShardSettingError as error:
        return f"{PREFIX} no summary: {error}"
    split = Split(share)
    domains = DomainIds()
    page = (log_path / PAGE) if log_path is not None else Path("/dev/null")
    past, warning = history(paths, environ, workspace)
    said = f"{warning}\n" if warning else ""
    try:
        total = html_report.write(paths, page, domains.add, split, past)
    except OSError as error:
        return f"{said}{PREFIX} cannot write the page {page}: {error.strerror or error}"
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
        return f"{said}{line}; no page: colcon's log is off (--log-base /dev/null)"
    return f"{said}{line}; page: {page}"


def history(
    paths: list[Path], environ: Mapping[str, str], workspace: Path | None
) -> tuple[tuple[str, dict[str, Past]] | None, str | None]:
    """Record the run into the workspace's history, and what it says for the page.

    The database is ``<workspace>/ros_isolated_test_history.sqlite3`` (where ``history``
    run in the workspace looks first), or the one ``ROS_ISOLATED_TEST_HISTORY`` names:
    the whole run as one, the only recorder of it (``run`` and the pytest plugin under
    colcon record nothing of their own: see ``argument_parser.one_history_recorder``).
    Never raises: a database that cannot be used is the one warning line returned, the
    page then without history.
    """
    if workspace is None:
        return None, None
    from ros_isolated_test.history.record import gathered, record_trees
    from ros_isolated_test.history.stats import before_run
    from ros_isolated_test.history.store import DEFAULT_FILE
    from ros_isolated_test.runner.settings import history_database
    from ros_isolated_test.text import display_text

    named = history_database(environ)
    db = named or workspace / DEFAULT_FILE
    try:
        run = gathered(paths)
    except Exception as error:  # the page reads the trees again and says what is wrong
        return None, f"{PREFIX} warning: not recorded in the test history: {error}"
    warning = record_trees(db, run)
    if warning is not None:
        return None, warning
    try:
        return (display_text(str(db)), before_run(db, run)), None
    except Exception as error:
        return None, f"{PREFIX} warning: the page has no history ({display_text(str(db))}): {error}"

"""``ros-isolated-test report``: what result trees say, as text, JSON, a page or durations.

The command only parses its arguments and hands over: reading, counting, the page, a
split's merge and the durations live in ``ros_isolated_test.report``. Added to the
command group by ``cli/__init__.py`` (``cli.add_command``), like ``shard``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import click

from ros_isolated_test.cli import usage

TYPE_CHECKING = False
if TYPE_CHECKING:
    from ros_isolated_test.report.html_parts import Past
    from ros_isolated_test.report.shard import Split
    from ros_isolated_test.report.text_report import TextReport


@click.command()
@click.argument(
    "paths",
    nargs=-1,
    type=click.Path(exists=True, path_type=Path),
)
@click.option("--verbose", "-v", is_flag=True, help="List each failure with its message.")
@click.option("--json", "as_json", is_flag=True, help="Print the same as JSON.")
@click.option(
    "--html",
    "html_file",
    type=click.Path(path_type=Path),
    help="Also write one self-contained page (with a timeline of every attempt) to this file.",
)
@click.option(
    "--durations",
    "durations_file",
    type=click.Path(dir_okay=False, path_type=Path),
    metavar="FILE",
    help="Instead of the report, write the durations file a split balances by "
    "(ROS_ISOLATED_TEST_DURATIONS) from the tests' times in PATHS: one or more earlier "
    "runs' trees, a split's shards included (a test measured in several runs keeps the "
    "median).",
)
@click.option(
    "--history",
    "history_db",
    type=click.Path(dir_okay=False, path_type=Path),
    metavar="DB",
    help="With --html: the test history database; each failure on the page then says "
    "whether it is new, known flaky or broken since a run, and each test shows its "
    "outcome strip (from the runs before this one; a DB not yet there is an empty history).",
)
def report(
    paths: tuple[Path, ...],
    verbose: bool,
    as_json: bool,
    html_file: Path | None,
    durations_file: Path | None,
    history_db: Path | None,
) -> None:
    """Summarise the xUnit result files under PATHS (default: build).

    Prints each file's counts and the total, like `colcon test-result --all`, counted
    from the test cases themselves. Reads canonical files and raw gtest, pytest,
    launch_testing, unittest-xml-reporting and ctest files alike; a broken file, or a
    folder it cannot read, counts as an error. Exits 1 when anything failed or errored.
    With --html FILE it also writes one page for them all, to open in a browser
    offline: totals, failures first, flaky cases, every case by package and suite, and
    a timeline of every attempt on its domain ID (exit 2 when FILE cannot be written).

    PATHS may be the trees of a split's machines (ROS_ISOLATED_TEST_SHARD=I/N): each
    test is counted where it ran, and the report also exits 1 when a share left no
    results ("shard 3 of 4 left no results"), when shares ran under different plans,
    or when a test ran in two of them. On a machine whose ROS_ISOLATED_TEST_SHARD is
    set, only that share is expected.
    """
    from ros_isolated_test.report import shard, text_report, tree
    from ros_isolated_test.runner import settings
    from ros_isolated_test.shard.spec import ShardSettingError

    if not paths:
        default = Path("build")
        if not default.exists():
            raise click.UsageError("no PATHS given and no 'build' folder here; name a folder")
        paths = (default,)
    if history_db is not None and html_file is None:
        raise click.UsageError("--history is shown on the page: give --html FILE too")
    if durations_file is not None:
        if html_file is not None or as_json:
            raise click.UsageError(
                "--durations writes the durations file alone: drop --html, --json"
            )
        _write_durations(paths, durations_file)
        return
    try:
        split = shard.Split(settings.machine_share())
    except ShardSettingError as error:
        usage.fail(str(error), usage.USAGE)
    # A folder it cannot read is an error; a flaky case (passed after failing) is listed
    # apart and never fails the report, one that failed and was then not run always does.
    # Each file is read once (for the page too) and only its counts are kept.
    with text_report.TextReport(verbose, as_json) as printed:
        printed.split = split
        if html_file is None:
            records: list[Path] = []
            for item in tree.read_tree(paths, records):
                printed.add(item)
                split.add(item)
            split.add_records(records)
        else:
            history = None if history_db is None else _history(history_db, paths)
            _html_report(paths, html_file, printed, split, history)
        printed.write(lambda piece: click.echo(piece, nl=False))
    if printed.total.failed or split.problems:
        sys.exit(usage.FAILED)


def _history(db: Path, paths: tuple[Path, ...]) -> tuple[str, dict[str, Past]]:
    """What the history says of the runs before these trees' run; unreadable: exit 2."""
    from ros_isolated_test.history.stats import before_run
    from ros_isolated_test.history.store import StoreError
    from ros_isolated_test.text import display_text

    try:
        return display_text(str(db)), before_run(db, paths)
    except StoreError as error:
        usage.fail(f"--history: {error}", usage.USAGE)


def _html_report(
    paths: tuple[Path, ...],
    destination: Path,
    printed: TextReport,
    split: Split,
    history: tuple[str, dict[str, Past]] | None = None,
) -> None:
    """Write the page (read once, for it and the text); a page that cannot be written: exit 2."""
    from ros_isolated_test import atomic_file
    from ros_isolated_test.report import html_report

    try:
        html_report.write(paths, destination, printed.add, split, history)
    except OSError as error:
        fix = "choose a writable file path"
        if isinstance(error, atomic_file.NotReplaceableError):
            fix = "name a regular file instead, or /dev/null to discard the page"
        usage.fail(
            f"cannot write --html {destination}: {error.strerror or error}; {fix}", usage.USAGE
        )


def _write_durations(paths: tuple[Path, ...], destination: Path) -> None:
    """``--durations FILE``: the tests' times under ``paths``, written; nothing found: exit 2."""
    from ros_isolated_test.report import shard_durations, tree
    from ros_isolated_test.shard.durations import DurationsError, write

    gathered = shard_durations.Gathered()
    for item in tree.read_tree(paths):
        gathered.add(item)
    durations = gathered.durations()
    shown = " ".join(map(str, paths))
    if not durations:
        usage.fail(
            f"no test's duration in {shown} ({gathered.files} result "
            "file(s) read): give the result trees of a run through ros-isolated-test (the "
            "RUNNER's files, or pytest's --junit-xml under the plugin); nothing written",
            usage.USAGE,
        )
    try:
        write(destination, durations)
    except DurationsError as error:
        usage.fail(str(error), usage.USAGE)
    click.echo(
        f"{destination}: {len(durations)} tests' durations from {gathered.measuring} of "
        f"{gathered.files} result file(s) (plan {durations.fingerprint})"
    )

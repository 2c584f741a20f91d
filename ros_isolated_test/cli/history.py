"""``ros-isolated-test history``: the test history database, recorded, read, merged.

The command parses its arguments and hands over to ``ros_isolated_test.history``. Its
default subcommand (``history [TEST]...``) prints each test's status over the last
runs; ``record``, ``prune``, ``merge``, ``export`` and ``durations`` are the others. A
database that cannot be used is one line naming the file (exit 1; for ``record``, a
warning and exit 0: recording never fails a run). Usage errors are the group's one
line (``cli.usage``), exit 2.
Added to the command group by ``cli/__init__.py`` (``cli.add_command``).
"""

from __future__ import annotations

from pathlib import Path

import click

from ros_isolated_test.cli import usage
from ros_isolated_test.history.store import DEFAULT_FILE
from ros_isolated_test.runner.settings import HISTORY_ENV, history_database

#: The database when neither --db nor ROS_ISOLATED_TEST_HISTORY names one.
DEFAULT_DB = Path(DEFAULT_FILE)
#: The subcommand ``history`` runs when the first argument names no other.
SHOW = "show"

TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import NoReturn

_DB_HELP = f"The history database. Default: {HISTORY_ENV}, else ./{DEFAULT_DB}."


class _HistoryGroup(click.Group):
    """``history [OPTIONS] [TEST]...`` runs ``show``; a subcommand's name runs it."""

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        if not args or (args[0] not in self.commands and args[0] != "--help"):
            args = [SHOW, *args]
        return super().parse_args(ctx, args)


def _db(db: Path | None) -> Path:
    return db or history_database() or DEFAULT_DB


def _failed(message: str) -> NoReturn:
    usage.fail(message, usage.FAILED)


_db_option = click.option("--db", type=click.Path(dir_okay=False, path_type=Path), help=_DB_HELP)


@click.group("history", cls=_HistoryGroup)
def history() -> None:
    """The test history: every run's results in one SQLite file, to tell flaky from broken.

    `history [TEST]...` (the `show` subcommand) prints each test's status over the last
    runs; the subcommands record, prune, merge and export the database.
    """


@history.command(SHOW)
@_db_option
@click.option("--json", "as_json", is_flag=True, help="Print a JSON list of objects.")
@click.option(
    "--runs",
    type=click.IntRange(1, 100_000),
    default=20,
    show_default=True,
    help="How many of the last runs to look at.",
)
@click.option("--flaky", "only", flag_value="flaky", help="Only the flaky tests.")
@click.option("--broken", "only", flag_value="broken", help="Only the broken tests.")
@click.argument("names", nargs=-1, metavar="[TEST]...")
def show(
    db: Path | None, as_json: bool, runs: int, only: str | None, names: tuple[str, ...]
) -> None:
    """Each test over the last runs, worst first: new, stable, broken or flaky.

    A test is <package>/<test> (a pytest item: <package>/<node id>). Broken: failed in
    every run of the window (at least 2); flaky: passed and failed, or passed only after
    failing within a run; new: seen in one run only. The strip shows the last outcome of
    each run, oldest first: P passed, f passed after failing, F failed, E error, T timed
    out, S skipped, N not run.
    """
    import json

    from ros_isolated_test.history import stats
    from ros_isolated_test.history.store import StoreError, connect
    from ros_isolated_test.text import display_text

    path = _db(db)
    try:
        connection = connect(path, write=False)
    except StoreError as error:
        _failed(str(error))
    try:
        found = stats.tests(connection, runs, list(names) if names else None)
    finally:
        connection.close()
    if only:
        found = [item for item in found if item.status == only]
    if as_json:
        click.echo(json.dumps([item.as_json() for item in found], indent=1))
        return
    for item in found:
        since = item.broken_since
        said = f" since run {since.number} ({since.started[:19]})" if since else ""
        median = item.as_json()["median_seconds"]
        timing = f"  median {median:.3f} s" if isinstance(median, float) else ""
        click.echo(
            f"{item.status:<7} {item.strip:>{min(runs, 20)}}  {item.passed}/{item.runs} passed"
            f"{said}{timing}  {display_text(item.test)}"
        )
    if not found:
        click.echo("no tests recorded" + (" by those names" if names else ""))


@history.command("record")
@_db_option
@click.argument(
    "trees",
    nargs=-1,
    required=True,
    metavar="TREE...",
    type=click.Path(exists=True, path_type=Path),
)
def record(db: Path | None, trees: tuple[Path, ...]) -> None:
    """Record the result trees of one run (a split's shares together are one run).

    Recording the same results again changes nothing. A database that cannot be
    written (locked, corrupt, foreign, read-only) gives one warning line; the exit
    code stays 0, so a CI step that records never fails the run.
    """
    from ros_isolated_test.history.record import record_trees

    warning = record_trees(_db(db), trees)
    if warning:
        click.echo(warning, err=True)


@history.command("prune")
@_db_option
@click.option(
    "--keep", type=click.IntRange(1, 1_000_000), help="Runs to keep from now on (default 200)."
)
def prune(db: Path | None, keep: int | None) -> None:
    """Drop all but the newest runs, and give the space back."""
    from ros_isolated_test.history import store

    path = _db(db)
    try:
        connection = store.connect(path)
        try:
            gone = store.prune(connection, keep, tidy=True)
        finally:
            connection.close()
    except store.StoreError as error:
        _failed(str(error))
    except Exception as error:
        _failed(str(store.problem(path, error)))
    click.echo(f"{gone} run(s) dropped")


@history.command("merge")
@click.option(
    "--db",
    type=click.Path(dir_okay=False, path_type=Path),
    required=True,
    help="The database to merge into (created if absent).",
)
@click.argument(
    "sources",
    nargs=-1,
    required=True,
    metavar="DB...",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
)
def merge(db: Path, sources: tuple[Path, ...]) -> None:
    """Merge the databases of several machines into --db; merging twice changes nothing."""
    from ros_isolated_test.history.merge import merge as merged
    from ros_isolated_test.history.store import StoreError

    try:
        new = merged(db, list(sources))
    except StoreError as error:
        _failed(str(error))
    click.echo(f"{new} new run(s)")


@history.command("export")
@_db_option
@click.option(
    "--jsonl", is_flag=True, required=True, help="One JSON object per attempt, a line each."
)
def export(db: Path | None, jsonl: bool) -> None:
    """Print every attempt of every run, oldest run first, for other tools."""
    from ros_isolated_test.history.export import json_lines
    from ros_isolated_test.history.store import StoreError, connect

    try:
        connection = connect(_db(db), write=False)
    except StoreError as error:
        _failed(str(error))
    try:
        for line in json_lines(connection):
            click.echo(line)
    finally:
        connection.close()


@history.command("durations")
@_db_option
@click.option(
    "--runs",
    type=click.IntRange(1, 100_000),
    default=20,
    show_default=True,
    help="How many of the last runs to take the median of.",
)
@click.argument("file", type=click.Path(dir_okay=False, path_type=Path))
def durations(db: Path | None, runs: int, file: Path) -> None:
    """Write the durations file a split plans from: each test's median of the last runs."""
    from ros_isolated_test.history.export import durations as from_history
    from ros_isolated_test.history.store import StoreError, connect
    from ros_isolated_test.shard.durations import write
    from ros_isolated_test.shard.spec import ShardSettingError

    try:
        connection = connect(_db(db), write=False)
    except StoreError as error:
        _failed(str(error))
    try:
        found = from_history(connection, runs)
    finally:
        connection.close()
    try:
        write(file, found)
    except (ShardSettingError, OSError) as error:
        _failed(str(error))
    click.echo(f"{len(found)} test(s) written to {file}")

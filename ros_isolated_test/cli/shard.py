"""``ros-isolated-test shard``: the plan of a split, to see before paying for machines.

The command only parses its arguments and hands over: the plan and its rendering live
in ``ros_isolated_test.shard``. What it reads of result trees is one function,
:func:`tests_in`, through the report package (``report.shard_durations.tests_in``).
Added to the command group by ``cli/__init__.py`` (``cli.add_command``).
"""

from __future__ import annotations

from pathlib import Path

import click

from ros_isolated_test.cli import usage
from ros_isolated_test.shard.spec import MAX_TOTAL


@click.command("shard")
@click.argument(
    "trees", nargs=-1, metavar="[TREE]...", type=click.Path(exists=True, path_type=Path)
)
@click.option("--plan", "show_plan", is_flag=True, help="Print each share's tests (required).")
@click.option(
    "--durations",
    "durations_file",
    metavar="FILE",
    help="The durations file the runners would plan from (or a test history database, "
    "read as `history durations` writes it). Default: "
    "ROS_ISOLATED_TEST_DURATIONS, else the split is by count.",
)
@click.option(
    "--total",
    type=click.IntRange(1, MAX_TOTAL),
    required=True,
    metavar="N",
    help=f"How many shares (machines) to split into, 1 to {MAX_TOTAL}.",
)
@click.option("--json", "as_json", is_flag=True, help="Print the same as JSON.")
def shard(
    trees: tuple[Path, ...], show_plan: bool, durations_file: str | None, total: int, as_json: bool
) -> None:
    """Show how the tests split over N machines, before paying for them.

    Prints the plan of a split into N shares: each share's tests and expected time, the
    total, and the lower bound no split beats (the larger of the total / N and the
    longest test), so you can pick N. The plan comes from the durations file alone
    (longest first onto the least loaded share, ties by name), so every machine
    computes the same one. TREE...: result trees of an earlier run; their tests the
    file does not know are shown in the share their name's hash draws, weighed as the
    file's median. Without a durations file the split is by count: by that hash alone.
    Exits 2 when the durations file cannot be read.
    """
    from ros_isolated_test.runner import settings
    from ros_isolated_test.shard import durations, plan, view
    from ros_isolated_test.shard.spec import ShardSettingError

    if not show_plan:
        raise click.UsageError("say what to show: --plan (each share's tests)")
    try:
        named = settings.durations_file(durations_file)
        if named is None and not trees:
            raise click.UsageError("nothing to plan: give --durations FILE, or result trees (TREE)")
        loaded = None if named is None else durations.load(*named)
    except ShardSettingError as error:
        usage.fail(str(error), usage.USAGE)
    found = tests_in(trees) if trees else None
    source = None if named is None else str(named[0])
    render = view.as_json if as_json else view.text
    click.echo(render(plan.Plan(total, loaded), found, source), nl=as_json)


def tests_in(trees: tuple[Path, ...]) -> set[str]:
    """The tests the runner and the plugin left results for under ``trees``.

    Read by the report package; a folder it cannot read is one note on stderr.
    """
    from ros_isolated_test.report.shard_durations import tests_in as read_tests
    from ros_isolated_test.text import display_text

    found, unreadable = read_tests(trees)
    for error in unreadable:
        folder = display_text(str(error.filename))
        click.echo(
            f"ros-isolated-test: note: cannot read {folder}: {error.strerror}; its tests "
            "are not shown",
            err=True,
        )
    return found

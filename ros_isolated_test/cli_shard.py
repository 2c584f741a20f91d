"""``ros-isolated-test shard``: the plan of a split, to see before paying for machines.

The command only parses its arguments and hands over: the plan and its rendering live
in ``ros_isolated_test.shard``. What it reads of result trees is one function,
:func:`tests_in`, through the report package's reading of which tests a file names.
Added to the command group by ``cli.py`` (``cli.add_command``).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import click

from ros_isolated_test.shard.spec import MAX_TOTAL

TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import NoReturn


class _OneLineCommand(click.Command):
    """A command whose usage errors are one line (click's own are three), exit 2."""

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        try:
            return super().parse_args(ctx, args)
        except click.UsageError as error:
            _usage(ctx, error)

    def invoke(self, ctx: click.Context) -> object:
        try:
            return super().invoke(ctx)
        except click.UsageError as error:
            _usage(ctx, error)


def _usage(ctx: click.Context, error: click.UsageError) -> NoReturn:
    said = error.format_message().strip().removesuffix(".")
    click.echo(
        f"ros-isolated-test: error: {said}; see ros-isolated-test {ctx.info_name} --help", err=True
    )
    ctx.exit(2)


@click.command("shard", cls=_OneLineCommand)
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
    from ros_isolated_test.shard import durations, plan, selection, view
    from ros_isolated_test.shard.spec import ShardSettingError

    if not show_plan:
        raise click.UsageError("say what to show: --plan (each share's tests)")
    try:
        named = selection.durations_file(os.environ, durations_file)
        if named is None and not trees:
            raise click.UsageError("nothing to plan: give --durations FILE, or result trees (TREE)")
        loaded = None if named is None else durations.load(*named)
    except ShardSettingError as error:
        click.echo(f"ros-isolated-test: error: {error}", err=True)
        sys.exit(2)
    found = tests_in(trees) if trees else None
    source = None if named is None else str(named[0])
    render = view.as_json if as_json else view.text
    click.echo(render(plan.Plan(total, loaded), found, source), nl=as_json)


def tests_in(trees: tuple[Path, ...]) -> set[str]:
    """The identities of the tests the runner and the plugin left results for under ``trees``.

    A runner's result file is its ctest test, an item in pytest's file under the plugin
    the node id it names (``report.measured``); other files name no test and are left out.
    """
    from ros_isolated_test.report.measured import named_tests
    from ros_isolated_test.report.tree import read_file, result_files
    from ros_isolated_test.text import display_text

    found: set[str] = set()
    for path in result_files(trees):
        if isinstance(path, OSError):
            folder = display_text(str(path.filename))
            click.echo(
                f"ros-isolated-test: note: cannot read {folder}: {path.strerror}; its tests "
                "are not shown",
                err=True,
            )
            continue
        item = read_file(path)
        if item is not None:
            found.update(key for key, _seconds in named_tests(item))
    return found

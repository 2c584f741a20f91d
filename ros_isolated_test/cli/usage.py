"""Usage errors of the command, one form for all: ``ros-isolated-test: error: <problem>; <fix>``.

Click's own is a four-line block (usage, a hint, a blank line, the error) in a form no
other part of the tool prints; a script or a CI log reads one line, the same from every
subcommand, the group and the RUNNER. The exit codes are the runner's
(``runner.exit_codes``), named here for the commands so no command exits with a literal.
"""

from __future__ import annotations

import sys

import click

from ros_isolated_test.runner import exit_codes

TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import NoReturn

#: The command's name, whatever started it (``python -m ros_isolated_test`` too).
PROG = "ros-isolated-test"
#: How every error line starts.
PREFIX = f"{PROG}: error: "
#: Nothing was done: bad arguments or settings, or a file the command cannot use.
USAGE = exit_codes.USAGE
#: The command ran and what it found failed, or a file could not be changed as asked.
FAILED = exit_codes.FAILED

# click >= 8.2: no arguments at all shows the help (a UsageError that prints it); kept.
_SHOWS_HELP: tuple[type[BaseException], ...] = tuple(
    kind for kind in (getattr(click.exceptions, "NoArgsIsHelpError", None),) if kind is not None
)


def command_path(ctx: click.Context) -> str:
    """``ros-isolated-test history record``: the command as typed, under our own name."""
    root = ctx.find_root().info_name or ""
    return f"{PROG} {ctx.command_path.removeprefix(root).strip()}".strip()


def line(error: click.UsageError, ctx: click.Context) -> str:
    """The problem click found, then where to look: ``<problem>; see <command> --help``.

    Without the prefix, which :func:`fail` and the runner's error line add.
    """
    said = error.format_message().strip().rstrip(".")
    return f"{said}; see {command_path(error.ctx or ctx)} --help"


def fail(problem: str, code: int = USAGE) -> NoReturn:
    """Say ``problem`` (already with its fix) in the one line, and exit with ``code``."""
    click.echo(f"{PREFIX}{problem}", err=True)
    sys.exit(code)


class OneLineGroup(click.Group):
    """The group whose every usage error, its own or any subcommand's, is one line, exit 2.

    click sets the context of the command that raised it on the error, so the line names
    the subcommand's ``--help``; a command may still answer its own first (``run`` writes
    the result file it was asked for).
    """

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        try:
            return super().parse_args(ctx, args)
        except click.UsageError as error:
            if isinstance(error, _SHOWS_HELP):
                raise
            fail(line(error, ctx))

    def invoke(self, ctx: click.Context) -> object:
        try:
            return super().invoke(ctx)
        except click.UsageError as error:
            if isinstance(error, _SHOWS_HELP):
                raise
            fail(line(error, ctx))

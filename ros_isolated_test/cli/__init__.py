"""The ``ros-isolated-test`` command: parses arguments and hands each command to its layer."""

from __future__ import annotations

import sys
import textwrap
from pathlib import Path

import click

from ros_isolated_test import __version__, names
from ros_isolated_test.cli import (
    cmake_include,
    history,
    normalise,
    report,
    run,
    runner_path,
    shard,
    status,
    usage,
)


def _environment_help() -> str:
    """The group's epilog: each variable of ours from the registry, its meaning beneath it."""
    lines = ["\b", "Environment:"]
    for entry in names.ENVIRONMENT:
        if entry.name.startswith("ROS_ISOLATED_TEST_") or entry.name == names.DISABLE:
            lines.append(f"  {entry.name}")
            lines.extend(
                textwrap.wrap(entry.meaning, 92, initial_indent=" " * 6, subsequent_indent=" " * 6)
            )
    return "\n".join(lines) + "\n"


ENVIRONMENT_HELP = _environment_help()


#: ``--version``: which copy answers and on which Python, for bug reports and for a machine
#: with more than one install (apt's under /opt/ros, a venv's, a workspace's).
VERSION_MESSAGE = "\n".join(
    (
        "%(prog)s %(version)s",
        f"installed in {Path(__file__).resolve().parent.parent}".replace("%", "%%"),
        f"Python {sys.version.split()[0]} ({sys.executable})".replace("%", "%%"),
    )
)


@click.group(
    cls=usage.OneLineGroup,
    context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100},
    epilog=ENVIRONMENT_HELP,
)
@click.version_option(__version__, prog_name="ros-isolated-test", message=VERSION_MESSAGE)
def cli() -> None:
    """Run ROS 2 tests in parallel, each on a ROS_DOMAIN_ID of its own.

    A machine-wide coordinator on file locks gives every test a free domain ID, so
    tests run at once (colcon test, ctest -j) never hear each other.
    """


for command in (
    run.run,
    status.status,
    report.report,
    normalise.normalise,
    shard.shard,
    history.history,
    runner_path.runner_path,
    cmake_include.cmake_include,
):
    cli.add_command(command)


def main() -> None:
    """Console-script entry point."""
    cli()

"""``ros-isolated-test run -- COMMAND``: a shell's way in, parsed and handed to the runner.

Its usage errors still leave the --junit-xml file that was asked for, so a CI step that
reads it learns why nothing ran.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import click

from ros_isolated_test.cli import usage
from ros_isolated_test.domain_coordinator.resources import CAPACITY_ENV, RESOURCES_ENV
from ros_isolated_test.not_run import NotRun
from ros_isolated_test.process.supervisor import KILL_GRACE
from ros_isolated_test.runner import session, settings
from ros_isolated_test.runner.request import Mode, RunRequest
from ros_isolated_test.runner.settings import (
    DEFAULT_WAIT_TIMEOUT,
    DISCOVERY_RANGE_ENV,
    ISOLATION_ENV,
    MAX_RERUNS,
    RERUNS_ENV,
    RERUNS_FLAKY_ENV,
    WAIT_TIMEOUT_ENV,
)
from ros_isolated_test.shard.spec import DURATIONS_ENV, SHARD_ENV

EXIT_CODES_HELP = """\b
Exit codes:
  N        the command's own exit code (0 passed); after reruns, the last attempt's
           (1 when a case failed and was then not run again)
  128+N    the command was killed by signal N, or the runner got signal N
  1        the test's result file reports failures, or the result file or
           --output-file could not be fully written
  2        nothing was run: bad arguments or settings, ROS_DOMAIN_ID (or
           GZ_PARTITION, IGN_PARTITION) was preset, --isolation namespace
           cannot be had here or is contradicted (SUBNET, remote static peers),
           the --junit-xml or --output-file path cannot be used, --resources
           asks for more than the capacity, or runners disagree on a capacity
  3        nothing was run: no domain ID (or the resources asked for) came free
  77       not run: the test is another share's of a split (--shard); else the
           command's own 77
  124      stopped by --timeout
  126/127  the command could not be executed / was not found
"""


def _finite(_ctx: click.Context, param: click.Parameter, value: float | None) -> float | None:
    """Reject nan and inf, which FloatRange lets through: either turns a limit off."""
    if value is not None and not math.isfinite(value):
        raise click.BadParameter(f"{value} is not a number of seconds", param=param)
    return value


def _is_path(value: str) -> bool:
    """Whether an option's value can name a file: an option word cannot.

    `--junit-xml -- cmd` would otherwise write a file `--`. Checked as typed (Path would
    make ./-name -name), so ./-name still names such a file.
    """
    return bool(value) and not value.startswith("-")


def _a_path(_ctx: click.Context, param: click.Parameter, value: str | None) -> Path | None:
    """Refuse an option word as a file name (:func:`_is_path`)."""
    if value is not None and not _is_path(value):
        raise click.BadParameter(f"needs a path, got {value!r}", param=param)
    return None if value is None else Path(value)


class _RunCommand(click.Command):
    """`run`, whose bad arguments still leave the --junit-xml file that was asked for."""

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        raw = list(args)  # click's parser consumes the list it is given
        try:
            return super().parse_args(ctx, args)
        except click.UsageError as error:
            # The one line (session adds its prefix), and the result file when one was asked.
            ctx.exit(session.report_usage_error(usage.line(error, ctx), _junit_xml_of(raw)))


def _junit_xml_of(args: list[str]) -> Path | None:
    """The --junit-xml path among raw arguments (before `--`), if one was given."""
    for index, item in enumerate(args):
        if item == "--":
            break
        value = None
        if item.startswith("--junit-xml="):
            value = item.split("=", 1)[1]
        elif item == "--junit-xml" and index + 1 < len(args):
            value = args[index + 1]
        if value is not None:
            # An option word (`--junit-xml -- true`) is no path: nothing is written there.
            return Path(value) if _is_path(value) else None
    return None


@click.command(
    cls=_RunCommand,
    # The first word that is no option of ours starts the command: its own options follow
    # it untouched. An unknown option before it is a typo, never the command.
    context_settings={"allow_interspersed_args": False},
    epilog=f"{EXIT_CODES_HELP}\n\b\nExample:\n  ros-isolated-test run --junit-xml out.xml -- "
    "python3 -m pytest test/test_talker.py",
)
@click.option(
    "--junit-xml",
    type=click.Path(dir_okay=False),
    callback=_a_path,
    help="Write an xUnit result file here (passed, failed with the output tail, or refused).",
)
@click.option(
    "--output-file",
    type=click.Path(dir_okay=False),
    callback=_a_path,
    help="Also write all output to this file, as it is produced.",
)
@click.option("--package-name", help="Package name for suite and class names in the result.")
@click.option(
    "--timeout",
    type=click.FloatRange(min=0, min_open=True),
    metavar="SECONDS",
    callback=_finite,
    help="Stop the test after this long (SIGTERM, then SIGKILL after --kill-grace); exit 124.",
)
@click.option(
    "--kill-grace",
    type=click.FloatRange(min=0),
    callback=_finite,
    default=KILL_GRACE,
    show_default=True,
    metavar="SECONDS",
    help="Time between SIGTERM and SIGKILL when stopping the test.",
)
@click.option(
    "--wait-timeout",
    type=click.FloatRange(min=0),
    callback=_finite,
    metavar="SECONDS",
    help=f"When every ID is in use, wait this long for one (first come, first served); 0 fails "
    f"at once. Default: {WAIT_TIMEOUT_ENV}, else {DEFAULT_WAIT_TIMEOUT:g}.",
)
@click.option(
    "--discovery-range",
    metavar="[LOCALHOST|SUBNET|OFF|SYSTEM_DEFAULT]",
    help=f"How far the test's DDS discovery reaches. Default: {DISCOVERY_RANGE_ENV}, else "
    "LOCALHOST unless ROS_AUTOMATIC_DISCOVERY_RANGE is set; SUBNET for tests that need other "
    "hosts or more than 32 processes.",
)
@click.option(
    "--rerun-failures",
    type=click.IntRange(min=0, max=MAX_RERUNS),
    metavar="N",
    help=f"Run a test that failed (exit code, failures in its result, timeout) again, up to N "
    f"(at most {MAX_RERUNS}) more times, each on a freshly reserved ID; every attempt is kept "
    f"in the result file, the exit code is the last attempt's (1 when a case failed and was then "
    f"not run again). Default: {RERUNS_ENV}, else 0.",
)
@click.option(
    "--rerun-flaky",
    type=click.IntRange(min=0, max=MAX_RERUNS),
    metavar="N",
    help=f"Run a failed test again up to N times only when the test history "
    f"(ROS_ISOLATED_TEST_HISTORY, else ./ros_isolated_test_history.sqlite3) calls it flaky; "
    f"a test new, stable or broken there fails at once. Every attempt is kept as with "
    f"--rerun-failures. Default: {RERUNS_FLAKY_ENV}, else 0.",
)
@click.option(
    "--resources",
    metavar="NAME=AMOUNT,...",
    help=f"Machine resources the test holds while it runs, taken with its ID (e.g. "
    f"cpu=2,mem=4G,gpu=1; mem in K, M, G, T): runners wait, first come first served, until "
    f"they are free, machine-wide. Capacity: {CAPACITY_ENV}, else the CPUs this runner may "
    f"use, MemTotal, and 1 of any other name (exclusive). Default: {RESOURCES_ENV}, else none.",
)
@click.option(
    "--isolation",
    metavar="[domain|namespace|auto]",
    help="domain: a reserved ROS_DOMAIN_ID. namespace: also Linux namespaces of the test's own "
    "(network with loopback only, a private /dev/shm, IPC, as the same user), so fixed ports "
    "and shared memory cannot collide either; never waits for an ID (runs unreserved when "
    "none is free); refused where user namespaces are not allowed. auto: namespace where "
    f"allowed, else domain. Default: {ISOLATION_ENV}, else domain.",
)
@click.option(
    "--shard",
    metavar="I/N",
    help=f"Run COMMAND only when it is in share I of N of a split (by its --package-name "
    f"and --junit-xml name, balanced by {DURATIONS_ENV}); else print why, write no result "
    f"and exit 77. Default: {SHARD_ENV}, else no split.",
)
@click.argument("command", nargs=-1, required=True, type=click.UNPROCESSED)
def run(
    junit_xml: Path | None,
    output_file: Path | None,
    package_name: str | None,
    timeout: float | None,
    kill_grace: float,
    wait_timeout: float | None,
    discovery_range: str | None,
    rerun_failures: int | None,
    rerun_flaky: int | None,
    resources: str | None,
    isolation: str | None,
    shard: str | None,
    command: tuple[str, ...],
) -> None:
    """Reserve a free ROS_DOMAIN_ID, run COMMAND with it, exit with its exit code.

    Put the command after `--`. Its stdout and stderr are streamed as produced. A
    ROS_DOMAIN_ID already set in the environment is refused: unset it, or set
    DISABLE_ROS_ISOLATION=1 to run without isolation. The test also gets a Gazebo
    transport partition of its own (GZ_PARTITION and IGN_PARTITION; a preset one is
    refused the same way). Every process the command
    starts is stopped when it ends, before the ID is released; SIGINT, SIGTERM and
    SIGHUP to the runner are passed on to the test.
    """
    try:
        config = settings.read(
            wait_timeout=wait_timeout,
            discovery_range=discovery_range,
            reruns=rerun_failures,
            resources=resources,
            isolation=isolation,
            reruns_flaky=rerun_flaky,
        )
        split = settings.split(shard)
        request = RunRequest(
            command=command,
            mode=Mode.SHELL,
            result_file=junit_xml,
            package_name=package_name,
            output_file=output_file,
            generate_result_on_success=True,
            timeout=timeout,
            kill_grace=kill_grace,
            settings=config,
            shard=split,
        )
    except NotRun as error:
        sys.exit(session.report_usage_error(str(error), junit_xml))
    sys.exit(session.run(request))

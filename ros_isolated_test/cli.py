"""The ``ros-isolated-test`` command: parses arguments and hands each command to its layer."""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path

import click

from ros_isolated_test import __version__
from ros_isolated_test.cli_history import history
from ros_isolated_test.cli_report import report
from ros_isolated_test.cli_shard import shard
from ros_isolated_test.domain_coordinator.resources import CAPACITY_ENV, RESOURCES_ENV
from ros_isolated_test.process.supervisor import KILL_GRACE
from ros_isolated_test.runner import session, settings, share
from ros_isolated_test.runner.partition import OPT_OUT_ENV as GZ_PARTITION_ENV
from ros_isolated_test.runner.request import Mode, RunRequest
from ros_isolated_test.runner.settings import (
    DEFAULT_WAIT_TIMEOUT,
    DISABLE_VAR,
    DISCOVERY_RANGE_ENV,
    ISOLATION_ENV,
    LOCK_DIR_ENV,
    MAX_RERUNS,
    POOL_ENV,
    RERUNS_ENV,
    RERUNS_FLAKY_ENV,
    WAIT_TIMEOUT_ENV,
)
from ros_isolated_test.shard.spec import DURATIONS_ENV, SHARD_ENV, ShardSettingError

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

ENVIRONMENT_HELP = f"""\b
Environment:
  {POOL_ENV}          domain IDs to hand out (e.g. 1-50,215-232); default 1-101,
                                     less any whose DDS ports fall in the host's
                                     net.ipv4.ip_local_port_range
  {LOCK_DIR_ENV}         the lock directory shared by all runners on the machine
  {WAIT_TIMEOUT_ENV}      seconds to wait for a free ID (run --wait-timeout)
  {DISCOVERY_RANGE_ENV}  LOCALHOST|SUBNET|OFF|SYSTEM_DEFAULT (run --discovery-range)
  {RERUNS_ENV}           rerun a failed test up to N times, N <= {MAX_RERUNS} (run --rerun-failures)
  {RERUNS_FLAKY_ENV}     as many, only for a test the history calls flaky (run --rerun-flaky)
  {RESOURCES_ENV}        resources the test holds, e.g. cpu=2,mem=4G,gpu=1 (run --resources)
  {CAPACITY_ENV}         what the machine has, e.g. cpu=8,mem=16G,gpu=1,sim=2; default:
                                     the CPUs usable, MemTotal, 1 of anything else;
                                     give every runner the same
  {GZ_PARTITION_ENV}=off set no Gazebo partition (GZ_PARTITION, IGN_PARTITION)
                                     per test, and refuse no preset one
  {ISOLATION_ENV}=namespace|auto  the test's own network, /dev/shm and
                                     IPC too, never waiting for an ID (run --isolation)
  {DISABLE_VAR}=1                 run without reserving an ID (loudly)
  {SHARD_ENV}=I/N        run only share I of N of the tests (run --shard)
  {DURATIONS_ENV}=FILE   the durations file (absolute) the split balances by
"""


#: ``--version``: which copy answers and on which Python, for bug reports and for a machine
#: with more than one install (apt's under /opt/ros, a venv's, a workspace's).
VERSION_MESSAGE = "\n".join(
    (
        "%(prog)s %(version)s",
        f"installed in {Path(__file__).resolve().parent}".replace("%", "%%"),
        f"Python {sys.version.split()[0]} ({sys.executable})".replace("%", "%%"),
    )
)


@click.group(
    context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100},
    epilog=ENVIRONMENT_HELP,
)
@click.version_option(__version__, prog_name="ros-isolated-test", message=VERSION_MESSAGE)
def cli() -> None:
    """Run ROS 2 tests in parallel, each on a ROS_DOMAIN_ID of its own.

    A machine-wide coordinator on file locks gives every test a free domain ID, so
    tests run at once (colcon test, ctest -j) never hear each other.
    """


cli.add_command(report)
cli.add_command(shard)
cli.add_command(history)


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
            # One line (click's own error is three), and the result file when one was asked.
            # session prefixes "ros-isolated-test: error: "; click ends its sentences in ".".
            said = error.format_message().strip().removesuffix(".")
            message = f"{said}; see ros-isolated-test run --help"
            ctx.exit(session.report_usage_error(message, _junit_xml_of(raw)))


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


@cli.command(
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
        split = share.read(os.environ, shard)
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
    except (settings.SettingsError, ShardSettingError) as error:
        sys.exit(session.report_usage_error(str(error), junit_xml))
    sys.exit(session.run(request))


@cli.command("runner-path")
def runner_path() -> None:
    """Print the path of the ctest RUNNER script for ament_add_test / add_launch_test.

    \b
    In CMakeLists.txt:
      execute_process(COMMAND ros-isolated-test runner-path
        OUTPUT_VARIABLE RUNNER OUTPUT_STRIP_TRAILING_WHITESPACE COMMAND_ERROR_IS_FATAL ANY)
      ament_add_test(my_test RUNNER "${RUNNER}" COMMAND ...)
    """  # noqa: D301 (click reads a backspace, not a backslash, as "keep these lines")
    from ros_isolated_test.runner.ament import installed

    click.echo(str(installed.runner_script()))


@cli.command("cmake-include")
@click.option(
    "--colcon-defaults",
    is_flag=True,
    help="Print a colcon defaults file that passes it to every build; with FILE, add it to "
    "that defaults file (made if missing), keeping every setting the file has.",
)
@click.argument("defaults_file", metavar="[FILE]", required=False, type=Path)
def cmake_include(colcon_defaults: bool, defaults_file: Path | None) -> None:
    """Print the path of the CMake file that isolates every ament_cmake package's tests.

    \b
    Nothing edited; each package's CMake cache keeps it for later builds:
      colcon build --cmake-args -DCMAKE_PROJECT_INCLUDE=$(ros-isolated-test cmake-include)
    Once for every build, in the defaults file colcon reads (COLCON_DEFAULTS_FILE, else
    $COLCON_HOME/defaults.yaml): added to the one you have, every other setting kept
      ros-isolated-test cmake-include --colcon-defaults ~/.colcon/defaults.yaml
    or a new one (never redirect it over a file you have: that drops its settings)
      ros-isolated-test cmake-include --colcon-defaults > isolated.yaml
      COLCON_DEFAULTS_FILE=isolated.yaml colcon build
    A FILE that cannot be changed safely is left as it is: the lines to add are
    printed, and the exit code is 1.
    Off: --cmake-args -DROS_ISOLATED_TEST_ALL=OFF, or -UCMAKE_PROJECT_INCLUDE to drop it.
    """  # noqa: D301 (click reads a backspace, not a backslash, as "keep these lines")
    from ros_isolated_test.runner.ament import colcon_defaults as defaults
    from ros_isolated_test.runner.ament import installed

    if defaults_file is not None and not colcon_defaults:
        raise click.UsageError("FILE is the colcon defaults file of --colcon-defaults: add it")
    path = installed.cmake_include()
    if path is None:
        click.echo(
            f"ros-isolated-test: error: the CMake files are not installed "
            f"({installed.CMAKE_INCLUDE} beside this package); reinstall ros-isolated-test "
            "with pip",
            err=True,
        )
        sys.exit(2)
    if not colcon_defaults:
        click.echo(str(path))
    elif defaults_file is None:
        click.echo(installed.colcon_defaults(path))
    else:
        try:
            added = defaults.add_to_file(defaults_file, path)
        except defaults.DefaultsError as error:
            click.echo(defaults.lines_to_add(path), nl=False)
            click.echo(
                f"ros-isolated-test: error: {defaults_file} was left as it is: {error}; add "
                "the lines above to it by hand",
                err=True,
            )
            sys.exit(1)
        click.echo(defaults.said(defaults_file, path, added))


@cli.command()
@click.option("--json", "as_json", is_flag=True, help="Print a JSON list instead of a table.")
def status(as_json: bool) -> None:
    """List every domain ID in use on this machine, and by whom; then who waits for one.

    GZ_PARTITION is the Gazebo transport partition a runner gave its test (GZ_PARTITION,
    IGN_PARTITION; "gz_partition" in --json), unless it ran with
    ROS_ISOLATED_TEST_GZ_PARTITION=off.
    HELD BY is "runner" (a ros-isolated-test runner holds its lock), "port" (its TCP
    port 32768+ID is bound: upstream's domain_coordinator, Kilted's rmw_test_fixture
    or another program), "participant" (a DDS participant outside any runner is
    bound to the ID's UDP ports, whoever started it and however it chose the ID),
    "survivor" (a process of an earlier test that its runner could not end, or that a
    killed runner left, named in a block record; listed once, though its environment
    also carries the ID) or
    "squatter" (a live process has ROS_DOMAIN_ID=<id> in its environment without
    holding it: a test that outlived a killed runner, a shell's export). The
    coordinator skips all of them; squatters once their ID's last holder died holding
    it (a clean release leaves none). Runners queued for an ID follow, in the order
    they get one
    (in --json: rows with "via": "queue", "domain_id": null and their "position"),
    then the machine resources runners hold (rows with "via": "hold" and their
    "resources") and the capacity (one row with "via": "capacity"), when resources are
    held, asked for, or ROS_ISOLATED_TEST_CAPACITY is set.
    The last line (on stderr with --json) says whether colcon on PATH loads
    ros-isolated-test's colcon extension, which isolates colcon test with no flag.
    """
    from ros_isolated_test.domain_coordinator.status import machine_status
    from ros_isolated_test.runner import status_table
    from ros_isolated_test.runner.ament import colcon_on_path

    try:
        # reruns=0: never reads ROS_ISOLATED_TEST_RERUNS (nor _FLAKY), which only `run`
        # uses. Nor the isolation mode, which only the runs read.
        config = settings.read(
            reruns=0, resources="", isolation=settings.DEFAULT_ISOLATION, reruns_flaky=0
        )
    except settings.SettingsError as error:
        click.echo(f"ros-isolated-test: error: {error}", err=True)
        sys.exit(2)
    for note in config.notes:  # the pool a runner here would use; on stderr: --json parses
        click.echo(f"ros-isolated-test: {note}", err=True)
    found = machine_status(config.lock_dir, config.pool, config.capacity)
    # A planted shared queue folder: on stderr, so --json stays parseable.
    if found.queue_problem is not None:
        click.echo(f"ros-isolated-test: note: {found.queue_problem}", err=True)
    click.echo(status_table.as_json(found) if as_json else status_table.table(found))
    # Whether `colcon test` here is isolated with no flag: after the table, or on stderr.
    click.echo(colcon_on_path.said(), err=as_json)


@cli.command()
@click.argument("source", type=click.Path(exists=True, path_type=Path))
@click.option(
    "--output",
    "-o",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Write the canonical file here instead of printing it.",
)
@click.option("--package-name", required=True, help="Package: suite name and classname prefix.")
@click.option("--test-name", help="Test name in the suite name (default: SOURCE's stem).")
def normalise(source: Path, output: Path | None, package_name: str, test_name: str | None) -> None:
    """Turn one result file into the canonical form of schemas/junit.xsd.

    Reads gtest, pytest, launch_testing, unittest-xml-reporting and ctest files (and
    broken ones), as the runner does after every test; for tests that did not run
    through it. Exits 1 when the result reports failures or errors, like `report`.
    """
    from ros_isolated_test.xunit import canonical

    try:
        data, failed = canonical.normalise_to(source, output, package_name, test_name)
    except canonical.OutputError as error:
        # Its output path cannot be used: one line, exit 2.
        click.echo(f"ros-isolated-test: error: {error}", err=True)
        sys.exit(2)
    if output is None:
        click.echo(data.decode("utf-8"), nl=False)
    if failed:
        sys.exit(1)


def main() -> None:
    """Console-script entry point."""
    cli()

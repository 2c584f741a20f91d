"""The ``ros-isolated-test`` command: parses arguments and hands each command to its layer."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from ros_isolated_test import __version__
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
from ros_isolated_test.domain_coordinator.resources import CAPACITY_ENV, RESOURCES_ENV
from ros_isolated_test.runner.partition import OPT_OUT_ENV as GZ_PARTITION_ENV
from ros_isolated_test.runner.settings import (
    DISABLE_VAR,
    DISCOVERY_RANGE_ENV,
    ISOLATION_ENV,
    LOCK_DIR_ENV,
    MAX_RERUNS,
    POOL_ENV,
    RERUNS_ENV,
    WAIT_TIMEOUT_ENV,
)
from ros_isolated_test.shard.spec import DURATIONS_ENV, SHARD_ENV

ENVIRONMENT_HELP = f"""\b
Environment:
  {POOL_ENV}          domain IDs to hand out (e.g. 1-50,215-232); default 1-101,
                                     less any whose DDS ports fall in the host's
                                     net.ipv4.ip_local_port_range
  {LOCK_DIR_ENV}         the lock directory shared by all runners on the machine
  {WAIT_TIMEOUT_ENV}      seconds to wait for a free ID (run --wait-timeout)
  {DISCOVERY_RANGE_ENV}  LOCALHOST|SUBNET|OFF|SYSTEM_DEFAULT (run --discovery-range)
  {RERUNS_ENV}           rerun a failed test up to N times, N <= {MAX_RERUNS} (run --rerun-failures)
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

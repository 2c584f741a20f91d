"""``ros-isolated-test status``: who holds each domain ID on this machine, who waits."""

from __future__ import annotations

import click

from ros_isolated_test.cli import usage
from ros_isolated_test.runner import settings


@click.command()
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
    A line on stderr (stdout is the table or the JSON alone) says whether colcon on PATH loads
    ros-isolated-test's colcon extension, which isolates colcon test with no flag.
    """
    from ros_isolated_test.cli import colcon_on_path, status_table
    from ros_isolated_test.domain_coordinator.status import machine_status

    try:
        # reruns=0: never reads ROS_ISOLATED_TEST_RERUNS (nor _FLAKY), which only `run`
        # uses. Nor the isolation mode, which only the runs read.
        config = settings.read(
            reruns=0, resources="", isolation=settings.DEFAULT_ISOLATION, reruns_flaky=0
        )
    except settings.SettingsError as error:
        usage.fail(str(error), usage.USAGE)
    for note in config.notes:  # the pool a runner here would use; on stderr: --json parses
        click.echo(f"ros-isolated-test: {note}", err=True)
    found = machine_status(config.lock_dir, config.pool, config.capacity)
    # A planted shared queue folder: on stderr, so --json stays parseable.
    if found.queue_problem is not None:
        click.echo(f"ros-isolated-test: note: {found.queue_problem}", err=True)
    click.echo(status_table.as_json(found) if as_json else status_table.table(found))
    # Whether `colcon test` here is isolated with no flag: on stderr, as the notes are, so
    # a script reading the table or the JSON reads them alone.
    click.echo(colcon_on_path.said(), err=True)

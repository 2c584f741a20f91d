"""What a run says first, and records in its result: the ID, the partition, how it is kept apart.

One wording for the runner's output and the pytest plugin's header, so a reader who
has seen one knows the other; each line has its suite property beside it, so the
result file says what the console said.
"""

from __future__ import annotations

from ros_isolated_test import names
from ros_isolated_test.runner import environment, partition

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from ros_isolated_test.runner import settings
    from ros_isolated_test.runner.isolation import Lease

#: The suite property holding the settings' notes (IDs left out of the default pool, ...).
SETTINGS_NOTES = "settings_notes"
NOTES_SEPARATOR = " | "


def header_line(policy: environment.Policy, domain_id: int, reserved: bool = True) -> str:
    """The runner's first line: the test's domain ID, and its Gazebo partition beside it.

    Starts as upstream's does (``Running with ROS_DOMAIN_ID <id>``): what greps for it
    finds it. Then, where isolation is not the default, what keeps the test apart:
    its namespaces (and whether the ID is its own), or auto's fall-back to the ID alone.
    """
    gz_name = policy.partition_for(domain_id)
    line = f"Running with ROS_DOMAIN_ID {domain_id}"
    if gz_name is not None:
        line += f" (Gazebo partition {gz_name})"
    if policy.namespaces and reserved:
        line += ", in namespaces of its own"
    elif policy.namespaces:
        line += (
            f", in namespaces of its own; ID {domain_id} is not reserved (no ID of the pool "
            "is free): the namespaces isolate the test"
        )
    elif policy.fallback is not None:
        line += "; isolation auto: by the domain ID alone, no namespaces (see below)"
    return line + replacing(policy)


def replacing(policy: environment.Policy) -> str:
    """``, replacing ROS_DOMAIN_ID 14 of <tool>`` after the ID, or "".

    The runner's first line and the pytest plugin's say it alike.
    """
    setter = policy.replaced
    return "" if setter is None else f", replacing ROS_DOMAIN_ID {setter.value} of {setter.short}"


def replaced_summary(
    policy: environment.Policy, domain_id: int
) -> tuple[list[str], dict[str, str]]:
    """Why a tool's ID was replaced: the line after the header, and its property."""
    setter = policy.replaced
    if setter is None:
        return [], {}
    why = {
        "colcon": "which gives one ID to all tests of a package, tests ctest runs at once",
    }.get(setter.kind, "an ID chosen outside the pool our runners share")
    text = (
        f"ROS_DOMAIN_ID {setter.value} was set by {setter.name}, pid {setter.pid}, {why}: "
        f"replaced by {domain_id}, an ID of this test's own; {setter.value} stays "
        f"{setter.short.split(' ', 1)[0]} while it holds it"
    )
    return [text], {"ros_domain_id_replaced": f"{setter.value}: {text}"}


def resources_summary(held: Lease, config: settings.Settings) -> tuple[str, dict[str, str]]:
    """The line saying what the test holds besides its ID, and the properties recording it."""
    from ros_isolated_test.domain_coordinator.resources import describe

    asked = describe(held.resources)
    capacity = describe({name: config.capacity[name] for name in held.resources})
    line = f"holding {asked} of {capacity} (waited {held.waited:.1f} s)"
    return line, {
        "resources": asked,
        "resources_waited": f"{held.waited:.3f}",
        "capacity": capacity,
    }


def summary(
    policy: environment.Policy,
    domain_id: int | None,
    config: settings.Settings | None = None,
    reserved: bool = True,
) -> tuple[list[str], dict[str, str]]:
    """What a run on ``domain_id`` (None: isolation disabled) says first, and its properties.

    ``config``'s notes concern the pool, so they are said only when an ID was handed out.
    ``reserved``: False for a test in namespaces that runs on an ID it does not hold.
    """
    lines: list[str] = []
    properties: dict[str, str] = {}
    if domain_id is not None:
        properties[names.DOMAIN_ID] = str(domain_id)
        if policy.discovery is not None:
            lines.append(policy.discovery.describe())
            if not policy.namespaces:  # in namespaces, static peers are loopback only
                lines.extend(policy.discovery.warnings)
            properties.update(policy.discovery.properties())
        # Gazebo's transport ignores the domain: its own partition, said beside it.
        gz_name = policy.partition_for(domain_id)
        lines.append(partition.describe(gz_name))
        properties[partition.PROPERTY] = gz_name or f"not set ({partition.OPT_OUT_ENV}=off)"
        more, isolated = isolation_summary(policy, domain_id, reserved)
        lines.extend(more)
        properties.update(isolated)
        for part in (replaced_summary(policy, domain_id), _fixture_summary(policy, domain_id)):
            lines.extend(part[0])
            properties.update(part[1])
        if config is not None and config.notes:
            lines.extend(config.notes)
            properties[SETTINGS_NOTES] = NOTES_SEPARATOR.join(config.notes)
    else:
        properties[names.DOMAIN_ID] = policy.env.get(environment.DOMAIN_VAR, "unset (0)")
        properties[names.ISOLATION_PROPERTY] = "disabled"
        preset = [policy.env[name] for name in partition.VARIABLES if name in policy.env]
        properties[partition.PROPERTY] = preset[0] if preset else "unset"
    lines.extend(policy.notes)
    return lines, properties


def isolation_summary(
    policy: environment.Policy, domain_id: int, reserved: bool
) -> tuple[list[str], dict[str, str]]:
    """The lines and properties saying how the test is kept apart, unless by default.

    Domain isolation asked for by nobody (the default) says nothing new: results look
    as they always did.
    """
    if policy.namespaces:
        from ros_isolated_test.process import namespace

        lines = [
            "isolation namespace: network (loopback only), mount (a private /dev/shm) and "
            f"IPC namespaces of its own, in a user namespace as {namespace.describe_user()}: "
            "its ports, multicast, abstract Unix sockets, /dev/shm and IPC are its own; files "
            "(a Unix socket bound to a path too) and processes (/proc, signals) are shared "
            "with the host"
        ]
        mode = "namespace" if policy.mode == "namespace" else "namespace (auto)"
        properties = {"isolation": mode}
        if reserved:
            properties[names.ROS_DOMAIN_ID_RESERVED] = "yes"
        else:
            why = "no ID of the pool is free (in use, or waited for by queued runners)"
            lines.append(
                f"ROS_DOMAIN_ID {domain_id} is not reserved: {why}; the test runs at once "
                "on it, isolated by its namespaces"
            )
            properties[names.ROS_DOMAIN_ID_RESERVED] = f"no: {why}; the namespaces isolate the test"
        return lines, properties
    if policy.fallback is not None:
        return (
            [f"isolation auto: by the domain ID alone, {policy.fallback}"],
            {"isolation": f"domain (auto: {policy.fallback})"},
        )
    if policy.mode != "domain":
        return [], {"isolation": policy.mode}
    return [], {}


def _fixture_summary(
    policy: environment.Policy, domain_id: int
) -> tuple[list[str], dict[str, str]]:
    """What was done about Kilted's rmw_test_fixture, unless the silent default."""
    if policy.fixture is None:
        return [], {}
    return policy.fixture.summary(domain_id)

"""What ``ros-isolated-test status`` prints: the table, or its rows as JSON.

The coordinator reads what is in use (``domain_coordinator.status``); this draws it.
It sits with the command, above the runner: each runner's row shows its test's Gazebo
partition, which only the runner's ``partition`` knows how to name.
"""

from __future__ import annotations

import json

from ros_isolated_test.domain_coordinator.records import iso_time
from ros_isolated_test.domain_coordinator.resources import describe
from ros_isolated_test.domain_coordinator.status import DomainUse, MachineStatus, anonymous_holder
from ros_isolated_test.runner import partition

#: HELD BY for each kind of use (the others show as they are named): an upstream
#: coordinator's ID (its port held, its process named) as that coordinator's.
_KINDS = {
    "lock": "runner",
    "port": "port",
    "environment": "squatter",
    "colcon": "colcon",
    "upstream": "upstream",
    "fixture": "rmw fixture",
}


def gz_partition(use: DomainUse) -> str | None:
    """The Gazebo partition a runner's test has: a function of its record, as the runner made it.

    A runner with ROS_ISOLATED_TEST_GZ_PARTITION=off set none; its record cannot say so.
    """
    if use.via != "lock" or use.holder is None:
        return None
    return partition.name(use.holder.host, use.domain_id, use.holder.pid)


def as_json(status: MachineStatus) -> str:
    """``status --json``: IDs in use, then waiters, holds and (when in play) the capacity."""
    rows: list[dict[str, object]] = [
        {
            "domain_id": use.domain_id,
            "via": use.via,
            **(use.holder.as_dict() if use.holder else {}),
            **({"gz_partition": gz} if (gz := gz_partition(use)) else {}),
            **({"ports": list(use.ports)} if use.ports else {}),
            **({"replaced": use.replaced} if use.replaced else {}),
        }
        for use in status.uses
    ]
    rows += [{**waiter.as_dict(), "domain_id": None, "via": "queue"} for waiter in status.waiters]
    rows += [{**hold.as_dict(), "via": "hold"} for hold in status.holds]
    if status.in_play:
        rows.append({"via": "capacity", "domain_id": None, "capacity": status.capacity})
    return json.dumps(rows, indent=2)


def table(status: MachineStatus) -> str:
    """The table ``status`` prints: IDs in use, then waiters, then resources when in play."""
    if not status.uses:
        lines = [f"No domain ID of the pool is held (lock directory {status.lock_dir})."]
    else:
        lines = _uses(status.uses)
    if status.waiters:
        lines += [
            "",
            f"Waiting for a domain ID ({len(status.waiters)}, first come, first served):",
            f"{'POS':>3}  {'PID':>7}  {'USER':<10} {'WAITING SINCE':<19}  COMMAND",
        ]
        for waiter in status.waiters:
            asks = f"[{describe(waiter.resources)}] " if waiter.resources else ""
            lines.append(
                f"{waiter.position:>3}  {waiter.pid:>7}  {waiter.user:<10.10} "
                f"{waiter.since_iso:<19}  {asks}{waiter.command}"
            )
    if status.in_play:
        lines += _resources(status)
    return "\n".join(lines)


def _uses(uses: list[DomainUse]) -> list[str]:
    names = {id(use): gz_partition(use) or "-" for use in uses}
    width = max(len("GZ_PARTITION"), *map(len, names.values()))
    lines = [
        f"{'ID':>3}  {'HELD BY':<11} {'PID':>7}  {'USER':<10} {'STARTED':<19}  "
        f"{'GZ_PARTITION':<{width}}  COMMAND"
    ]
    for use in uses:
        kind = _KINDS.get(use.via, use.via)
        gz = names[id(use)]
        if use.holder is None:
            lines.append(
                f"{use.domain_id:>3}  {kind:<11} {'-':>7}  {'-':<10} {'-':<19}  "
                f"{gz:<{width}}  {anonymous_holder(use)}"
            )
            continue
        holder = use.holder
        # A runner whose test got this ID in place of a tool's (colcon's coordinator).
        replaced = f"[replaced {_owner(use.replaced)}] " if use.replaced else ""
        lines.append(
            f"{use.domain_id:>3}  {kind:<11} {holder.pid:>7}  {holder.user:<10.10} "
            f"{holder.started_iso:<19}  {gz:<{width}}  {replaced}{holder.command}"
        )
    return lines


def _owner(replaced: str) -> str:
    """``colcon's ROS_DOMAIN_ID 14`` for ``14 (colcon's domain-ID coordinator)``."""
    value, _, tool = replaced.partition(" (")
    owner = tool.split("'s ", 1)[0] if "'s " in tool else tool.rstrip(")")
    return f"{owner}'s ROS_DOMAIN_ID {value}"


def _resources(status: MachineStatus) -> list[str]:
    lines = ["", f"Resources (capacity {describe(status.capacity)}):"]
    if not status.holds:
        return [*lines, "  none held"]
    lines.append(f"{'PID':>7}  {'USER':<10} {'SINCE':<19}  {'ID':>3}  {'HOLDS':<20} COMMAND")
    for hold in status.holds:
        domain = "-" if hold.domain_id is None else str(hold.domain_id)
        # A hold its runner left to survivors of its test: they are what keeps it.
        kept = f"(survivors {', '.join(map(str, hold.survivors))}) " if hold.survivors else ""
        lines.append(
            f"{hold.pid:>7}  {hold.user:<10.10} {iso_time(hold.since):<19}  {domain:>3}  "
            f"{describe(hold.resources):<20} {kept}{hold.command}"
        )
    return lines

"""The suite properties a result's timeline is drawn from: when each attempt ran, and its wait.

Apart from the result file's life cycle because two sides share them: the runner
records them for each attempt, and the report's page (``report.html_timeline``) reads
them back from files gathered, perhaps, from several machines.
"""

from __future__ import annotations

import time

from ros_isolated_test import names

#: Suite properties the report's timeline draws from (one set per attempt; a rerun's
#: earlier ones as ``attempt_<k>.<name>``): when the command started and ended (local
#: ISO 8601 to the microsecond, with the zone), the seconds waited before it for an ID
#: and for the resources asked for, and the pool the ID came from.
STARTED_AT = names.STARTED_AT
ENDED_AT = names.ENDED_AT
WAIT_DOMAIN = names.WAIT_DOMAIN
WAIT_RESOURCES = names.WAIT_RESOURCES
DOMAIN_POOL = names.DOMAIN_POOL


def instant(when: float) -> str:
    """``when`` as local ISO 8601 to the microsecond, with its zone: ordered across hosts.

    The suite's ``timestamp`` keeps the second and no zone, as the strictest readers
    want; a timeline of short tests, gathered from several machines, needs both.
    """
    local = time.localtime(when)
    minutes = local.tm_gmtoff // 60
    sign = "-" if minutes < 0 else "+"
    hours, minutes = divmod(abs(minutes), 60)
    micro = min(int(when % 1 * 1_000_000), 999_999)
    day = time.strftime("%Y-%m-%dT%H:%M:%S", local)
    return f"{day}.{micro:06d}{sign}{hours:02d}:{minutes:02d}"


def timeline_properties(
    started: float, ended: float, waited: float, waited_resources: float, pool: str
) -> dict[str, str]:
    """The properties of one attempt for the timeline (see :data:`STARTED_AT`).

    ``pool`` is the pool the ID came from as ID ranges (``102-110, 150``), empty when
    the test held no ID.
    """
    found = {
        STARTED_AT: instant(started),
        ENDED_AT: instant(ended),
        WAIT_DOMAIN: f"{max(waited - waited_resources, 0.0):.3f}",
        WAIT_RESOURCES: f"{waited_resources:.3f}",
    }
    if pool:
        found[DOMAIN_POOL] = pool
    return found

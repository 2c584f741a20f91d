"""What the history gives other tools: every attempt as JSON lines, and a durations file.

``history export --jsonl`` writes one object per attempt, oldest run first, for any
tool that keeps its own dashboard. ``history durations FILE`` writes the durations file
a split plans from (``shard.durations``): each test's median last attempt over the
window, so no one carries the file by hand.
"""

from __future__ import annotations

import json
import sqlite3
from collections.abc import Iterator

from ros_isolated_test.history.stats import DEFAULT_RUNS
from ros_isolated_test.history.store import loaded
from ros_isolated_test.shard.durations import Durations, history_medians, measured

_RUN_FIELDS = (
    "key",
    "started",
    "host",
    "git_commit",
    "branch",
    "job_url",
    "distro",
    "rmw",
    "shard",
    "plan",
    "tool_version",
)


def json_lines(connection: sqlite3.Connection) -> Iterator[str]:
    """Each attempt of each run as one line of JSON, oldest run first."""
    runs = connection.execute(
        f"SELECT id, {', '.join(_RUN_FIELDS)} FROM runs ORDER BY started, id"
    ).fetchall()
    for run, *fields in runs:
        about = dict(zip(_RUN_FIELDS, fields, strict=True))
        for name, attempt, outcome, seconds, domain, signature in connection.execute(
            "SELECT t.name, a.attempt, a.outcome, a.seconds, a.domain_id, a.signature"
            " FROM attempts a JOIN tests t ON t.id = a.test WHERE a.run = ?"
            " ORDER BY t.name, a.attempt",
            (run,),
        ):
            line = {
                "run": about,
                "test": loaded(name),
                "attempt": attempt,
                "outcome": outcome,
                "seconds": seconds,
                "domain_id": domain,
                "signature": signature,
            }
            yield json.dumps(line, ensure_ascii=True)


def durations(connection: sqlite3.Connection, runs: int = DEFAULT_RUNS) -> Durations:
    """Each test's median last-attempt seconds over the last ``runs`` runs.

    Read by ``shard.durations`` (which a split planning from the database itself calls
    too), so the file written and the database give the same plan.
    """
    return measured(history_medians(connection, runs))

"""Tests that fail on purpose, and how a rerun series is read back from its result file.

For the rerun tests (``runner.reruns``): state lives in a file, so the first attempt fails
and the next passes; each series is checked as CI reads it: valid against our schema and
Jenkins' junit-10 rules, a flaky pass with a ``flakyFailure`` and no failure, and
``report`` calling it flaky.
"""

from __future__ import annotations

import json
import re
import subprocess
from pathlib import Path

from lxml import etree

from helpers import jenkins_junit10, xunit
from helpers.commands import run_cli
from helpers.processes import Children, poll_until
from ros_isolated_test.domain_coordinator.queue import Queue
from ros_isolated_test.schemas import junit_schema

#: Fails the first time (no state file yet), passes after: the flake, made certain.
FLAKY = (
    'if [ -e "$1" ]; then echo "passed on $ROS_DOMAIN_ID"; exit 0; fi; '
    ': > "$1"; echo "failed on $ROS_DOMAIN_ID"; exit 1'
)
#: Fails every time, with 10 + the attempt's number: the exit code says which attempt it was.
COUNTING = (
    'n=$(( $(cat "$1" 2>/dev/null || echo 0) + 1 )); echo "$n" > "$1"; '
    'echo "attempt $n on $ROS_DOMAIN_ID"; exit $((10 + n))'
)
DOMAIN_LINE = re.compile(r"^Running with ROS_DOMAIN_ID (\d+)\b", re.MULTILINE)

#: Queues for the one ID (first come, first served), prints "held" once it has it, holds it
#: until stdin closes. argv: lock dir, ID.
QUEUE_AND_HOLD = """
import sys
from pathlib import Path
from ros_isolated_test.domain_coordinator import DomainCoordinator
from ros_isolated_test.domain_coordinator.queue import Queue
coordinator = DomainCoordinator(Path(sys.argv[1]), [int(sys.argv[2])])
reservation = coordinator.acquire(["queued holder"], wait_timeout=120)
print("held", flush=True)
sys.stdin.read()
reservation.release()
"""


def queued_holder(children: Children, lock_dir: Path, domain_id: int) -> subprocess.Popen[str]:
    """A holder queued for the pool's one ID while attempt 1 holds it: it gets it first.

    So the rerun waits behind it, for as long as the test keeps it (``children.finish``).
    """
    holder = children.python(QUEUE_AND_HOLD, lock_dir, domain_id)
    poll_until(lambda: bool(Queue(lock_dir).waiters()), "the holder queued")
    return holder


def ids_of(stdout: str) -> list[int]:
    """The ID of each attempt, from its first line."""
    return [int(found) for found in DOMAIN_LINE.findall(stdout)]


def root_of(path: Path) -> etree._Element:
    return etree.parse(str(path)).getroot()


def properties_of(path: Path) -> dict[str, str]:
    """The properties of the result file at ``path`` (every attempt's, as written)."""
    return xunit.properties_of(root_of(path))


def valid(path: Path) -> etree._Element:
    """The canonical file's root, valid against our schema and junit-10's rules."""
    root = root_of(path)
    schema = junit_schema()
    assert schema.validate(root), schema.error_log
    assert jenkins_junit10.rejections(root) == []
    return root


def text_of(element: etree._Element | None) -> str:
    """An element's text, its children's (a stackTrace) included."""
    assert element is not None
    return "".join(str(part) for part in element.itertext())


def flaky_pass_on_record(path: Path, ids: list[int]) -> None:
    """The flaky case has one flakyFailure (attempt 1) and no failure; both IDs noted."""
    root = valid(path)
    (case,) = root.iter("testcase")
    assert case.find("failure") is None and case.find("error") is None
    (flaky,) = case.findall("flakyFailure")
    assert f"failed on {ids[0]}" in text_of(flaky), etree.tostring(flaky)
    properties = properties_of(path)
    assert properties["attempts"] == "2", properties
    assert properties["ros_domain_ids"] == f"{ids[0]}, {ids[1]}", properties
    assert properties["ros_domain_id"] == str(ids[1]), properties
    assert root.find("testsuite").get("failures") == "0"  # type: ignore[union-attr]


def report_names_it_flaky(path: Path, env: dict[str, str]) -> None:
    shown = run_cli(["report", str(path)], env)
    assert shown.returncode == 0, shown.stdout + shown.stderr
    assert "Flaky: 1 case(s) passed after failing" in shown.stdout, shown.stdout
    as_json = run_cli(["report", "--json", str(path)], env)
    (row,) = json.loads(as_json.stdout)["files"]
    assert row["failures"] == 0 and len(row["flaky_cases"]) == 1, row

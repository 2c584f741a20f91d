"""pytest sessions as real processes, in a project of their own, for the plugin's tests.

Every test of the pytest plugin (tests/unit/pytest_plugin/) writes a project (a
``pytest.ini`` that keeps this repository's config out, one test file, a ``package.xml``
when it is a ROS package), runs the installed plugin on it with this
suite's own interpreter, and reads what the test recorded and what the plugin said.
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path

from helpers.commands import HUNG, start_cli, start_process
from helpers.processes import wait_for

PYTEST = (sys.executable, "-m", "pytest", "-p", "no:cacheprovider")
#: The plugin off, as a user turns it off.
OFF = ("-p", "no:ros_isolated_test")
#: pytest's exit when the plugin got no ID (docs/reference.md): sysexits' EX_TEMPFAIL, none
#: of pytest's own codes (0 to 5: 3 is its internal error) nor the runner's.
NO_ID_EXIT = 75
#: The least package.xml that makes a folder a ROS package.
PACKAGE_XML = "<package format='3'><name>pkg</name></package>\n"
#: Where RECORDING_TEST writes (the ``plain_env`` of the tests names it).
RECORD_VAR = "PLUGIN_RECORD"

#: A test that records what it ran with: ROS_DOMAIN_ID and the discovery range.
RECORDING_TEST = """\
import json, os

def test_records():
    names = ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")
    record = {name: os.environ.get(name) for name in names}
    with open(os.environ["PLUGIN_RECORD"], "w") as out:
        json.dump(record, out)
"""

#: The next session's test: notes in $EVENTS that it ran, and on which ID (a release's order).
NEXT_TEST = """\
import os

def test_runs_next():
    with open(os.environ["EVENTS"], "a") as out:
        out.write(f"next test on {os.environ['ROS_DOMAIN_ID']}\\n")
"""


def run_in(
    cwd: Path, env: Mapping[str, str], argv: list[str], timeout: float = HUNG
) -> subprocess.CompletedProcess[str]:
    """``argv`` as a real process in ``cwd``, output captured as text."""
    return subprocess.run(
        argv, cwd=cwd, env=dict(env), capture_output=True, text=True, timeout=timeout, check=False
    )


def run_pytest(
    cwd: Path, env: Mapping[str, str], *args: str, timeout: float = HUNG
) -> subprocess.CompletedProcess[str]:
    return run_in(cwd, env, [*PYTEST, *args], timeout)


def start_pytest(
    cwd: Path,
    env: Mapping[str, str],
    log: Path,
    into: list[subprocess.Popen[bytes]],
    args: Sequence[str] = ("test",),
    **popen: object,
) -> subprocess.Popen[bytes]:
    """pytest ``args`` in the background, output into ``log``, kept in ``into`` (``started``).

    ``popen`` goes to Popen, e.g. ``start_new_session=True`` for a process group of its own.
    """
    return start_process([*PYTEST, *args], env, log, into, cwd=cwd, **popen)


def project(root: Path, test: str = RECORDING_TEST, package: bool = True) -> Path:
    """A folder with one test file (and a package.xml: a ROS package), its own pytest.ini."""
    root.mkdir(parents=True, exist_ok=True)
    (root / "pytest.ini").write_text("[pytest]\n")  # keep this repo's config out
    (root / "test").mkdir(exist_ok=True)
    (root / "test" / "test_it.py").write_text(test)
    if package:
        (root / "package.xml").write_text(PACKAGE_XML)
    return root


def recording_env(env: Mapping[str, str], tmp_path: Path) -> dict[str, str]:
    """The runner environment, RECORDING_TEST writing to ``tmp_path/record.json``."""
    return {**env, RECORD_VAR: str(tmp_path / "record.json")}


def without_resources(env: Mapping[str, str]) -> dict[str, str]:
    """``env`` without a resource request or capacity of this machine's own."""
    clean = dict(env)
    for name in ("ROS_ISOLATED_TEST_RESOURCES", "ROS_ISOLATED_TEST_CAPACITY"):
        clean.pop(name, None)
    return clean


def recorded(tmp_path: Path) -> dict[str, str | None]:
    found: dict[str, str | None] = json.loads((tmp_path / "record.json").read_text())
    return found


def header_lines(output: str) -> list[str]:
    return [line for line in output.splitlines() if line.startswith("ros-isolated-test:")]


def hold_the_one_id(
    tmp_path: Path, env: Mapping[str, str], started: list[subprocess.Popen[bytes]]
) -> subprocess.Popen[bytes]:
    """A runner holding the pool's only ID until terminated."""
    ready = tmp_path / "holder-ready"
    hold = "import pathlib, sys, time; pathlib.Path(sys.argv[1]).touch(); time.sleep(300)"
    holder = start_cli(
        ["run", "--", sys.executable, "-c", hold, str(ready)], env, tmp_path / "holder.log", started
    )
    wait_for(ready)
    return holder

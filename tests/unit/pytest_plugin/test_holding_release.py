"""``holding``'s release: what the tests left running is ended before the ID goes.

The runner's order, in a pytest session: a daemon a test left behind is ended, then the
ID (or, isolation disabled, the resources) is released, so the next session gets it only
then (the order of events, never a time). The same order after a signal is
test_interrupts.py's.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
from helpers.commands import HUNG
from helpers.processes import poll_until, wait_for
from helpers.pytest_sessions import NEXT_TEST, project, start_pytest

#: Leaves a double-forked daemon behind that notes its end in EVENTS, then waits for GO.
LEAKING_TEST = """\
import os, pathlib, signal, sys, time

def test_leaks_a_daemon():
    events, pid_file, go = (os.environ[n] for n in ("EVENTS", "PID_FILE", "GO"))
    if os.fork() == 0:
        os.setsid()
        if os.fork() == 0:
            def ended(signum, frame):
                with open(events, "a") as out:
                    out.write("daemon ended\\n")
                os._exit(0)
            signal.signal(signal.SIGTERM, ended)
            pathlib.Path(pid_file).write_text(str(os.getpid()))
            time.sleep(120)
        os._exit(0)
    deadline = time.monotonic() + 120
    while not os.path.exists(go) and time.monotonic() < deadline:
        time.sleep(0.05)
"""


#: The next session's test with isolation disabled: notes that it ran (it has no ID).
NEXT_TEST_WITHOUT_ID = """\
import os

def test_runs_next():
    with open(os.environ["EVENTS"], "a") as out:
        out.write("next test\\n")
"""


@pytest.mark.parametrize("disabled", [False, True], ids=["id", "isolation-disabled-gpu"])
def test_a_leftover_daemon_is_ended_before_the_id_or_the_resources_are_released(
    tmp_path: Path,
    one_id: dict[str, str],
    started: list[subprocess.Popen[bytes]],
    disabled: bool,
) -> None:
    """Order of events: the daemon ends, then the next session gets the pool's one ID, or
    (isolation disabled) the one GPU both sessions ask for."""
    events, pid_file, go = tmp_path / "events", tmp_path / "daemon.pid", tmp_path / "go"
    shared = {**one_id, "EVENTS": str(events), "PID_FILE": str(pid_file), "GO": str(go)}
    domain = one_id["ROS_ISOLATED_TEST_DOMAINS"]
    leaking = project(tmp_path / "leaking", LEAKING_TEST)
    if disabled:
        shared.update(DISABLE_ROS_ISOLATION="1", ROS_ISOLATED_TEST_CAPACITY="gpu=1")
        following = project(tmp_path / "following", NEXT_TEST_WITHOUT_ID)
        for root in (leaking, following):
            (root / "pytest.ini").write_text("[pytest]\nros_isolated_test_resources = gpu=1\n")
        waiting, next_event = "waiting for gpu=1", "next test"
    else:
        following = project(tmp_path / "following", NEXT_TEST)
        waiting, next_event = "waiting for a free ROS_DOMAIN_ID", f"next test on {domain}"
    first = start_pytest(leaking, shared, tmp_path / "first.log", started)
    wait_for(pid_file)
    second = start_pytest(following, shared, tmp_path / "second.log", started)
    poll_until(
        lambda: waiting in (tmp_path / "second.log").read_text(),
        f"the second session queued: {waiting}",
    )
    go.touch()
    assert first.wait(HUNG) == 0, (tmp_path / "first.log").read_text()
    assert second.wait(HUNG) == 0, (tmp_path / "second.log").read_text()
    assert events.read_text().splitlines() == ["daemon ended", next_event]
    daemon = int(pid_file.read_text())
    log = (tmp_path / "first.log").read_text()
    assert f"stopped process {daemon}" in log, log
    assert not Path(f"/proc/{daemon}").exists()

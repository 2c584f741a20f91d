"""A runner killed after its test wrote a passing file never leaves "passed" behind.

A gtest that deadlocks in shutdown after writing its XML, a launch test whose teardown
never returns: the test wrote "passed", then hangs, and ctest's TIMEOUT SIGKILLs the
runner's tree (or someone SIGKILLs the runner alone). The test writes its own file
beside the result path, and the runner adopts it only once the test has ended, so the
result path keeps the placeholder, which ``report`` counts as an error; a test whose
runner died alone is killed with it, so it never writes anything later. Three ways, as a
user meets them: ``run`` started with setsid and its whole group SIGKILLed; the RUNNER
under real ``colcon test`` of an ament_cmake package built with the zero-edit include,
with an ``ament_add_test(... TIMEOUT 5)``; and the runner alone SIGKILLed, its test told
to write its pass afterwards. The control: the same test, not killed, passes each way.
And what holds for the test's own child when the runner is killed alone: it lives on,
and its ID stays blocked until it has ended (docs/faults.md says where each part holds).
Every wait is for an event (the file the test writes, the orphan's exit), never a clock.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
from collections.abc import Mapping
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import CLI, HUNG, MODES, ament_args, run_cli, start_process, start_runner
from helpers.domains import free_ids
from helpers.orphans import wait_ended, watch
from helpers.processes import DEADLINE, poll_until, wait_for
from helpers.workspace import crosstalk_workspace
from helpers.xunit import properties_of
from lxml import etree

from ros_isolated_test.xunit.result_file import IN_PLACE_PROPERTY

PASSING = (
    '<testsuite name="t" tests="1" failures="0" errors="0">'
    '<testcase classname="t" name="ok" time="0.1"/></testsuite>'
)
#: The test (argv: its result file, a state folder): says its PID, waits for ``go``, writes
#: a passing result, says so (``wrote``), then hangs if ``hang`` is there, else exits 0.
PASS_THEN_HANG = f"""#!/bin/bash
echo $$ > "$2/pid"
while [ ! -e "$2/go" ]; do sleep 0.05; done
echo '{PASSING}' > "$1"
: > "$2/wrote"
if [ -e "$2/hang" ]; then exec sleep 600; fi
exit 0
"""


def _script(folder: Path) -> Path:
    script = folder / "pass_then_hang.sh"
    script.write_text(PASS_THEN_HANG)
    script.chmod(0o755)
    return script


def _state(folder: Path, *files: str) -> Path:
    state = folder / "state"
    state.mkdir()
    for name in files:
        (state / name).touch()
    return state


def _reported(result: Path, env: Mapping[str, str]) -> tuple[int, dict[str, int]]:
    """``report``'s exit code for ``result`` and its totals, as a user or CI reads them."""
    shown = run_cli(["report", str(result)], env)
    totals = json.loads(run_cli(["report", "--json", str(result)], env).stdout)["total"]
    return shown.returncode, totals


def _fails(result: Path, env: Mapping[str, str]) -> None:
    """``report`` fails the file, and the file itself counts an error or a failure."""
    code, totals = _reported(result, env)
    assert code != 0 and totals["failures"] + totals["errors"] >= 1, (totals, result.read_text())
    text = result.read_text()
    assert "the runner was killed before the test ended" in text, text
    assert 'errors="1"' in text or 'failures="1"' in text, text


def _passes(result: Path, env: Mapping[str, str]) -> None:
    code, totals = _reported(result, env)
    assert code == 0 and totals["failures"] + totals["errors"] == 0, (totals, result.read_text())
    assert totals["tests"] == 1, totals


def _run(folder: Path, result: Path, state: Path) -> list[str]:
    return [CLI, "run", "--junit-xml", str(result), "--package-name", "pkg", "--",
            str(_script(folder)), str(result), str(state)]  # fmt: skip


# --- run, its whole group SIGKILLed ------------------------------------------------------


def test_run_with_its_group_killed_after_the_test_wrote_a_pass_fails(
    env: dict[str, str], tmp_path: Path, started: list[subprocess.Popen[bytes]]
) -> None:
    result = tmp_path / "r.xml"
    state = _state(tmp_path, "go", "hang")
    log = tmp_path / "log"
    runner = start_process(_run(tmp_path, result, state), env, log, started,
                           start_new_session=True)  # fmt: skip
    wait_for(state / "wrote")  # the passing file is written; the test now hangs
    os.killpg(runner.pid, signal.SIGKILL)
    assert runner.wait(timeout=DEADLINE) == -signal.SIGKILL, log.read_text()
    _fails(result, env)
    # What the test wrote is beside the result path, under a name no *.xml glob reads.
    beside = result.with_name("r.xml.attempt1.orig")
    assert 'name="ok"' in beside.read_text()
    assert sorted(path.name for path in tmp_path.glob("*.xml")) == ["r.xml"]


# --- run, the runner alone SIGKILLed ------------------------------------------------------


def test_a_test_whose_runner_is_killed_alone_is_ended_and_never_writes_its_pass(
    env: dict[str, str], tmp_path: Path, started: list[subprocess.Popen[bytes]]
) -> None:
    """The orphan would write "passed" later (told to once its runner is dead): it is
    ended with its runner, so it never does, and the result path keeps the placeholder."""
    result = tmp_path / "r.xml"
    state = _state(tmp_path)
    log = tmp_path / "log"
    runner = start_process(_run(tmp_path, result, state), env, log, started)
    poll_until(lambda: (state / "pid").is_file() and (state / "pid").read_text().strip() != "",
               "the test started")  # fmt: skip
    pid = int((state / "pid").read_text())
    pidfd = watch(pid)
    runner.kill()
    assert runner.wait(timeout=DEADLINE) == -signal.SIGKILL, log.read_text()
    (state / "go").touch()  # a test that outlived its runner now writes its pass
    wait_ended(pidfd, pid, "the test of a runner killed alone")
    assert not (state / "wrote").exists(), "the orphan ran on after its runner died"
    _fails(result, env)


def test_control_the_same_test_not_killed_passes_through_run(
    env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "r.xml"
    state = _state(tmp_path, "go")
    done = subprocess.run(_run(tmp_path, result, state), env=env, capture_output=True,
                          text=True, timeout=DEADLINE, check=False)  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    _passes(result, env)
    assert 'name="ok"' in result.with_name("r.xml.orig").read_text()
    assert not result.with_name("r.xml.attempt1.orig").exists()
    assert IN_PLACE_PROPERTY not in properties_of(etree.parse(str(result)).getroot())


def test_a_command_that_finds_its_result_path_itself_is_said_to_write_it_in_place(
    env: dict[str, str], tmp_path: Path
) -> None:
    """No argument names the result path: the runner cannot point it beside, and says so."""
    result = tmp_path / "r.xml"
    write = f"echo '{PASSING}' > \"$1/r.xml\""
    done = run_cli(["run", "--junit-xml", str(result), "--", "sh", "-c", write, "t",
                    str(tmp_path)], env)  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    _passes(result, env)
    said = properties_of(etree.parse(str(result)).getroot())[IN_PLACE_PROPERTY]
    assert "so the test wrote it itself" in said, said
    assert f"result file {result}: {said} (see docs/faults.md)" in done.stdout, done.stdout


# --- the RUNNER under colcon test, ctest's TIMEOUT -----------------------------------------

MANIFEST = """<?xml version="1.0"?>
<package format="3">
  <name>killed_pkg</name>
  <version>0.0.0</version>
  <description>A test that writes a pass, then hangs.</description>
  <maintainer email="dev@example.com">dev</maintainer>
  <license>Apache-2.0</license>
  <buildtool_depend>ament_cmake</buildtool_depend>
  <export><build_type>ament_cmake</build_type></export>
</package>
"""

#: Two tests of the same script, on state folders of their own: one hangs (ctest's
#: TIMEOUT 5 kills it), one exits (the control).
CMAKE_LISTS = """cmake_minimum_required(VERSION 3.15)
project(killed_pkg NONE)
find_package(ament_cmake REQUIRED)
if(BUILD_TESTING)
  foreach(name hangs exits)
    set(result "${AMENT_TEST_RESULTS_DIR}/${PROJECT_NAME}/${name}.xml")
    ament_add_test(${name} COMMAND "${CMAKE_CURRENT_SOURCE_DIR}/pass_then_hang.sh"
      "${result}" "${STATE_ROOT}/${name}" TIMEOUT 5)
  endforeach()
endif()
ament_package()
"""


@capabilities.COLCON.mark
@capabilities.CTEST.mark
@pytest.mark.colcon
def test_colcon_test_timeout_after_the_test_wrote_a_pass_fails_and_its_control_passes(
    tmp_path: Path, env: dict[str, str]
) -> None:
    package = tmp_path / "src" / "killed_pkg"
    package.mkdir(parents=True)
    (package / "package.xml").write_text(MANIFEST)
    (package / "CMakeLists.txt").write_text(CMAKE_LISTS)
    _script(package)
    states = tmp_path / "states"
    for name, files in (("hangs", ("go", "hang")), ("exits", ("go",))):
        (states / name).mkdir(parents=True)
        for file in files:
            (states / name / file).touch()
    pool = ",".join(map(str, free_ids(2)))
    ws = crosstalk_workspace()
    base = {**env, "ROS_ISOLATED_TEST_DOMAINS": pool}
    colcon_env = {**ws.colcon_env(ws.Toolchain(base_env=base)), "COLCON_HOME": str(tmp_path / "ch")}
    colcon_env.pop("COLCON_DEFAULTS_FILE", None)
    recipe = (
        "colcon build --cmake-args -DCMAKE_PROJECT_INCLUDE=$(ros-isolated-test cmake-include)"
        f" -DSTATE_ROOT={states} && colcon test --ctest-args -j2"
    )
    done = subprocess.run(["bash", "-c", recipe], cwd=tmp_path, env=colcon_env,
                          capture_output=True, text=True, timeout=600, check=False)  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    results = tmp_path / "build" / "killed_pkg" / "test_results" / "killed_pkg"
    assert (states / "hangs" / "wrote").exists(), "the test never wrote its pass"
    _fails(results / "hangs.xml", env)
    _passes(results / "exits.xml", env)


# --- the test's own child, when its runner is killed alone --------------------------------

#: The test (argv: a state folder): starts a child that ignores SIGTERM and SIGHUP (it says
#: its PID, then execs a long sleep that keeps both ignored) and waits until ``done``.
STUBBORN_CHILD = """#!/bin/sh
sh -c 'trap "" TERM HUP; echo $$ > "$0/child.new"; mv "$0/child.new" "$0/child"; \
exec sleep 3600' "$1" &
while [ ! -e "$1/done" ]; do sleep 0.05; done
exit 0
"""


def _stubborn(folder: Path) -> list[str]:
    script = folder / "stubborn_child.sh"
    script.write_text(STUBBORN_CHILD)
    script.chmod(0o755)
    state = folder / "state"
    state.mkdir()
    return [str(script), str(state)]


def _rows_of(domain_id: int, env: Mapping[str, str]) -> dict[int, str]:
    """``status --json``'s rows for ``domain_id``: how each PID holds it."""
    rows = json.loads(run_cli(["status", "--json"], env).stdout)
    return {row["pid"]: row["via"] for row in rows if row["domain_id"] == domain_id}


@pytest.mark.parametrize("killed", ["killed alone", "control: not killed"])
@pytest.mark.parametrize("mode", MODES)
def test_the_own_child_of_a_test_whose_runner_is_killed_alone_holds_its_id_till_it_ends(
    mode: str,
    killed: str,
    env: dict[str, str],
    runner_script: str,
    tmp_path: Path,
    started: list[subprocess.Popen[bytes]],
) -> None:
    """What holds where (docs/faults.md): the runner SIGKILLed alone takes its test with it
    (``PR_SET_PDEATHSIG``), but not the test's own child, which lives on under the next
    subreaper; its ID stays blocked while it lives (``status``: a squatter, then a survivor
    once a reservation has looked) and is free once it has ended. The control: a runner not
    killed sweeps the same child (SIGTERM ignored, then SIGKILL) before it releases the ID.
    """
    (domain_id,) = free_ids(1)
    env["ROS_ISOLATED_TEST_DOMAINS"] = str(domain_id)
    command = _stubborn(tmp_path)
    state = Path(command[1])
    result, log = tmp_path / "pkg" / "t.xml", tmp_path / "runner.log"
    if mode == "shell":
        runner = start_process([CLI, "run", "--kill-grace", "0.2", "--junit-xml", str(result),
                                "--", *command], env, log, started)  # fmt: skip
    else:
        # The sweep's grace is the RUNNER's default, 5 s.
        args = ament_args(result, command, "--generate-result-on-success")
        runner = start_runner(runner_script, args, env, log, started)
    wait_for(state / "child")
    child = int((state / "child").read_text())
    pidfd = watch(child)
    try_id = ["run", "--wait-timeout", "0", "--", "true"]
    if killed == "killed alone":
        runner.kill()
        assert runner.wait(timeout=DEADLINE) == -signal.SIGKILL, log.read_text()
        os.kill(child, 0)  # the test's own child lives on, TERM and HUP ignored
        assert _rows_of(domain_id, env).get(child) == "environment"  # a squatter
        refused = run_cli(try_id, env)
        assert refused.returncode == 3, refused.stdout + refused.stderr
        assert _rows_of(domain_id, env).get(child) == "survivor"  # written down by that look
        os.kill(child, signal.SIGKILL)  # what ends it: nothing of the runner's
    else:
        (state / "done").touch()
        assert runner.wait(timeout=HUNG) == 0, log.read_text()
        assert f"stopped process {child} (sleep)" in log.read_text()
    wait_ended(pidfd, child, "the test's own child")
    free = run_cli(["run", "--wait-timeout", str(HUNG), "--", "true"], env)
    assert free.returncode == 0, free.stdout + free.stderr
    assert f"ROS_DOMAIN_ID {domain_id} " in free.stdout, free.stdout

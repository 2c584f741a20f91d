"""The pytest plugin: each pytest session (each xdist worker) on a domain ID of its own.

Real pytest processes with the installed plugin (entry point ``ros_isolated_test``), real
colcon over the ament_python packages of examples/python_tokens (built once per session),
real rclpy token exchanges that fail on crosstalk, and a control for each: the same run
with ``-p no:ros_isolated_test`` fails.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
import uuid
from collections.abc import Iterator, Mapping
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import CLI, HUNG, POLICY_VARS, REPO, start_cli
from helpers.processes import carrying, poll_until, wait_for
from helpers.workspace import crosstalk_workspace

EXAMPLES = REPO / "examples" / "python_tokens"
ONE_TEST = ("python_tokens_dahlia", "python_tokens_ember", "python_tokens_fennel")
OFF = ("-p", "no:ros_isolated_test")

#: A test that records what it ran with: ROS_DOMAIN_ID and the discovery range.
RECORDING_TEST = """\
import json, os

def test_records():
    names = ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")
    record = {name: os.environ.get(name) for name in names}
    with open(os.environ["PLUGIN_RECORD"], "w") as out:
        json.dump(record, out)
"""


@pytest.fixture(scope="session")
def token_workspace(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """examples/python_tokens built once with colcon: install/ holds the python_tokens module."""
    capabilities.require(capabilities.RCLPY, capabilities.COLCON)
    root = tmp_path_factory.mktemp("python-tokens")
    shutil.copytree(EXAMPLES, root / "src", ignore=shutil.ignore_patterns("__pycache__"))
    build = subprocess.run(
        ["colcon", "build", "--event-handlers", "console_direct-"],
        cwd=root,
        env=crosstalk_workspace().colcon_env(),
        capture_output=True,
        text=True,
        timeout=HUNG * 3,
        check=False,
    )
    assert build.returncode == 0, build.stdout + build.stderr
    return root


@pytest.fixture
def ros_env(env: dict[str, str], tmp_path: Path) -> dict[str, str]:
    """colcon's environment, our own lock dir, records in tmp_path/records."""
    clean = {
        key: value
        for key, value in crosstalk_workspace().colcon_env().items()
        if key not in POLICY_VARS
    }
    clean["ROS_ISOLATED_TEST_LOCK_DIR"] = env["ROS_ISOLATED_TEST_LOCK_DIR"]
    clean["CROSSTALK_RECORD_DIR"] = str(tmp_path / "records")
    return clean


def records(tmp_path: Path) -> dict[str, dict[str, object]]:
    folder = tmp_path / "records"
    found = {path.stem: json.loads(path.read_text()) for path in folder.glob("*.json")}
    return found


def colcon_test(root: Path, env: Mapping[str, str], *extra: str) -> str:
    """``colcon test`` of the three one-test packages, three at once; colcon's summary."""
    subprocess.run(
        ["colcon", "test", "--packages-select", *ONE_TEST, "--parallel-workers", "3", *extra],
        cwd=root,
        env=dict(env),
        capture_output=True,
        timeout=HUNG * 2,
        check=False,
    )
    summary = subprocess.run(
        ["colcon", "test-result", "--all"],
        cwd=root,
        env=dict(env),
        capture_output=True,
        text=True,
        timeout=HUNG,
        check=False,
    )
    return summary.stdout


def clear_results(root: Path) -> None:
    for name in ONE_TEST:
        (root / "build" / name / "pytest.xml").unlink(missing_ok=True)


@pytest.mark.ros
@pytest.mark.colcon
def test_colcon_runs_three_ament_python_packages_on_three_ids(
    token_workspace: Path, ros_env: dict[str, str], tmp_path: Path
) -> None:
    clear_results(token_workspace)
    summary = colcon_test(token_workspace, ros_env)
    assert "Summary: 3 tests, 0 errors, 0 failures, 0 skipped" in summary, summary
    found = records(tmp_path)
    assert sorted(found) == ["dahlia", "ember", "fennel"]
    ids = {str(record["domain_id"]) for record in found.values()}
    assert len(ids) == 3 and "None" not in ids, found
    # colcon's own result file (pytest's --junit-xml) names the ID as a suite property.
    for token in found:
        xml = (token_workspace / "build" / f"python_tokens_{token}" / "pytest.xml").read_text()
        assert f'<property name="ros_domain_id" value="{found[token]["domain_id"]}"' in xml


@pytest.mark.ros
@pytest.mark.colcon
def test_colcon_without_the_plugin_hears_crosstalk(
    token_workspace: Path, ros_env: dict[str, str], tmp_path: Path
) -> None:
    """The control: the same packages, the plugin off, share domain 0 and fail."""
    clear_results(token_workspace)
    summary = colcon_test(token_workspace, ros_env, "--pytest-args", *OFF)
    assert "Summary: 3 tests, 0 errors, 3 failures, 0 skipped" in summary, summary
    found = records(tmp_path)
    assert all(record["domain_id"] is None and record["foreign"] for record in found.values())


PYTEST = (sys.executable, "-m", "pytest", "-p", "no:cacheprovider")


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


def xdist_env(root: Path, ros_env: dict[str, str]) -> dict[str, str]:
    package = root / "src" / "python_tokens"
    return {**ros_env, "PYTHONPATH": f"{package}{os.pathsep}{ros_env.get('PYTHONPATH', '')}"}


@pytest.mark.ros
def test_xdist_gives_each_worker_its_own_id(
    token_workspace: Path, ros_env: dict[str, str], tmp_path: Path
) -> None:
    package = token_workspace / "src" / "python_tokens"
    junit = tmp_path / "xdist.xml"
    done = run_pytest(
        package, xdist_env(token_workspace, ros_env), "-n", "3", "test", f"--junit-xml={junit}"
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "ros-isolated-test: each xdist worker reserves a ROS_DOMAIN_ID" in done.stdout
    found = records(tmp_path)
    assert sorted(found) == ["amber", "birch", "cobalt"]
    ids = {str(record["domain_id"]) for record in found.values()}
    assert len(ids) == 3 and "None" not in ids, found
    xml = junit.read_text()
    for domain_id in ids:  # the controller's file names every worker's ID
        assert f'value="{domain_id}"' in xml


@pytest.mark.ros
def test_xdist_without_the_plugin_hears_crosstalk(
    token_workspace: Path, ros_env: dict[str, str], tmp_path: Path
) -> None:
    package = token_workspace / "src" / "python_tokens"
    done = run_pytest(package, xdist_env(token_workspace, ros_env), "-n", "3", "test", *OFF)
    assert done.returncode == 1, done.stdout + done.stderr
    found = records(tmp_path)
    assert sorted(found) == ["amber", "birch", "cobalt"]
    assert all(record["domain_id"] is None and record["foreign"] for record in found.values())


def project(root: Path, test: str = RECORDING_TEST, package: bool = True) -> Path:
    """A folder with one test file (and a package.xml: a ROS package), its own pytest.ini."""
    root.mkdir(parents=True, exist_ok=True)
    (root / "pytest.ini").write_text("[pytest]\n")  # keep this repo's config out
    (root / "test").mkdir(exist_ok=True)
    (root / "test" / "test_it.py").write_text(test)
    if package:
        (root / "package.xml").write_text("<package format='3'><name>pkg</name></package>\n")
    return root


@pytest.fixture
def plain_env(env: dict[str, str], tmp_path: Path) -> dict[str, str]:
    return {**env, "PLUGIN_RECORD": str(tmp_path / "record.json")}


def recorded(tmp_path: Path) -> dict[str, str | None]:
    found: dict[str, str | None] = json.loads((tmp_path / "record.json").read_text())
    return found


def header_lines(output: str) -> list[str]:
    return [line for line in output.splitlines() if line.startswith("ros-isolated-test:")]


@pytest.mark.parametrize(
    ("package", "args", "isolated"),
    [
        (True, (), True),  # inside a ROS package: on by itself
        (False, (), False),  # elsewhere: off
        (False, ("--ros-isolation",), True),
        (False, ("-o", "ros_isolation=true"), True),
        (True, ("--no-ros-isolation",), False),
        (True, ("-o", "ros_isolation=false"), False),
        (True, OFF, False),
        # The ini option's other words, read as every on/off switch reads them; auto and
        # blank leave it to the package.
        (False, ("-o", "ros_isolation= Yes "), True),
        (True, ("-o", "ros_isolation=0"), False),
        (True, ("-o", "ros_isolation=AUTO"), True),
        (True, ("-o", "ros_isolation="), True),
        (False, ("-o", "ros_isolation=auto"), False),
    ],
)
def test_activation(
    tmp_path: Path,
    plain_env: dict[str, str],
    package: bool,
    args: tuple[str, ...],
    isolated: bool,
) -> None:
    root = project(tmp_path / "pkg", package=package)
    done = run_pytest(root, plain_env, *args, "test")
    assert done.returncode == 0, done.stdout + done.stderr
    seen = recorded(tmp_path)
    if isolated:
        domain = seen["ROS_DOMAIN_ID"]
        assert domain is not None and int(domain) > 0
        assert seen["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
        assert header_lines(done.stdout)[0].startswith(
            f"ros-isolated-test: ROS_DOMAIN_ID {domain},"
        )
    else:
        assert seen == {"ROS_DOMAIN_ID": None, "ROS_AUTOMATIC_DISCOVERY_RANGE": None}
        assert header_lines(done.stdout) == []


def test_an_ini_word_neither_on_nor_off_is_a_usage_error(
    tmp_path: Path, plain_env: dict[str, str]
) -> None:
    root = project(tmp_path / "pkg")
    done = run_pytest(root, plain_env, "-o", "ros_isolation=maybe", "test")
    assert done.returncode == 4, done.stdout + done.stderr  # pytest's usage error
    assert "ini option ros_isolation='maybe': use auto, true or false" in done.stderr, done.stderr
    assert not (tmp_path / "record.json").exists()  # nothing ran


def test_a_bad_rerun_variable_does_not_concern_the_plugin(
    tmp_path: Path, plain_env: dict[str, str]
) -> None:
    """ROS_ISOLATED_TEST_RERUNS is `run`'s: the plugin never reruns, so never reads it."""
    root = project(tmp_path / "pkg")
    done = run_pytest(root, {**plain_env, "ROS_ISOLATED_TEST_RERUNS": "two"}, "test")
    assert done.returncode == 0, done.stdout + done.stderr
    domain = recorded(tmp_path)["ROS_DOMAIN_ID"]
    assert domain is not None and int(domain) > 0  # isolated, as without the variable
    # The control: a bad variable the plugin does use still stops the session.
    bad = {**plain_env, "ROS_ISOLATED_TEST_WAIT_TIMEOUT": "ten"}
    refused = run_pytest(root, bad, "test")
    assert refused.returncode == pytest.ExitCode.USAGE_ERROR, refused.stdout + refused.stderr
    assert "ROS_ISOLATED_TEST_WAIT_TIMEOUT='ten'" in refused.stderr, refused.stderr


def test_explicit_isolation_refuses_a_preset_id(tmp_path: Path, plain_env: dict[str, str]) -> None:
    root = project(tmp_path / "pkg")
    done = run_pytest(root, {**plain_env, "ROS_DOMAIN_ID": "5"}, "--ros-isolation", "test")
    assert done.returncode == pytest.ExitCode.USAGE_ERROR, done.stdout + done.stderr
    assert "refusing to run: ROS_DOMAIN_ID is already set to '5'" in done.stderr
    assert "DISABLE_ROS_ISOLATION=1" in done.stderr
    assert not (tmp_path / "record.json").exists()


def test_automatic_isolation_keeps_a_preset_id_and_says_so(
    tmp_path: Path, plain_env: dict[str, str]
) -> None:
    root = project(tmp_path / "pkg")
    done = run_pytest(root, {**plain_env, "ROS_DOMAIN_ID": "5"}, "test")
    assert done.returncode == 0, done.stdout + done.stderr
    assert recorded(tmp_path)["ROS_DOMAIN_ID"] == "5"
    (line,) = header_lines(done.stdout)
    assert "ROS_DOMAIN_ID is already set to '5'" in line and "NOT isolated" in line


def test_disable_ros_isolation_runs_without_an_id(
    tmp_path: Path, plain_env: dict[str, str]
) -> None:
    root = project(tmp_path / "pkg")
    env = {**plain_env, "DISABLE_ROS_ISOLATION": "1", "ROS_DOMAIN_ID": "5"}
    done = run_pytest(root, env, "--ros-isolation", "test")
    assert done.returncode == 0, done.stdout + done.stderr
    assert recorded(tmp_path) == {"ROS_DOMAIN_ID": "5", "ROS_AUTOMATIC_DISCOVERY_RANGE": None}
    (line,) = header_lines(done.stdout)
    assert "WARNING: DISABLE_ROS_ISOLATION is set: running WITHOUT isolation" in line


def test_under_the_runner_it_uses_the_runners_id(
    tmp_path: Path, plain_env: dict[str, str], one_id: dict[str, str]
) -> None:
    """Nested: the runner holds the pool's only ID; the plugin takes none (or it would wait)."""
    root = project(tmp_path / "pkg")
    env = {**plain_env, **one_id, "ROS_ISOLATED_TEST_WAIT_TIMEOUT": "0"}
    done = run_in(root, env, [CLI, "run", "--", *PYTEST, "--ros-isolation", "test"])
    assert done.returncode == 0, done.stdout + done.stderr
    domain = one_id["ROS_ISOLATED_TEST_DOMAINS"]
    assert done.stdout.startswith(f"Running with ROS_DOMAIN_ID {domain} (Gazebo partition ")
    assert recorded(tmp_path)["ROS_DOMAIN_ID"] == domain
    assert f"ros-isolated-test: ROS_DOMAIN_ID {domain}, held by the runner" in done.stdout


def test_a_mark_for_another_id_is_no_runner(tmp_path: Path, plain_env: dict[str, str]) -> None:
    """The control for nesting: only the runner's mark naming that very ID counts."""
    root = project(tmp_path / "pkg")
    env = {**plain_env, "ROS_DOMAIN_ID": "5", "ROS_ISOLATED_TEST_HELD_DOMAIN_ID": "6"}
    done = run_pytest(root, env, "--ros-isolation", "test")
    assert done.returncode == pytest.ExitCode.USAGE_ERROR, done.stdout + done.stderr
    assert "refusing to run" in done.stderr


def test_pool_exhausted_waits_then_fails(
    tmp_path: Path,
    plain_env: dict[str, str],
    one_id: dict[str, str],
    started: list[subprocess.Popen[bytes]],
) -> None:
    root = project(tmp_path / "pkg")
    env = {**plain_env, **one_id, "ROS_ISOLATED_TEST_WAIT_TIMEOUT": "1"}
    ready = tmp_path / "holder-ready"
    hold = "import pathlib, sys, time; pathlib.Path(sys.argv[1]).touch(); time.sleep(300)"
    holder = start_cli(
        ["run", "--", sys.executable, "-c", hold, str(ready)], env, tmp_path / "holder.log", started
    )
    wait_for(ready)
    done = run_pytest(root, env, "test")
    assert done.returncode == 3, done.stdout + done.stderr
    assert "waiting for a free ROS_DOMAIN_ID" in done.stderr
    assert "after waiting 1 s, no free ROS_DOMAIN_ID" in done.stderr
    assert not (tmp_path / "record.json").exists()
    holder.terminate()  # the runner ends its test, then releases the ID
    holder.wait(HUNG)
    again = run_pytest(root, env, "test")  # the control: the ID free, the same run passes
    assert again.returncode == 0, again.stdout + again.stderr
    assert recorded(tmp_path)["ROS_DOMAIN_ID"] == one_id["ROS_ISOLATED_TEST_DOMAINS"]


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

#: The next session's test: notes that it ran, and on which ID.
NEXT_TEST = """\
import os

def test_runs_next():
    with open(os.environ["EVENTS"], "a") as out:
        out.write(f"next test on {os.environ['ROS_DOMAIN_ID']}\\n")
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


def start_pytest(
    cwd: Path, env: Mapping[str, str], log: Path, into: list[subprocess.Popen[bytes]]
) -> subprocess.Popen[bytes]:
    with log.open("wb") as out:
        process = subprocess.Popen(
            [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "test"],
            cwd=cwd,
            env=dict(env),
            stdin=subprocess.DEVNULL,
            stdout=out,
            stderr=out,
        )
    into.append(process)
    return process


def test_inactive_plugin_imports_nothing_of_the_runner(tmp_path: Path, env: dict[str, str]) -> None:
    """Loaded by every pytest run: outside a ROS package it must cost nothing."""
    check = """\
import sys

def test_modules():
    heavy = ("lxml", "filelock", "ros_isolated_test.runner", "ros_isolated_test.domain_coordinator")
    assert "ros_isolated_test.pytest_plugin" in sys.modules
    loaded = [name for name in sys.modules if name.startswith(heavy)]
    assert loaded == [], loaded
"""
    root = project(tmp_path / "plain", check, package=False)
    done = run_pytest(root, env, "test")
    assert done.returncode == 0, done.stdout + done.stderr
    active = run_pytest(project(tmp_path / "ros", check), env, "test")  # the control
    assert active.returncode == 1, active.stdout
    assert "ros_isolated_test.runner" in active.stdout


@pytest.mark.parametrize("explicit", [False, True])
def test_xdist_controller_decides_on_a_preset_id(
    tmp_path: Path, plain_env: dict[str, str], explicit: bool
) -> None:
    """Said once by the controller: refused (explicit) or NOT isolated; never a crash loop."""
    root = project(tmp_path / "pkg")
    args = ("--ros-isolation",) if explicit else ()
    done = run_pytest(root, {**plain_env, "ROS_DOMAIN_ID": "5"}, "-n", "2", *args, "test")
    output = done.stdout + done.stderr
    assert "each xdist worker reserves" not in output
    assert "crashed" not in output
    if explicit:
        assert done.returncode == pytest.ExitCode.USAGE_ERROR, output
        assert "refusing to run: ROS_DOMAIN_ID is already set to '5'" in done.stderr
        assert not (tmp_path / "record.json").exists()
    else:
        assert done.returncode == 0, output
        (line,) = header_lines(done.stdout)
        assert "ROS_DOMAIN_ID is already set to '5'" in line and "NOT isolated" in line
        assert recorded(tmp_path)["ROS_DOMAIN_ID"] == "5"


def test_xdist_with_disable_ros_isolation_says_so(
    tmp_path: Path, plain_env: dict[str, str]
) -> None:
    root = project(tmp_path / "pkg")
    env = {**plain_env, "DISABLE_ROS_ISOLATION": "1"}
    done = run_pytest(root, env, "-n", "2", "test")
    assert done.returncode == 0, done.stdout + done.stderr
    (line,) = header_lines(done.stdout)
    assert "WARNING: DISABLE_ROS_ISOLATION is set: running WITHOUT isolation" in line
    assert recorded(tmp_path)["ROS_DOMAIN_ID"] is None


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


def test_xdist_pool_exhausted_exits_3_without_restarting_workers(
    tmp_path: Path,
    plain_env: dict[str, str],
    one_id: dict[str, str],
    started: list[subprocess.Popen[bytes]],
) -> None:
    root = project(tmp_path / "pkg")
    env = {**plain_env, **one_id, "ROS_ISOLATED_TEST_WAIT_TIMEOUT": "1"}
    holder = hold_the_one_id(tmp_path, env, started)
    done = run_pytest(root, env, "-n", "2", "test")
    output = done.stdout + done.stderr
    assert done.returncode == 3, output
    assert "ros-isolated-test: error: after waiting 1 s, no free ROS_DOMAIN_ID" in done.stderr
    assert "crashed" not in output and "restarting" not in output, output
    assert not (tmp_path / "record.json").exists()
    holder.terminate()
    holder.wait(HUNG)
    again = run_pytest(root, env, "-n", "1", "test")  # the control: the ID free, it passes
    assert again.returncode == 0, again.stdout + again.stderr


#: Two pytest sessions in one process (an embedding program).
TWICE = """\
import ctypes, json, os
import pytest

def subreaper():
    flag = ctypes.c_int(0)
    ctypes.CDLL(None).prctl(37, ctypes.byref(flag), 0, 0, 0)  # PR_GET_CHILD_SUBREAPER
    return flag.value

seen = []
for _ in range(2):
    code = pytest.main(["-p", "no:cacheprovider", "test"])
    seen.append([int(code), os.environ.get("ROS_DOMAIN_ID"),
                 os.environ.get("ROS_ISOLATED_TEST_HELD_DOMAIN_ID"), subreaper()])
print("SEEN " + json.dumps(seen))
"""


def test_os_environ_is_restored_after_the_session(
    tmp_path: Path, plain_env: dict[str, str], one_id: dict[str, str]
) -> None:
    """The second session reserves again: the first left nothing of its isolation behind."""
    root = project(tmp_path / "pkg")
    env = {**plain_env, **one_id, "ROS_ISOLATED_TEST_WAIT_TIMEOUT": "1"}
    done = run_in(root, env, [sys.executable, "-c", TWICE])
    assert done.returncode == 0, done.stdout + done.stderr
    (seen,) = (line for line in done.stdout.splitlines() if line.startswith("SEEN "))
    # No ID, no held mark, no subreaper left to the embedding program.
    assert json.loads(seen[5:]) == [[0, None, None, 0], [0, None, None, 0]]
    domain = one_id["ROS_ISOLATED_TEST_DOMAINS"]
    starts = f"ros-isolated-test: ROS_DOMAIN_ID {domain},"
    assert sum(line.startswith(starts) for line in header_lines(done.stdout)) == 2
    assert "held by the runner" not in done.stdout


@pytest.mark.parametrize("option", ["--help", "--markers", "--fixtures", "--collect-only"])
def test_options_that_run_no_test_reserve_nothing(
    tmp_path: Path,
    plain_env: dict[str, str],
    one_id: dict[str, str],
    started: list[subprocess.Popen[bytes]],
    option: str,
) -> None:
    """The pool's one ID held: they still answer at once (a reservation would fail: 3)."""
    root = project(tmp_path / "pkg")
    env = {**plain_env, **one_id, "ROS_ISOLATED_TEST_WAIT_TIMEOUT": "0"}
    hold_the_one_id(tmp_path, env, started)
    done = run_pytest(root, env, option, "test")
    assert done.returncode == 0, done.stdout + done.stderr
    assert "no free ROS_DOMAIN_ID" not in done.stderr
    control = run_pytest(root, env, "test")
    assert control.returncode == 3, control.stdout + control.stderr


#: Forks a child without exec (it inherits everything, the lock too) that ignores SIGTERM.
FORKING_TEST = """\
import os, pathlib, signal, time

def test_forks_and_waits():
    events, pid_file = os.environ["EVENTS"], os.environ["PID_FILE"]
    if os.fork() == 0:
        def noted(signum, frame):
            with open(events, "a") as out:
                out.write("child got SIGTERM\\n")
        signal.signal(signal.SIGTERM, noted)
        pathlib.Path(pid_file + ".new").write_text(str(os.getpid()))
        os.rename(pid_file + ".new", pid_file)  # whole, never seen empty
        while True:
            time.sleep(1)
    time.sleep(120)
"""


@pytest.mark.parametrize("signum", [15, 1])
def test_a_signal_ends_the_tests_leftovers_before_the_release(
    tmp_path: Path,
    env: dict[str, str],
    one_id: dict[str, str],
    started: list[subprocess.Popen[bytes]],
    signum: int,
) -> None:
    """SIGTERM or SIGHUP (ctest's timeout): the sweep runs, and a second one cannot cut it."""
    events, pid_file = tmp_path / "events", tmp_path / "child.pid"
    shared = {**one_id, "EVENTS": str(events), "PID_FILE": str(pid_file)}
    log = tmp_path / "pytest.log"
    session = start_pytest(project(tmp_path / "forking", FORKING_TEST), shared, log, started)
    wait_for(pid_file)
    child = int(pid_file.read_text())
    session.send_signal(signum)
    poll_until(
        lambda: session.poll() is not None or (events.exists() and bool(events.read_text())),
        "the sweep's SIGTERM reached the child, or pytest ended",
    )
    assert events.exists() and events.read_text() == "child got SIGTERM\n", log.read_text()
    session.send_signal(signum)  # during the grace: only noted
    assert session.wait(HUNG) == pytest.ExitCode.INTERRUPTED, log.read_text()
    assert not Path(f"/proc/{child}").exists()
    assert f"stopped process {child}" in log.read_text()
    # The ID is free at once: the next session gets it without waiting.
    following = project(tmp_path / "following", NEXT_TEST)
    after = run_pytest(following, {**shared, "ROS_ISOLATED_TEST_WAIT_TIMEOUT": "0"}, "test")
    assert after.returncode == 0, after.stdout + after.stderr


#: Two tests (one per xdist worker): each starts a long-lived child that ignores SIGINT (a
#: terminal's Ctrl-C reaches it too: only the sweep's SIGTERM ends it), names it in a file
#: named after its own process (the worker), then runs on until interrupted.
RUNNING_TEST = """\
import os, pathlib, subprocess, sys, time
import pytest

CHILD = "import signal, time; signal.signal(signal.SIGINT, signal.SIG_IGN); time.sleep(300)"

@pytest.mark.parametrize("n", range(2))
def test_runs_on(n):
    child = subprocess.Popen([sys.executable, "-c", CHILD])
    started = pathlib.Path(os.environ["STARTED"])
    (started / f"{os.getpid()}.new").write_text(str(child.pid))
    os.rename(started / f"{os.getpid()}.new", started / str(os.getpid()))  # whole, never empty
    time.sleep(300)
"""

#: Where a session's processes are found: in their environment, whatever their names.
MARK_VAR = "RIT_SESSION_MARK"


@pytest.fixture
def session_mark() -> Iterator[str]:
    """``RIT_SESSION_MARK=<uuid>`` for a session's environment; whatever still carries it
    when the test ends (it failed) is killed, so nothing of it outlives the test."""
    entry = f"{MARK_VAR}={uuid.uuid4().hex}"
    yield entry
    for pid in carrying(entry):
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)


def running_tests(folder: Path) -> dict[int, int]:
    """Each running test's process (an xdist worker) and its child, as their files say."""
    return {int(path.name): int(path.read_text()) for path in folder.glob("[0-9]*[0-9]")}


def held_rows(env: Mapping[str, str], cwd: Path) -> list[dict[str, object]]:
    """``status --json`` rows of the lock directory that hold an ID: a lock or a survivor."""
    listed = run_in(cwd, env, [CLI, "status", "--json"])
    assert listed.returncode == 0, listed.stderr
    rows: list[dict[str, object]] = json.loads(listed.stdout)
    return [row for row in rows if row["via"] in ("lock", "survivor")]


def start_running_tests(
    tmp_path: Path,
    env: Mapping[str, str],
    mark: str,
    workers: int,
    into: list[subprocess.Popen[bytes]],
) -> tuple[subprocess.Popen[bytes], Path, dict[int, int]]:
    """pytest (``-n workers``, 0: no xdist) on RUNNING_TEST in a ROS package, in a process
    group of its own, the environment marked; once every test runs: pytest, its log, and
    each test's process with its child."""
    started_dir = tmp_path / "started"
    started_dir.mkdir()
    name, value = mark.split("=", 1)
    session_env = {**env, "STARTED": str(started_dir), name: value}
    root = project(tmp_path / "pkg", RUNNING_TEST)
    log = tmp_path / "pytest.log"
    xdist = ("-n", str(workers)) if workers else ()
    with log.open("wb") as out:
        session = subprocess.Popen(
            [*PYTEST, *xdist, "test"], cwd=root, env=session_env, stdin=subprocess.DEVNULL,
            stdout=out, stderr=out, start_new_session=True,
        )  # fmt: skip
    into.append(session)
    expected = max(workers, 1)  # without xdist the tests run one after the other
    poll_until(
        lambda: len(running_tests(started_dir)) >= expected,
        f"{expected} test(s) running, each with its child",
    )
    children = running_tests(started_dir)
    # The control for the checks after: while the tests run, status shows each ID held by
    # the process that runs its test, and the children are found by the mark.
    assert {row["pid"] for row in held_rows(env, tmp_path)} == set(children)
    assert set(children.values()) <= set(carrying(mark))
    return session, log, children


@pytest.mark.parametrize(
    ("how", "workers"),
    [
        ("SIGTERM", 2),
        ("SIGHUP", 2),
        ("Ctrl-C", 2),  # the control: SIGINT to the whole process group, as a terminal sends it
        ("SIGTERM", 0),  # the control: the same signal without xdist
    ],
    ids=["sigterm-xdist", "sighup-xdist", "ctrl-c-xdist", "sigterm-no-xdist"],
)
def test_a_signal_to_the_xdist_controller_ends_the_workers_as_ctrl_c_does(
    tmp_path: Path,
    env: dict[str, str],
    started: list[subprocess.Popen[bytes]],
    session_mark: str,
    how: str,
    workers: int,
) -> None:
    """SIGTERM or SIGHUP to the controller alone: pytest exits 2, as without xdist, and only
    after every worker ended its test's child and released its ID: nothing of the session
    lives on, and status shows nothing held in the session's lock directory."""
    session, log, children = start_running_tests(tmp_path, env, session_mark, workers, started)
    if how == "Ctrl-C":
        os.killpg(session.pid, signal.SIGINT)
    else:
        session.send_signal(signal.Signals[how])
    code = session.wait(HUNG)
    output = log.read_text()
    assert code == pytest.ExitCode.INTERRUPTED, output
    # Nothing of the session lives once pytest has exited: workers, tests' children.
    assert carrying(session_mark) == [], output
    for child in children.values():
        assert f"stopped process {child}" in output, output  # ended by the sweep
    assert held_rows(env, tmp_path) == [], output


def test_xdist_workers_release_when_the_controller_is_killed(
    tmp_path: Path,
    env: dict[str, str],
    started: list[subprocess.Popen[bytes]],
    session_mark: str,
) -> None:
    """The controller gone (SIGKILL): execnet interrupts each worker (SIGINT), whose report
    to the controller then fails; the worker has ended its test's child and released its ID
    before, not in unconfigure, which pytest skips after that failure."""
    session, log, children = start_running_tests(tmp_path, env, session_mark, 2, started)
    session.kill()
    assert session.wait(HUNG) == -signal.SIGKILL
    poll_until(lambda: carrying(session_mark) == [], "every process of the session ended")
    output = log.read_text()
    for child in children.values():
        assert f"stopped process {child}" in output, output  # ended by the sweep
    assert held_rows(env, tmp_path) == [], output


#: Holds its session open until GO exists (so another runner can try the same resources).
HOLDING_TEST = """\
import os, pathlib, time

def test_holds_until_go():
    pathlib.Path(os.environ["READY"]).touch()
    deadline = time.monotonic() + 120
    while not os.path.exists(os.environ["GO"]) and time.monotonic() < deadline:
        time.sleep(0.05)
"""


@pytest.fixture
def resource_env(plain_env: dict[str, str]) -> dict[str, str]:
    """plain_env without a resource request or capacity of this machine's own."""
    clean = dict(plain_env)
    for name in ("ROS_ISOLATED_TEST_RESOURCES", "ROS_ISOLATED_TEST_CAPACITY"):
        clean.pop(name, None)
    return clean


def _lidar_runner(env: Mapping[str, str], cwd: Path) -> subprocess.CompletedProcess[str]:
    """Another runner asking for the one lidar, giving up after 1 s."""
    return run_in(
        cwd, env, [CLI, "run", "--resources", "lidar=1", "--wait-timeout", "1", "--", "true"]
    )


def test_the_session_holds_its_resources_until_pytest_ends(
    tmp_path: Path, resource_env: dict[str, str], started: list[subprocess.Popen[bytes]]
) -> None:
    """The ini option's request is held by the session: another runner asking for it gets
    nothing while the session lives (exit 3), and gets it once pytest ended (control)."""
    ready, go, junit = tmp_path / "ready", tmp_path / "go", tmp_path / "junit.xml"
    env = {**resource_env, "READY": str(ready), "GO": str(go)}
    root = project(tmp_path / "pkg", HOLDING_TEST)
    (root / "pytest.ini").write_text("[pytest]\nros_isolated_test_resources = lidar=1\n")
    log = tmp_path / "session.log"
    with log.open("wb") as out:
        session = subprocess.Popen(
            [*PYTEST, "test", f"--junit-xml={junit}"], cwd=root, env=env,
            stdin=subprocess.DEVNULL, stdout=out, stderr=out,
        )  # fmt: skip
    started.append(session)
    wait_for(ready)
    refused = _lidar_runner(env, tmp_path)
    assert refused.returncode == 3, refused.stdout + refused.stderr
    go.touch()
    assert session.wait(HUNG) == 0, log.read_text()
    assert "ros-isolated-test: holding lidar=1 of lidar=1" in log.read_text()
    assert '<property name="resources" value="lidar=1"' in junit.read_text()
    after = _lidar_runner(env, tmp_path)
    assert after.returncode == 0, after.stdout + after.stderr


@pytest.mark.parametrize("package", [True, False])
def test_the_option_wins_over_the_ini_and_turns_isolation_on(
    tmp_path: Path, resource_env: dict[str, str], package: bool
) -> None:
    """Outside a ROS package too: a request needs the plugin (without one it stays off)."""
    root = project(tmp_path / "pkg", package=package)
    # A bad ini value: never read when the option is given.
    (root / "pytest.ini").write_text("[pytest]\nros_isolated_test_resources = lidar\n")
    done = run_pytest(root, resource_env, "--ros-isolated-test-resources", "camera=1", "test")
    assert done.returncode == 0, done.stdout + done.stderr
    lines = header_lines(done.stdout)
    assert lines[1].startswith("ros-isolated-test: holding camera=1 of camera=1"), lines
    domain = recorded(tmp_path)["ROS_DOMAIN_ID"]
    assert domain is not None and lines[0].startswith(f"ros-isolated-test: ROS_DOMAIN_ID {domain},")


@pytest.mark.parametrize(
    ("args", "ini", "says"),
    [
        (("--ros-isolated-test-resources", "lidar"), "", "--ros-isolated-test-resources: 'lidar'"),
        ((), "lidar", "ini option ros_isolated_test_resources: 'lidar'"),
        ((), "lidar=2", "ini option ros_isolated_test_resources: lidar=2 is more than"),
        # The option is read, not the ini's (good) value.
        (
            ("--ros-isolated-test-resources", "lidar=0"),
            "lidar=1",
            "--ros-isolated-test-resources: lidar='0' is zero",
        ),
    ],
)
def test_a_bad_request_is_a_usage_error_naming_the_option(
    tmp_path: Path, resource_env: dict[str, str], args: tuple[str, ...], ini: str, says: str
) -> None:
    root = project(tmp_path / "pkg")
    (root / "pytest.ini").write_text(f"[pytest]\nros_isolated_test_resources = {ini}\n")
    done = run_pytest(root, resource_env, *args, "test")
    assert done.returncode == pytest.ExitCode.USAGE_ERROR, done.stdout + done.stderr
    assert f"ros-isolated-test: {says}" in done.stderr, done.stderr
    assert not (tmp_path / "record.json").exists()


@pytest.mark.parametrize("capacity", ["lidar=2", "lidar=1"])
def test_xdist_holds_the_resources_per_worker(
    tmp_path: Path, resource_env: dict[str, str], capacity: str
) -> None:
    """Two workers, lidar=1 each: they fit a capacity of 2; with 1, the second worker waits
    for the first, which holds it until pytest ends: no lidar in time, exit 3."""
    root = project(tmp_path / "pkg")
    env = {
        **resource_env,
        "ROS_ISOLATED_TEST_CAPACITY": capacity,
        "ROS_ISOLATED_TEST_WAIT_TIMEOUT": "2",
    }
    done = run_pytest(root, env, "-n", "2", "--ros-isolated-test-resources", "lidar=1", "test")
    output = done.stdout + done.stderr
    assert "ros-isolated-test: each xdist worker reserves a ROS_DOMAIN_ID and lidar=1" in output
    if capacity == "lidar=2":
        assert done.returncode == 0, output
    else:
        assert done.returncode == 3, output
        assert "crashed" not in output and "restarting" not in output, output


def test_under_the_runner_the_plugin_holds_no_resources(
    tmp_path: Path, resource_env: dict[str, str], one_id: dict[str, str]
) -> None:
    """The runner holds what it was asked; the plugin asking again could wait for itself."""
    root = project(tmp_path / "pkg")
    env = {**resource_env, **one_id, "ROS_ISOLATED_TEST_WAIT_TIMEOUT": "0"}
    argv = [CLI, "run", "--resources", "lidar=1", "--", *PYTEST]
    done = run_in(root, env, [*argv, "--ros-isolated-test-resources", "lidar=1", "test"])
    assert done.returncode == 0, done.stdout + done.stderr
    assert (
        "ros-isolated-test: --ros-isolated-test-resources (lidar=1) not held by the plugin"
        in done.stdout
    ), done.stdout


#: A test that records the Gazebo partition it ran with, its domain ID and its process.
PARTITION_TEST = """\
import json, os

def test_records():
    names = ("ROS_DOMAIN_ID", "GZ_PARTITION", "IGN_PARTITION")
    record = {name: os.environ.get(name) for name in names}
    record["pid"] = os.getpid()
    with open(os.environ["PLUGIN_RECORD"], "w") as out:
        json.dump(record, out)
"""


def test_the_session_gets_a_gazebo_partition_of_its_own(
    tmp_path: Path, plain_env: dict[str, str]
) -> None:
    """The name ``status`` shows for the session's holder record: host, ID, pytest's PID."""
    from ros_isolated_test.runner import partition

    root = project(tmp_path / "pkg", PARTITION_TEST)
    junit = tmp_path / "junit.xml"
    done = run_pytest(root, plain_env, "test", f"--junit-xml={junit}")
    assert done.returncode == 0, done.stdout + done.stderr
    seen = json.loads((tmp_path / "record.json").read_text())
    name = partition.name(os.uname().nodename, int(seen["ROS_DOMAIN_ID"]), seen["pid"])
    assert seen["GZ_PARTITION"] == seen["IGN_PARTITION"] == name
    assert f"ros-isolated-test: Gazebo transport partition {name} " in done.stdout
    assert f'name="gz_partition" value="{name}"' in junit.read_text()


@pytest.mark.parametrize("variable", ["GZ_PARTITION", "IGN_PARTITION"])
def test_explicit_isolation_refuses_a_preset_partition(
    tmp_path: Path, plain_env: dict[str, str], variable: str
) -> None:
    root = project(tmp_path / "pkg", PARTITION_TEST)
    done = run_pytest(root, {**plain_env, variable: "sim"}, "--ros-isolation", "test")
    assert done.returncode == pytest.ExitCode.USAGE_ERROR, done.stdout + done.stderr
    assert f"refusing to run: {variable} is already set to 'sim'" in done.stderr
    assert not (tmp_path / "record.json").exists()


def test_automatic_isolation_keeps_a_preset_partition_and_says_so(
    tmp_path: Path, plain_env: dict[str, str]
) -> None:
    root = project(tmp_path / "pkg", PARTITION_TEST)
    done = run_pytest(root, {**plain_env, "GZ_PARTITION": "sim"}, "test")
    assert done.returncode == 0, done.stdout + done.stderr
    seen = json.loads((tmp_path / "record.json").read_text())
    assert (seen["GZ_PARTITION"], seen["ROS_DOMAIN_ID"]) == ("sim", None)
    (line,) = header_lines(done.stdout)
    assert "GZ_PARTITION is already set to 'sim'" in line and "NOT isolated" in line

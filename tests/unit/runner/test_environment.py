"""``environment``: the test's environment, and whether isolation may go ahead at all.

A preset ROS_DOMAIN_ID is refused, in the shell ``run`` and in the ctest RUNNER alike.
Upstream silently runs on a preset ID; we refuse, because an exported ID turns a parallel
run into crosstalk nobody notices. DISABLE_ROS_ISOLATION=1 is the documented way out, and
it counts wherever the test's environment gets it (the runner's own environment, or
``--env``, ament_add_test's ENV, which has the last word). The refusal runs on each
supported distro (the ``tools`` fixture); it matters most on Kilted, whose upstream runner
silently replaces a preset ID instead. In process: the policy itself (the unset control
of every refusal, the mark of an ID held for us, ``--append-env``, what never reaches the
test, namespaces that contradict the test's discovery or would hide its
files in the host's /dev/shm). The Gazebo partition's half of
the policy is in test_environment_partition.py.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import (
    CLI,
    ERROR_PREFIX,
    MODES,
    ament,
    ament_args,
    run_process,
    the_error_line,
    through,
)
from helpers.coordinator import stand_in_colcon
from helpers.distros import Tools
from helpers.domains import free_ids
from helpers.results import load_result

from ros_isolated_test.domain_coordinator.pool import POOL_ENV
from ros_isolated_test.domain_coordinator.port_guard import claim_port
from ros_isolated_test.runner import environment, settings
from ros_isolated_test.runner.environment import DOMAIN_VAR, HELD_VAR, RefusedError
from ros_isolated_test.runner.request import EnvAssignment

WARNING = "WARNING: DISABLE_ROS_ISOLATION is set"
#: Writes the domain the test saw, so a test can tell it ran and where.
SEEN = ("sh", "-c", 'echo "${ROS_DOMAIN_ID-unset}" > seen')
PRINT = ("sh", "-c", 'echo "id=$ROS_DOMAIN_ID"')


# --- an ID colcon's coordinator set for the task: a tool's, replaced ------------------------


def _under_colcon(
    mode: str, runner_script: str, env: dict[str, str], tmp_path: Path, colcon_id: int, hold: str
) -> subprocess.CompletedProcess[str]:
    """``run`` or the RUNNER started by the colcon stand-in, which set ``colcon_id``."""
    colcon = [sys.executable, str(stand_in_colcon(tmp_path)), str(colcon_id), hold]
    if mode == "shell":
        argv = [CLI, "run", "--junit-xml", str(tmp_path / "t.xml"), "--", *PRINT]
    else:
        args = ament_args(tmp_path / "t.xml", PRINT, "--generate-result-on-success")
        argv = [sys.executable, "-u", runner_script, *args]
    return run_process([*colcon, *argv], env, cwd=tmp_path)


@capabilities.SOCK_DIAG_BOUND
@pytest.mark.parametrize("mode", MODES)
def test_an_id_colcons_coordinator_holds_is_replaced_by_one_of_the_pool(
    runner_script: str, env: dict[str, str], tmp_path: Path, mode: str
) -> None:
    """The test runs on a pool ID, never colcon's (in the pool too, but held by colcon);
    the first line and the result file say which ID was replaced, and why. The control:
    the same colcon not holding the port (no coordinator's ID) is refused as ever."""
    colcon_id, other = free_ids(2)
    env[POOL_ENV] = f"{colcon_id},{other}"
    proc = _under_colcon(mode, runner_script, env, tmp_path, colcon_id, "hold")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert f"id={other}\n" in proc.stdout
    first = proc.stdout.splitlines()[0]
    assert first.startswith(f"Running with ROS_DOMAIN_ID {other} ")
    assert first.endswith(
        f", replacing ROS_DOMAIN_ID {colcon_id} of colcon's domain-ID coordinator"
    )
    replaced = load_result(tmp_path / "t.xml").properties["ros_domain_id_replaced"]
    assert replaced.startswith(f"{colcon_id}: ROS_DOMAIN_ID {colcon_id} was set by colcon's ")
    assert f"replaced by {other}, an ID of this test's own" in replaced
    control = _under_colcon(mode, runner_script, env, tmp_path, colcon_id, "free")
    assert control.returncode == 2, control.stdout + control.stderr
    assert f"ROS_DOMAIN_ID is already set to '{colcon_id}', so" in the_error_line(control)


@capabilities.SOCK_DIAG_BOUND
@pytest.mark.parametrize("mode", MODES)
def test_an_id_colcon_set_while_another_process_holds_its_port_is_refused(
    runner_script: str, env: dict[str, str], tmp_path: Path, mode: str
) -> None:
    """An environment hook's ID that colcon set, its port 32768+ID held by someone else
    (here as our runner holds its own ID): no coordinator's, refused as any preset ID.
    The control: the same colcon holding the port itself is replaced (the test above)."""
    colcon_id, other = free_ids(2)
    env[POOL_ENV] = str(other)
    held = claim_port(colcon_id)
    assert held is not None
    try:
        proc = _under_colcon(mode, runner_script, env, tmp_path, colcon_id, "free")
    finally:
        held.close()
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "id=" not in proc.stdout
    assert f"ROS_DOMAIN_ID is already set to '{colcon_id}', so" in the_error_line(proc)


#: The policy's answer for its own ROS_DOMAIN_ID, in a process colcon's stand-in started,
#: the kernel's probe answered by argv[1]: "hidden" as before Linux 6.8, "probe" asked.
POLICY_UNDER_COLCON = """
import os, sys
from ros_isolated_test.runner import environment
shown = None if sys.argv[1] == "probe" else False
try:
    setter = environment._tool_domain(os.environ["ROS_DOMAIN_ID"], shown)
except environment.RefusedError as error:
    print("refused:", error)
else:
    print("replaced:", setter.kind, setter.domain_id)
"""


@pytest.mark.parametrize(
    "probe", ["hidden", pytest.param("probe", marks=capabilities.SOCK_DIAG_BOUND.mark)]
)
def test_where_the_kernel_hides_colcons_socket_its_id_is_refused_saying_why(
    env: dict[str, str], tmp_path: Path, probe: str
) -> None:
    """colcon holding the ID it set, the probe answered as on Linux before 6.8: refused in
    one line that says the kernel cannot tell its coordinator apart, and the fixes. The
    positive control, the probe asked on this kernel: the same ID is colcon's, replaced."""
    colcon_id = free_ids(1)[0]
    colcon = [sys.executable, str(stand_in_colcon(tmp_path)), str(colcon_id), "hold"]
    argv = [*colcon, sys.executable, "-c", POLICY_UNDER_COLCON, probe]
    proc = run_process(argv, env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    if probe == "probe":
        assert proc.stdout == f"replaced: colcon {colcon_id}\n"
        return
    line = proc.stdout.removesuffix("\n")
    assert "\n" not in line, proc.stdout
    prefix = f"refused: refusing to run: ROS_DOMAIN_ID is already set to '{colcon_id}' by colcon"
    assert line.startswith(f"{prefix} (pid "), line
    pid, rest = line.removeprefix(f"{prefix} (pid ").split(")", 1)
    assert pid.isdigit()  # the stand-in's, started by run_process: not known before
    assert rest == (
        f" and port {32768 + colcon_id} is taken, but colcon's domain-ID coordinator cannot be "
        "told apart on this kernel (Linux before 6.8 shows no bound-only sockets): the port "
        "may be any program's and the ID a package's environment hook's; fix: run on Linux "
        "6.8 or later, or block the coordinator (COLCON_EXTENSION_BLOCKLIST="
        "colcon_core.shell.ros_domain_id:colcon_core.event_handler.ros_domain_id) and the "
        "runner picks a free ID, or set DISABLE_ROS_ISOLATION=1 to run without isolation"
    )


@capabilities.SOCK_DIAG_BOUND
@pytest.mark.parametrize("mode", MODES)
def test_a_users_id_colcon_started_with_is_refused_though_colcon_replaced_it(
    runner_script: str, env: dict[str, str], tmp_path: Path, mode: str
) -> None:
    """``ROS_DOMAIN_ID=5 colcon test``: the user's 5, with today's message, and where."""
    colcon_id = free_ids(1)[0]
    proc = _under_colcon(mode, runner_script, {**env, DOMAIN_VAR: "5"}, tmp_path, colcon_id, "hold")
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "id=" not in proc.stdout
    assert the_error_line(proc).removeprefix(ERROR_PREFIX) == (
        f"refusing to run: ROS_DOMAIN_ID is already set to '5' where colcon's domain-ID "
        f"coordinator runs (it gave this task {colcon_id} in its place), so the test would "
        "share that domain with whatever else runs in it; unset it (unset ROS_DOMAIN_ID) and "
        "the runner picks a free ID, or set DISABLE_ROS_ISOLATION=1 to run without isolation"
    )


# --- a preset ROS_DOMAIN_ID, as users meet it: run and the RUNNER ----------------------------


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("value", ["5", ""], ids=["set", "empty"])
def test_preset_domain_id_is_refused_and_nothing_runs(
    tools: Tools,
    distro_runner_script: str,
    distro_env: dict[str, str],
    tmp_path: Path,
    mode: str,
    value: str,
) -> None:
    env = distro_env
    env["ROS_DOMAIN_ID"] = value
    proc = through(mode, distro_runner_script, env, tmp_path, ["touch", "ran"], tools=tools)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert not (tmp_path / "ran").exists(), "a refused test must not run"
    assert "Running with ROS_DOMAIN_ID" not in proc.stdout
    line = the_error_line(proc)
    assert f"ROS_DOMAIN_ID is already set to {value!r}" in line
    assert "share that domain" in line, "the message must say why"
    assert "unset ROS_DOMAIN_ID" in line, "the message must name the way out"
    assert "DISABLE_ROS_ISOLATION=1" in line
    if not value:
        assert "domain 0" in line


@pytest.mark.parametrize("mode", MODES)
def test_refusal_is_recorded_in_the_result_file_as_a_failed_case(
    tools: Tools, distro_runner_script: str, distro_env: dict[str, str], tmp_path: Path, mode: str
) -> None:
    env = distro_env
    env["ROS_DOMAIN_ID"] = "17"
    result = tmp_path / "out" / "pkg" / "t.xml"
    proc = through(
        mode, distro_runner_script, env, tmp_path, ["touch", "ran"], result=result, tools=tools
    )
    assert proc.returncode == 2
    assert not (tmp_path / "ran").exists()
    message = the_error_line(proc).removeprefix(ERROR_PREFIX)
    case = load_result(result).only
    assert case.outcome == "failure"
    assert case.message == message
    assert "ROS_DOMAIN_ID is already set to '17'" in case.text


@pytest.mark.parametrize("option", ["--env", "--append-env"])
def test_domain_id_passed_with_env_option_is_refused(
    runner_script: str, env: dict[str, str], tmp_path: Path, option: str
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    proc = through(
        "runner",
        runner_script,
        env,
        tmp_path,
        ["touch", "ran"],
        result=result,
        runner_options=[option, "ROS_DOMAIN_ID=7"],
    )
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert not (tmp_path / "ran").exists()
    line = the_error_line(proc)
    keyword = "APPEND_ENV" if option == "--append-env" else "ENV"
    assert f"ROS_DOMAIN_ID='7' is passed with {option} (ament_add_test {keyword}), so" in line
    assert f"remove it from {option} (ament_add_test {keyword}) (the runner picks" in line
    assert "add DISABLE_ROS_ISOLATION=1 to --env (ament_add_test ENV)" in line
    case = load_result(result).only
    assert case.outcome == "failure"
    assert case.message == line.removeprefix(ERROR_PREFIX)


@pytest.mark.parametrize("mode", MODES)
def test_disable_ros_isolation_runs_with_the_preset_id_and_warns(
    runner_script: str, env: dict[str, str], tmp_path: Path, mode: str
) -> None:
    env["ROS_DOMAIN_ID"] = "42"
    env["DISABLE_ROS_ISOLATION"] = "1"
    result = tmp_path / "pkg" / "t.xml"
    proc = through(
        mode, runner_script, env, tmp_path, ["sh", "-c", 'echo "seen=$ROS_DOMAIN_ID"'], result
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "seen=42\n" in proc.stdout
    assert "Running with ROS_DOMAIN_ID" not in proc.stdout
    warnings = [line for line in proc.stdout.splitlines() if "WARNING" in line]
    assert len(warnings) == 1, proc.stdout
    assert "ROS_DOMAIN_ID=42" in warnings[0]
    assert "WITHOUT isolation" in warnings[0]
    summary = load_result(result)
    assert summary.only.outcome == "passed"
    assert summary.properties["ros_domain_id"] == "42"


def test_disable_ros_isolation_lets_env_option_set_the_id(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    env["DISABLE_ROS_ISOLATION"] = "1"
    proc = through(
        "runner",
        runner_script,
        env,
        tmp_path,
        ["sh", "-c", 'echo "seen=$ROS_DOMAIN_ID"'],
        runner_options=["--env", "ROS_DOMAIN_ID=7"],
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "seen=7\n" in proc.stdout
    assert any("WARNING" in line and "ROS_DOMAIN_ID=7" in line for line in proc.stdout.splitlines())


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("word", ["0", "false"])
def test_disable_ros_isolation_0_does_not_disable(
    runner_script: str, env: dict[str, str], tmp_path: Path, mode: str, word: str
) -> None:
    env["DISABLE_ROS_ISOLATION"] = word
    env["ROS_DOMAIN_ID"] = "5"
    proc = through(mode, runner_script, env, tmp_path, ["touch", "ran"])
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert not (tmp_path / "ran").exists()
    assert "ROS_DOMAIN_ID is already set to '5'" in the_error_line(proc)

    del env["ROS_DOMAIN_ID"]
    isolated = through(
        mode, runner_script, env, tmp_path, ["sh", "-c", 'echo "seen=$ROS_DOMAIN_ID"']
    )
    assert isolated.returncode == 0, isolated.stdout + isolated.stderr
    first = isolated.stdout.splitlines()[0]
    assert first.startswith("Running with ROS_DOMAIN_ID ")
    assert f"seen={first.split()[3]}\n" in isolated.stdout
    assert "WARNING" not in isolated.stdout


# --- DISABLE_ROS_ISOLATION wherever the test's environment gets it ------------------------


@pytest.mark.parametrize(
    ("how", "runs"),
    [
        ("--env", True),  # ament_add_test(... ENV DISABLE_ROS_ISOLATION=1)
        ("environment", True),  # the runner's own environment
        ("neither", False),  # control: a preset ID is refused
        ("--env says no", False),  # the assignment has the last word over the environment
    ],
)
def test_disable_ros_isolation_counts_wherever_the_tests_environment_gets_it(
    env: dict[str, str], runner_script: str, tmp_path: Path, how: str, runs: bool
) -> None:
    options = ["--env", "ROS_DOMAIN_ID=42"]
    if how == "--env":
        options += ["--env", "DISABLE_ROS_ISOLATION=1"]
    elif how == "environment":
        env["DISABLE_ROS_ISOLATION"] = "1"
    elif how == "--env says no":
        env["DISABLE_ROS_ISOLATION"] = "1"
        options += ["--env", "DISABLE_ROS_ISOLATION=0"]
    result = tmp_path / "pkg" / "t.xml"
    options.append("--generate-result-on-success")
    proc = ament(runner_script, result, SEEN, env, *options, cwd=tmp_path)
    summary = load_result(result)
    if not runs:
        assert proc.returncode == 2, proc.stdout + proc.stderr
        assert not (tmp_path / "seen").exists()
        assert "DISABLE_ROS_ISOLATION=1" in proc.stderr
        assert summary.only.outcome in ("error", "failure")
        return
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (tmp_path / "seen").read_text().strip() == "42"
    assert WARNING in proc.stdout  # loudly, as the environment variable does
    if how == "--env":
        assert "(by --env" in proc.stdout
    assert summary.properties.get("isolation") == "disabled"
    assert summary.only.outcome == "passed"


# --- the policy, in process ------------------------------------------------------------------


def _decide(
    environ: dict[str, str],
    assignments: tuple[EnvAssignment, ...] = (),
    config: settings.Settings | None = None,
) -> environment.Policy:
    """The policy for ``environ`` (never this process's own), with settings read from it."""
    config = settings.read(environ) if config is None else config
    return environment.decide(assignments, config, environ)


@pytest.mark.parametrize("value", ["5", "", " "])
def test_a_preset_domain_id_is_refused_and_unset_is_the_control(value: str) -> None:
    with pytest.raises(RefusedError) as refused:
        _decide({DOMAIN_VAR: value, "OTHER": "kept"})
    assert refused.value.variable == DOMAIN_VAR
    message = str(refused.value)
    assert f"{DOMAIN_VAR} is already set to {value!r}" in message and "\n" not in message
    assert ("domain 0" in message) is (not value.strip()), message
    # The control: unset, the test is isolated, on the ID the runner hands it, marked held.
    policy = _decide({"OTHER": "kept"})
    assert policy.isolate and DOMAIN_VAR not in policy.env and policy.env["OTHER"] == "kept"
    env = policy.for_domain(9)
    assert (env[DOMAIN_VAR], env[HELD_VAR], env["OTHER"]) == ("9", "9", "kept")


def test_a_preset_id_is_run_on_only_with_isolation_disabled() -> None:
    """DISABLE_ROS_ISOLATION: nothing reserved, the ID kept as it is, said loudly."""
    policy = _decide({DOMAIN_VAR: "42", "DISABLE_ROS_ISOLATION": "1"})
    assert not policy.isolate and policy.env[DOMAIN_VAR] == "42"
    (warning,) = policy.notes
    assert warning.startswith(WARNING) and f"WITHOUT isolation on {DOMAIN_VAR}=42" in warning
    # An off word is no way out: refused as before.
    with pytest.raises(RefusedError):
        _decide({DOMAIN_VAR: "42", "DISABLE_ROS_ISOLATION": "no"})


def test_an_id_is_held_for_us_only_when_the_mark_names_that_very_id() -> None:
    """A pytest started under a runner sees its ID held for it; a plain preset ID is not."""
    assert environment.held_for_us({DOMAIN_VAR: "5", HELD_VAR: "5"})
    assert not environment.held_for_us({DOMAIN_VAR: "5"})
    assert not environment.held_for_us({DOMAIN_VAR: "5", HELD_VAR: "6"})
    assert not environment.held_for_us({HELD_VAR: "5"})


def test_append_env_to_an_unset_or_empty_variable_gives_the_plain_value() -> None:
    """Upstream's leading separator would put the current directory on the path."""
    appended = [EnvAssignment("P", "/x", append=True)]
    for base in ({}, {"P": ""}):
        env, notes = environment.apply_assignments(base, appended)
        assert env["P"] == "/x", base
        assert notes == ["extra environment variables to append:", " - P+=/x"]
    # The control: a value there gets the separator once, never twice.
    assert environment.apply_assignments({"P": "/a"}, appended)[0]["P"] == f"/a{os.pathsep}/x"
    ends = {"P": f"/a{os.pathsep}"}
    assert environment.apply_assignments(ends, appended)[0]["P"] == f"/a{os.pathsep}/x"
    # --env sets before --append-env appends, whatever the order given.
    both = [*appended, EnvAssignment("P", "/set")]
    assert environment.apply_assignments({}, both)[0]["P"] == f"/set{os.pathsep}/x"


def test_the_rerun_count_and_the_resources_never_reach_the_test() -> None:
    """A runner started inside the test would rerun, or wait for what its parent holds."""
    environ = {
        settings.RERUNS_ENV: "2",
        settings.RESOURCES_ENV: "gpu=1",
        "OTHER_VARIABLE": "2",
    }
    policy = _decide(environ, config=settings.read({}))
    assert settings.RERUNS_ENV not in policy.env and settings.RESOURCES_ENV not in policy.env
    assert policy.env["OTHER_VARIABLE"] == "2"  # the control: any other reaches it as it is


@pytest.mark.parametrize(
    ("range_given", "peers", "says"),
    [
        ("SUBNET", "", "its discovery range is SUBNET"),
        (None, "localhost;10.203.99.7", "names another host (10.203.99.7)"),
    ],
)
def test_namespaces_that_would_cut_the_test_off_are_refused_or_fall_back(
    range_given: str | None, peers: str, says: str
) -> None:
    """``namespace`` refuses what needs the outside network; ``auto`` runs on the ID alone."""
    environ = {"ROS_STATIC_PEERS": peers} if peers else {}

    def config(mode: str) -> settings.Settings:
        return settings.read(environ, isolation=mode, discovery_range=range_given)

    with pytest.raises(RefusedError) as refused:
        _decide(environ, config=config("namespace"))
    assert refused.value.variable == settings.ISOLATION_ENV
    assert says in str(refused.value) and "--isolation namespace" in str(refused.value)
    auto = _decide(environ, config=config("auto"))
    assert not auto.namespaces and auto.fallback is not None and says in auto.fallback
    # The control: loopback peers and the default range leave namespace mode as asked.
    loopback = {"ROS_STATIC_PEERS": "localhost;127.0.0.1;[::1]"}
    policy = _decide(loopback, config=settings.read(loopback, isolation="namespace"))
    assert policy.namespaces and policy.fallback is None


def test_a_test_starting_in_the_hosts_dev_shm_is_refused_namespaces_or_falls_back(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Its private /dev/shm would hide it: ``namespace`` refuses, ``auto`` runs on the ID
    alone, ``domain`` (the control) runs it; from a folder on disk, namespaces as asked."""
    shm = Path("/dev/shm") / f"rit-env-{tmp_path.name}"
    shm.mkdir()
    try:
        monkeypatch.chdir(shm)
        with pytest.raises(RefusedError) as refused:
            _decide({}, config=settings.read({}, isolation="namespace"))
        assert refused.value.variable == settings.ISOLATION_ENV
        message = str(refused.value)
        assert f"its working directory {shm} is in the host's /dev/shm" in message, message
        assert "/dev/shm of its own" in message and "\n" not in message
        auto = _decide({}, config=settings.read({}, isolation="auto"))
        assert not auto.namespaces and auto.fallback is not None
        assert f"as namespaces would cut it off: its working directory {shm}" in auto.fallback
        assert not _decide({}).namespaces and _decide({}).fallback is None
    finally:
        monkeypatch.chdir(tmp_path)
        shm.rmdir()
    policy = _decide({}, config=settings.read({}, isolation="namespace"))
    assert policy.namespaces and policy.fallback is None

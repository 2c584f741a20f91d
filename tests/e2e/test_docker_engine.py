"""The Docker entrypoint in a real Docker engine: the project's image, as users run it.

The image is built from the project's own Dockerfile on a stand-in for
``ros:jazzy-ros-base`` (tests/data/docker; helpers/docker_engine.py builds both once per
session and keeps them between runs). Its runner is PID 1 of each container with a PID
namespace of its own, as the Dockerfile makes it. Every test gets a lock directory of its
own, bind-mounted where the image's runner looks for it, and a pool of IDs free on this
machine now.

Each claim has its control: crosstalk probes in containers (and one on the host) pass on
distinct IDs, and fail with isolation disabled, and the shared IPC namespace is what
lets them hear each other; a runner on the host waits for the ID a container holds
through the shared lock directory, and without that directory both hold it at once.
"""

from __future__ import annotations

import contextlib
import json
import signal
import subprocess
import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import pytest
from helpers import capabilities, docker_engine
from helpers.commands import CLI, HUNG, REPO, run_cli, start_cli, the_error_line
from helpers.docker_engine import HOST_NAMESPACES, IMAGE_LOCK_DIR, Containers, Engine, Images
from helpers.domains import free_ids
from helpers.processes import Children, poll_until
from helpers.results import NO_RESULT, ResultSummary, domain_of, load_result

pytestmark = [capabilities.DOCKER_ENGINE.mark]

POOL_VAR = "ROS_ISOLATED_TEST_DOMAINS"
#: Inside the containers: the test helpers (read-only) and each test's results folder.
HELPERS_IN_IMAGE = "/probe/helpers"
CROWD_PROBE = REPO / "tests" / "helpers" / "crowd_probe.py"
RESULTS = "/res"
#: Crosstalk probes started at once (the machine has 2 cores).
PROBES = 3
#: After all probes are up: longer than the ~3 s a late joiner may wait for an announcement.
LISTEN_S = 5.0
#: The test says when SIGTERM reached it, then exits 7.
TRAP_SCRIPT = (
    "trap 'echo TERM > received; exit 7' TERM; echo ready > ready; while :; do sleep 0.1; done"
)
#: A daemon: its own session, its parent gone at once. SIGTERM, which only the runner
#: sends (the kernel's end of a PID namespace is SIGKILL), is the one way it says "ended".
DAEMON_SCRIPT = """\
trap 'echo TERM > daemon-ended; exit 0' TERM
echo $$ > daemon.partial && mv daemon.partial daemon
while :; do sleep 0.05; done
"""
#: The test: leaves the daemon, and orphans for PID 1 to reap (order of events only: they
#: end when told, and the test waits until each is gone, which a zombie never is). Only
#: zombies of PID 1 count: the daemon's loop makes short-lived ones of its own.
FORKING_TEST = """\
sh -c 'setsid sh daemon.sh </dev/null >/dev/null 2>&1 &'
for i in 1 2 3 4 5; do sh -c 'while [ ! -e go ]; do sleep 0.05; done & echo $! >> orphans'; done
while [ ! -e daemon ]; do sleep 0.05; done
adopted=0
for p in $(cat orphans daemon); do
  [ "$(ps -o ppid= -p "$p" | tr -d ' ')" = 1 ] && adopted=$((adopted+1))
done
echo adopted=$adopted
touch go
n=0
for p in $(cat orphans); do
  while kill -0 "$p" 2>/dev/null && [ $n -lt 600 ]; do sleep 0.1; n=$((n+1)); done
done
echo zombies=$(ps -eo stat=,ppid= | awk '$1 ~ /^Z/ && $2 == 1' | wc -l)
exit 42
"""


def _say(config: pytest.Config, line: str) -> None:
    """A line on the terminal, past pytest's capture (build times belong in CI's log)."""
    capture = config.pluginmanager.getplugin("capturemanager")
    with capture.global_and_fixture_disabled() if capture else contextlib.nullcontext():
        print(f"\n{line}", flush=True)


@pytest.fixture(scope="session")
def engine() -> Iterator[Engine]:
    """A Docker engine for the session: one that answers, else dockerd started (and stopped)."""
    with docker_engine.running() as running:
        yield running


@pytest.fixture(scope="session")
def images(engine: Engine, request: pytest.FixtureRequest) -> Images:
    """The stand-in base and the project's image on it, built once (cached between runs)."""
    built = docker_engine.build_images(engine)
    _say(request.config, f"docker tier: {'; '.join(built.steps)}")
    return built


@pytest.fixture
def containers(engine: Engine, images: Images) -> Iterator[Containers]:
    started = Containers(engine, images.project)
    yield started
    started.remove_all()


@pytest.fixture
def results(tmp_path: Path) -> Path:
    folder = tmp_path / "res"
    folder.mkdir()
    return folder


def mounts(lock_dir: Path, results: Path) -> list[str]:
    """The test's own lock directory where the image's runner looks, and its results."""
    return ["-v", f"{lock_dir}:{IMAGE_LOCK_DIR}", "-v", f"{results}:{RESULTS}", "-w", RESULTS]


def pool(*ids: int) -> list[str]:
    return ["-e", f"{POOL_VAR}={','.join(map(str, ids))}"]


def run_args(result: str, *command: str) -> list[str]:
    """The runner's arguments: the image's entrypoint is ``ros-isolated-test``."""
    return ["run", "--junit-xml", f"{RESULTS}/{result}", "--", *command]


def output_of(log: Path) -> str:
    return log.read_text(errors="replace")


def wait_until_started(marker: Path, process: subprocess.Popen[str], log: Path) -> None:
    """Until the test in the container made ``marker``; fails at once if the container ended."""
    poll_until(lambda: marker.exists() or process.poll() is not None, f"{marker} ({log})")
    assert marker.exists(), f"the container ended first:\n{output_of(log)}"


def start_test(
    containers: Containers,
    lock_dir: Path,
    results: Path,
    log: Path,
    script: str,
    marker: str,
    *ids: int,
) -> tuple[str, subprocess.Popen[str]]:
    """A container on ``lock_dir`` and pool ``ids`` whose runner runs ``sh -c script`` (result
    ``t.xml``), once its test made ``results/marker``."""
    options = [*mounts(lock_dir, results), *pool(*ids)]
    name, process = containers.start(options, run_args("t.xml", "sh", "-c", script), log)
    wait_until_started(results / marker, process, log)
    return name, process


# --- the image -----------------------------------------------------------------------------


def test_the_image_builds_on_the_stand_in_and_its_tests_import_rclpy(
    engine: Engine, images: Images, containers: Containers, lock_dir: Path, results: Path
) -> None:
    inspected = engine.docker("image", "inspect", images.project, "--format", "{{json .Config}}")
    config = json.loads(inspected.stdout)
    assert config["Entrypoint"] == ["/ros_entrypoint.sh", "ros-isolated-test"], config
    (domain_id,) = free_ids(1)
    script = "import os, rclpy, std_msgs.msg; print('rclpy on', os.environ['ROS_DOMAIN_ID'])"
    proc = containers.run(
        [*mounts(lock_dir, results), *pool(domain_id)],
        run_args("t.xml", "python3", "-c", script),
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert f"rclpy on {domain_id}" in proc.stdout
    assert load_result(results / "t.xml").only.outcome == "passed"
    # What the README's CI job passes to colcon build is in the image.
    include = containers.run(
        ["--entrypoint", "/ros_entrypoint.sh"],
        ["sh", "-c", 'test -f "$(ros-isolated-test cmake-include)" && echo found'],
    )
    assert include.stdout.strip() == "found", include.stdout + include.stderr


# --- PID 1 ---------------------------------------------------------------------------------


def test_docker_stop_passes_sigterm_on_and_the_result_names_the_id(
    engine: Engine, containers: Containers, lock_dir: Path, results: Path, tmp_path: Path
) -> None:
    (domain_id,) = free_ids(1)
    log = tmp_path / "container.log"
    name, process = start_test(containers, lock_dir, results, log, TRAP_SCRIPT, "ready", domain_id)
    # SIGKILL only after 120 s: far later than a test that got its SIGTERM takes to end.
    engine.docker("stop", "--time", "120", name, timeout=HUNG + 120)
    code = process.wait(timeout=HUNG)
    output = output_of(log)
    assert (results / "received").read_text().strip() == "TERM", output
    assert code == 128 + signal.SIGTERM, output
    assert "received SIGTERM, passed it on" in output
    summary = load_result(results / "t.xml")
    assert summary.properties["ros_domain_id"] == str(domain_id), summary
    case = summary.only
    assert case.outcome == "failure", case
    assert "interrupted" in case.message and "SIGTERM" in case.message, case


def test_docker_kill_leaves_the_placeholder(
    engine: Engine, containers: Containers, lock_dir: Path, results: Path, tmp_path: Path
) -> None:
    """SIGKILL ends PID 1 at once: the placeholder written before the test is what stays."""
    (domain_id,) = free_ids(1)
    log = tmp_path / "container.log"
    script = "echo ready > ready; while :; do sleep 0.1; done"
    name, process = start_test(containers, lock_dir, results, log, script, "ready", domain_id)
    engine.docker("kill", "--signal", "KILL", name)
    code = process.wait(timeout=HUNG)
    assert code == 128 + signal.SIGKILL, output_of(log)
    case = load_result(results / "t.xml").only
    assert case.outcome == "error", case
    assert NO_RESULT in case.message, case


def test_a_forked_daemon_is_ended_orphans_are_reaped_and_the_exit_code_is_the_tests(
    containers: Containers, lock_dir: Path, results: Path
) -> None:
    (domain_id,) = free_ids(1)
    (results / "daemon.sh").write_text(DAEMON_SCRIPT)
    (results / "test.sh").write_text(FORKING_TEST)
    proc = containers.run(
        [*mounts(lock_dir, results), *pool(domain_id)], run_args("t.xml", "sh", "test.sh")
    )
    output = proc.stdout + proc.stderr
    # The daemon and five orphans were PID 1's (the runner's) while the test ran.
    assert "adopted=6" in proc.stdout, output
    assert "zombies=0" in proc.stdout, output
    assert proc.returncode == 42, output
    # The runner ended the daemon with SIGTERM before it exited, and nothing survived it.
    assert (results / "daemon-ended").read_text().strip() == "TERM", output
    summary = load_result(results / "t.xml")
    daemon = (results / "daemon").read_text().strip()
    assert f"{daemon} (sh)" in summary.properties.get("leftover_processes", ""), summary
    assert "surviving_processes" not in summary.properties, summary
    case = summary.only
    assert case.outcome == "failure" and "exited with code 42" in case.message, case


# --- crosstalk between containers ----------------------------------------------------------


@dataclass(frozen=True)
class Probe:
    token: str
    returncode: int
    output: str
    report: dict[str, object]
    result: ResultSummary


def probe_args(token: str, results: str, count: int) -> list[str]:
    """The probe's arguments after its path: the rendezvous is the results folder."""
    return [token, results, str(count), "--listen", str(LISTEN_S)]


def run_probes(
    containers: Containers,
    lock_dir: Path,
    tmp_path: Path,
    options: Sequence[str],
    namespaces: Sequence[str] = HOST_NAMESPACES,
    host_env: dict[str, str] | None = None,
) -> list[Probe]:
    """Crosstalk probes at once, each through a runner: PROBES containers sharing one lock
    directory and (by default) the host's namespaces, as the README's ``docker run`` line
    does; with ``host_env``, one container and one probe run by the runner on the host."""
    rendezvous = tmp_path / "rendezvous"
    rendezvous.mkdir(parents=True)
    in_containers = PROBES if host_env is None else 1
    count = in_containers + (host_env is not None)
    started: list[tuple[str, subprocess.Popen[str] | subprocess.Popen[bytes], Path]] = []
    for index in range(in_containers):
        token = f"probe{index}"
        log = tmp_path / f"{token}.log"
        helpers = f"{REPO / 'tests' / 'helpers'}:{HELPERS_IN_IMAGE}:ro"
        _, container = containers.start(
            [*namespaces, *mounts(lock_dir, rendezvous), "-v", helpers, *options],
            run_args(
                f"{token}.xml",
                "python3",
                f"{HELPERS_IN_IMAGE}/crowd_probe.py",
                *probe_args(token, RESULTS, count),
            ),
            log,
        )
        started.append((token, container, log))
    if host_env is not None:
        token, log = "host", tmp_path / "host.log"
        args = probe_args(token, str(rendezvous), count)
        command = [sys.executable, str(CROWD_PROBE), *args]
        junit = ["--junit-xml", str(rendezvous / f"{token}.xml")]
        runner = start_cli(["run", *junit, "--", *command], host_env, log, [])
        started.append((token, runner, log))
    probes = []
    try:
        codes = [process.wait(timeout=HUNG) for _, process, _ in started]
    finally:
        for _, process, _ in started:
            if process.poll() is None:
                process.terminate()  # the runner passes it on and ends its probe
                process.wait(timeout=HUNG)
    for (token, _, log), code in zip(started, codes, strict=True):
        output = output_of(log)
        reports = [line for line in output.splitlines() if line.startswith("RESULT ")]
        assert len(reports) == 1, f"probe {token} printed no RESULT:\n{output}"
        report = json.loads(reports[0].removeprefix("RESULT "))
        result = load_result(rendezvous / f"{token}.xml")
        probes.append(Probe(token, code, output, report, result))
    for probe in probes:
        assert probe.report["own"], f"DDS did not work for {probe.token}:\n{probe.output}"
        assert probe.report["met_all"], f"the probes never ran at once:\n{probe.output}"
    return probes


def assert_isolated(probes: Sequence[Probe], ids: Sequence[int]) -> None:
    """Each probe held one of ``ids`` (all at once), heard only itself, and passed."""
    held = sorted(int(probe.result.properties["ros_domain_id"]) for probe in probes)
    assert held == sorted(ids), "the probes did not hold the pool's IDs, one each, at once"
    for probe in probes:
        assert probe.report["foreign"] == {}, f"crosstalk despite isolation:\n{probe.output}"
        assert probe.returncode == 0, probe.output
        assert probe.result.only.outcome == "passed", probe.output


def test_containers_sharing_the_lock_dir_and_host_namespaces_run_on_distinct_ids(
    containers: Containers, lock_dir: Path, tmp_path: Path
) -> None:
    ids = free_ids(PROBES)
    assert_isolated(run_probes(containers, lock_dir, tmp_path, pool(*ids)), ids)


def probes_on_one_id(
    containers: Containers,
    lock_dir: Path,
    tmp_path: Path,
    namespaces: Sequence[str],
    env: dict[str, str] | None = None,
) -> list[Probe]:
    """The probes with isolation disabled, all on one ID free on this machine; with
    ``env`` (the runner environment), one of them on the host."""
    (shared_id,) = free_ids(1)
    disabled = {"DISABLE_ROS_ISOLATION": "1", "ROS_DOMAIN_ID": str(shared_id)}
    options = [word for name, value in disabled.items() for word in ("-e", f"{name}={value}")]
    host_env = None if env is None else {**env, **disabled}
    probes = run_probes(containers, lock_dir, tmp_path, options, namespaces, host_env)
    for probe in probes:
        assert probe.result.properties["ros_domain_id"] == str(shared_id), probe.output
    return probes


def assert_crosstalk(probes: Sequence[Probe]) -> None:
    """Each probe heard every other one, and so failed."""
    tokens = {probe.token for probe in probes}
    for probe in probes:
        heard = probe.report["foreign"]
        assert isinstance(heard, dict)
        others = tokens - {probe.token}
        assert others <= set(heard), f"no crosstalk without isolation:\n{probe.output}"
        assert probe.returncode == 1, probe.output
        assert probe.result.only.outcome == "failure", probe.output


def test_control_the_same_containers_without_isolation_crosstalk(
    containers: Containers, lock_dir: Path, tmp_path: Path
) -> None:
    """Without this, silence above could be containers that cannot hear each other at all."""
    assert_crosstalk(probes_on_one_id(containers, lock_dir, tmp_path, HOST_NAMESPACES))


def test_what_lets_ros_through_between_containers_is_the_shared_ipc_namespace(
    containers: Containers, lock_dir: Path, tmp_path: Path
) -> None:
    """The README's reason, measured: Fast DDS sends same-host data over shared memory.

    With the host's network alone (Docker's private IPC) the probes on one ID hear
    themselves and nobody else; the same with ``--ipc host`` crosstalk, with no shared
    PID namespace (the control, each side failing if the other stops holding).
    """
    alone = probes_on_one_id(containers, lock_dir, tmp_path / "network", ["--network", "host"])
    for probe in alone:
        assert probe.report["foreign"] == {}, f"heard across IPC namespaces:\n{probe.output}"
        assert probe.returncode == 0, probe.output
    shared_ipc = ["--network", "host", "--ipc", "host"]
    assert_crosstalk(probes_on_one_id(containers, lock_dir, tmp_path / "ipc", shared_ipc))


# --- a container and a runner on the host --------------------------------------------------


def host_runner(
    children: Children, env: dict[str, str], script: str, *ids: int
) -> subprocess.Popen[str]:
    return children.start(
        [CLI, "run", "--", "sh", "-c", script], env={**env, POOL_VAR: ",".join(map(str, ids))}
    )


def meet(me: str, other: str) -> str:
    """One side of a rendezvous: say the ID, then hold it until the other side said its own."""
    return f'echo $ROS_DOMAIN_ID > "{me}.id"; while [ ! -e "{other}.id" ]; do sleep 0.05; done'


def meet_container_and_host(
    containers: Containers,
    children: Children,
    env: dict[str, str],
    lock_dir: Path,
    results: Path,
    log: Path,
    *ids: int,
) -> None:
    """Container and host runner ``meet`` on pool ``ids``: the lock-dir test and its control."""
    _, process = start_test(
        containers, lock_dir, results, log, meet("container", "host"), "container.id", *ids
    )
    host = host_runner(children, env, f"cd {results}; {meet('host', 'container')}", *ids)
    stdout, stderr = host.communicate(timeout=HUNG)
    assert host.returncode == 0, stdout + stderr
    assert process.wait(timeout=HUNG) == 0, output_of(log)


def test_a_host_runner_waits_for_the_id_a_container_holds_through_the_lock_dir(
    containers: Containers,
    env: dict[str, str],
    lock_dir: Path,
    results: Path,
    tmp_path: Path,
    children: Children,
) -> None:
    (domain_id,) = free_ids(1)
    log = tmp_path / "container.log"
    container_test = (
        "echo $ROS_DOMAIN_ID > container.id; while [ ! -e go ]; do sleep 0.05; done; "
        "touch container.done"
    )
    _, process = start_test(
        containers, lock_dir, results, log, container_test, "container.id", domain_id
    )
    # The host's test notes whether the container's had ended when it started.
    host_test = (
        f"cd {results}; [ -e container.done ] && echo after > host.order; "
        "echo $ROS_DOMAIN_ID > host.id"
    )
    host = host_runner(children, env, host_test, domain_id)
    while "waiting for a free ROS_DOMAIN_ID" not in (line := children.first_line(host)):
        assert "Running with ROS_DOMAIN_ID" not in line, "the host runner did not wait"
    assert not (results / "host.id").exists()
    (results / "go").touch()
    assert process.wait(timeout=HUNG) == 0, output_of(log)
    stdout, stderr = host.communicate(timeout=HUNG)
    assert host.returncode == 0, stdout + stderr
    assert domain_of(stdout) == domain_id
    assert (results / "container.id").read_text().strip() == str(domain_id)
    assert (results / "host.id").read_text().strip() == str(domain_id)
    assert (results / "host.order").read_text().strip() == "after", "held at once"


def test_a_container_and_a_host_runner_sharing_the_lock_dir_hold_distinct_ids_at_once(
    containers: Containers,
    env: dict[str, str],
    lock_dir: Path,
    results: Path,
    tmp_path: Path,
    children: Children,
) -> None:
    ids = free_ids(2)
    log = tmp_path / "container.log"
    meet_container_and_host(containers, children, env, lock_dir, results, log, *ids)
    held = {int((results / f"{side}.id").read_text()) for side in ("container", "host")}
    assert held == set(ids), "both held one ID at the same moment"


def test_control_without_the_shared_lock_dir_both_hold_one_id_at_once(
    containers: Containers,
    env: dict[str, str],
    results: Path,
    tmp_path: Path,
    tmp_path_factory: pytest.TempPathFactory,
    children: Children,
) -> None:
    """Without this, the wait above could come from something else than the lock directory."""
    (domain_id,) = free_ids(1)
    log = tmp_path / "container.log"
    its_own = tmp_path_factory.mktemp("container-locks")
    meet_container_and_host(containers, children, env, its_own, results, log, domain_id)
    for side in ("container", "host"):
        assert (results / f"{side}.id").read_text().strip() == str(domain_id), side


def test_a_container_and_the_host_talk_ros_and_run_on_distinct_ids(
    containers: Containers, env: dict[str, str], lock_dir: Path, tmp_path: Path
) -> None:
    """A probe in a container (the README's line) and one run on the host, at once."""
    ids = free_ids(2)
    host_env = {**env, POOL_VAR: ",".join(map(str, ids))}
    probes = run_probes(containers, lock_dir, tmp_path, pool(*ids), host_env=host_env)
    assert_isolated(probes, ids)


def test_control_a_container_and_the_host_without_isolation_crosstalk(
    containers: Containers, env: dict[str, str], lock_dir: Path, tmp_path: Path
) -> None:
    """Without this, silence above could be a container that cannot reach the host at all."""
    assert_crosstalk(probes_on_one_id(containers, lock_dir, tmp_path, HOST_NAMESPACES, env))


# --- refusal -------------------------------------------------------------------------------


def test_a_preset_domain_id_is_refused_in_a_container_as_on_the_host(
    containers: Containers, env: dict[str, str], lock_dir: Path, results: Path
) -> None:
    (domain_id,) = free_ids(1)
    options = [*mounts(lock_dir, results), *pool(domain_id)]
    # Control: the same container without the preset ID runs its test.
    allowed = containers.run(options, run_args("allowed.xml", "touch", "allowed"))
    assert allowed.returncode == 0, allowed.stdout + allowed.stderr
    assert (results / "allowed").exists()

    refused = containers.run([*options, "-e", "ROS_DOMAIN_ID=5"], run_args("t.xml", "touch", "ran"))
    assert refused.returncode == 2, refused.stdout + refused.stderr
    assert not (results / "ran").exists(), "a refused test must not run"
    line = the_error_line(refused)
    on_host = run_cli(["run", "--", "true"], {**env, "ROS_DOMAIN_ID": "5"})
    assert on_host.returncode == 2
    assert line == the_error_line(on_host)
    case = load_result(results / "t.xml").only
    assert case.outcome == "failure", case
    assert "ROS_DOMAIN_ID is already set to '5'" in case.text, case

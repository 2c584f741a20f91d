"""Shared fixtures: every test gets its own lock directory and a clean ROS environment."""

from __future__ import annotations

import atexit
import contextlib
import os
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
from helpers import busy_machine, capabilities, domains
from helpers.commands import BIN, CLI, HUNG, POLICY_VARS
from helpers.distros import JAZZY, KILTED, Distro, Tools
from helpers.domains import free_ids
from helpers.processes import Children
from helpers.workspace import CrosstalkBuilds

from ros_isolated_test.process import reaper

#: Strict mode, as CI runs the suite: any skip fails (``pytest --no-skips`` does the same).
NO_SKIPS_ENV = "ROS_ISOLATED_TEST_NO_SKIPS"
#: ros_isolated_test.colcon.switch.VARIABLE (not imported: colcon's side stays out of the way).
COLCON_SWITCH = "ROS_ISOLATED_TEST_COLCON"


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--no-skips",
        action="store_true",
        help="strict mode (CI): a skipped test fails, with its reason; CI has every capability "
        f"(also {NO_SKIPS_ENV}=1)",
    )


@pytest.hookimpl(tryfirst=True)
def pytest_configure(config: pytest.Config) -> None:
    """The suite's own sessions hold no ID: the root package.xml makes this checkout a ROS
    package, where the plugin would hold one for each session (the tests take their own).

    Called before the plugin's own hook (a conftest registers after it); an explicit
    ``--ros-isolation`` still wins. pytest runs of the examples load no conftest of ours.
    """
    if config.getoption("ros_isolation", None) is None:
        config.option.ros_isolation = False
    # colcon's extension of ours is off for every colcon the suite starts (their controls
    # build without us); tests/e2e/test_colcon_extension.py turns it on where it tests it.
    os.environ.setdefault(COLCON_SWITCH, "off")


#: The xdist group of the ros and colcon tests: one session runs them, one at a time.
ONE_AT_A_TIME = "ros-and-colcon"


@pytest.hookimpl(tryfirst=True)  # before xdist reads the groups
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Under ``--dist loadgroup`` (scripts/test.sh): every ros and colcon test in one group.

    They run one at a time in one session, as on a developer's machine, while the other
    session runs every other module whole (as ``--dist loadfile`` would): two sessions are
    two users of one machine, which every test must bear. Without loadgroup, no effect.
    """
    for item in items:
        heavy = item.get_closest_marker("ros") or item.get_closest_marker("colcon")
        group = ONE_AT_A_TIME if heavy else item.nodeid.split("::", 1)[0]
        item.add_marker(pytest.mark.xdist_group(group))


def _strict(config: pytest.Config) -> bool:
    return bool(config.getoption("--no-skips")) or os.environ.get(NO_SKIPS_ENV) == "1"


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Iterator[None]:
    """In strict mode a skip is a failure: CI has root, unshare and the outside tier."""
    outcome = yield
    report: pytest.TestReport = outcome.get_result()  # type: ignore[attr-defined]
    if report.skipped and _strict(item.config) and not hasattr(report, "wasxfail"):
        longrepr = report.longrepr
        reason = longrepr[2] if isinstance(longrepr, tuple) else str(longrepr)
        report.outcome = "failed"
        report.longrepr = f"strict mode (--no-skips): this test was skipped: {reason}"
    scene = item.config.stash.get(_SCENE, None)
    if report.failed and scene is not None:
        report.sections.append(("busy machine", scene))


#: What the busy-machine scene holds, for the reports of failing tests.
_SCENE = pytest.StashKey[str]()


@pytest.fixture(scope="session", autouse=True)
def _busy_machine(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[None]:
    """Every test runs on a machine that runs other ROS work: real holders of real IDs.

    Runners in the default lock directory on the lowest free IDs, upstream's port
    coordinator, a process with ROS_DOMAIN_ID=7 and an rclpy node on an ID its code
    chose (see helpers/busy_machine.py), for
    the whole session: a test that assumes an ID is free, or the machine empty, fails.
    """
    if os.environ.get(busy_machine.QUIET_ENV) == "1" and not _strict(request.config):
        yield  # debugging only: strict mode (CI) always has the scene
        return
    scene = busy_machine.build(BIN, tmp_path_factory.mktemp("busy-machine"))
    atexit.register(scene.stop)  # an interrupt that skips fixture teardown
    try:
        described = scene.describe()
        request.config.stash[_SCENE] = described
        capture = request.config.pluginmanager.getplugin("capturemanager")
        with capture.global_and_fixture_disabled() if capture else contextlib.nullcontext():
            print(f"\n{described}", flush=True)
        yield
    finally:
        scene.stop()


@pytest.fixture(autouse=True)
def _id_claims() -> Iterator[None]:
    """The IDs a test picked (helpers/domains.py) stay its own until it ends, then free."""
    yield
    domains.release_claims()


@pytest.fixture
def lock_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A lock directory of the test's own, so tests never contend with other runs."""
    return tmp_path_factory.mktemp("locks")


def _runner_env(lock_dir: Path) -> dict[str, str]:
    clean = {key: value for key, value in os.environ.items() if key not in POLICY_VARS}
    clean["ROS_ISOLATED_TEST_LOCK_DIR"] = str(lock_dir)
    clean["PATH"] = f"{BIN}{os.pathsep}{clean.get('PATH', '')}"
    return clean


@pytest.fixture
def env(lock_dir: Path) -> dict[str, str]:
    """The environment for runner processes: no ROS_DOMAIN_ID, our own lock dir."""
    return _runner_env(lock_dir)


@pytest.fixture(scope="module")
def module_env(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """``env`` for a module whose tests share one folder of results (one lock dir)."""
    return _runner_env(tmp_path_factory.mktemp("locks"))


@pytest.fixture(autouse=True)
def _isolated_process_env(lock_dir: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """In-process calls see the same clean environment as subprocesses."""
    for name in POLICY_VARS:
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("ROS_ISOLATED_TEST_LOCK_DIR", str(lock_dir))
    yield


@pytest.fixture(autouse=True)
def _subreaper_restored() -> Iterator[None]:
    """pytest's process adopts no orphans after a test that ran the supervisor in process.

    ``supervisor.run`` makes its process a subreaper for good (the runner's is short-lived):
    left on, every process a later test orphans would come back to pytest, which a test
    of who started a process (a squatter is nobody's child) then reads wrongly.
    """
    was = reaper.is_subreaper()
    yield
    if not was:
        reaper.stop_subreaper()


@pytest.fixture(scope="session")
def runner_script() -> str:
    """The ctest RUNNER script, as ``ros-isolated-test runner-path`` prints it."""
    return subprocess.run(
        [CLI, "runner-path"], check=True, capture_output=True, text=True
    ).stdout.strip()


@pytest.fixture
def children() -> Iterator[Children]:
    """Child processes of this test (holders, waiters); whatever still runs is killed."""
    spawned = Children()
    yield spawned
    spawned.kill_all()


@pytest.fixture
def traversable_dir(tmp_path: Path) -> Iterator[Path]:
    """pytest's tmp dirs are private to root; other users need a way in to share locks."""
    capabilities.require(capabilities.OTHER_USERS)
    shared = Path(os.environ.get("TMPDIR", "/tmp")) / f"rit-shared-{os.getpid()}-{tmp_path.name}"
    shared.mkdir(mode=0o777)
    os.chmod(shared, 0o777)
    try:
        yield shared
    finally:
        shutil.rmtree(shared, ignore_errors=True)


@pytest.fixture(scope="session")
def crosstalk_builds(tmp_path_factory: pytest.TempPathFactory) -> CrosstalkBuilds:
    """The example package, built once per runner for the whole session (colcon is slow).

    Tests run ``colcon test`` on these builds one after another (each clears the last
    run's results first); a test that needs a changed package copies what it needs.
    """
    capabilities.require(capabilities.COLCON)
    return CrosstalkBuilds(tmp_path_factory.mktemp("crosstalk_ws"))


@pytest.fixture(
    scope="module",
    params=[
        pytest.param(JAZZY, id="jazzy"),
        pytest.param(KILTED, id="kilted", marks=capabilities.KILTED.mark),
    ],
)
def distro(request: pytest.FixtureRequest) -> Distro:
    """Each ROS 2 distro the suite supports: a test that asks for it runs on each.

    Jazzy is the suite's own venv; Kilted is .venv-kilted (skipped, or failed in strict
    mode, when scripts/setup.sh has not made it).
    """
    chosen: Distro = request.param
    return chosen


@pytest.fixture(scope="module")
def tools(distro: Distro) -> Tools:
    """How to run our CLI and RUNNER on ``distro`` (Jazzy's: the suite's own, unchanged)."""
    return Tools.on(distro)


@pytest.fixture(scope="module")
def distro_runner_script(tools: Tools) -> str:
    """The RUNNER as the distro's own ``ros-isolated-test runner-path`` prints it."""
    return tools.runner_script()


@pytest.fixture
def distro_env(env: dict[str, str], tools: Tools) -> dict[str, str]:
    """The ``env`` fixture on the distro: as its sourced setup would give, same lock dir."""
    return tools.env(env)


@pytest.fixture
def one_id(env: dict[str, str]) -> dict[str, str]:
    """The runner environment with a pool of one ID that is free now (lock, port, squatter)."""
    (domain_id,) = free_ids(1)
    return {**env, "ROS_ISOLATED_TEST_DOMAINS": str(domain_id)}


@pytest.fixture
def started() -> Iterator[list[subprocess.Popen[bytes]]]:
    """Background processes a test starts (``helpers.commands.start_cli``); ended at its end.

    SIGTERM first: a runner passes it on and ends its test's tree before it exits, where
    SIGKILL would leave the test running, orphaned, on its ID.
    """
    processes: list[subprocess.Popen[bytes]] = []
    yield processes
    for process in processes:
        if process.poll() is None:
            process.terminate()
    for process in processes:
        try:
            process.wait(HUNG)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(HUNG)

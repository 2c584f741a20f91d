"""pytest plugin: a ROS_DOMAIN_ID of its own for each pytest session (each xdist worker).

colcon runs an ament_python package's tests with pytest directly: no ctest RUNNER exists
to wrap them. This plugin (entry point ``ros_isolated_test``, off with ``-p
no:ros_isolated_test`` or ``--no-ros-isolation``) reserves an ID from the machine-wide
coordinator before collection, puts it and the discovery range into ``os.environ``, and
holds it until pytest ends; what the tests left running is ended before the release.
It goes through the runner's own policy, reservation and sweep (runner/session.py), so
a preset ID, DISABLE_ROS_ISOLATION and the pool mean here what they mean there.

Loaded by every pytest run in the environment, so it imports nothing of its own until it
knows it is active: inside a ROS package (a package.xml at or above the rootdir or the
test paths), or asked for with ``--ros-isolation`` or the ``ros_isolation`` ini option.
"""

from __future__ import annotations

import contextlib
import os
import sys
from pathlib import Path

import pytest

INI = "ros_isolation"
#: Seconds the tests' leftover processes get to exit on SIGTERM (the runner's --kill-grace).
KILL_GRACE = 5.0
#: The exit code when no ID became free in time (the runner's, too).
NO_DOMAIN = 3
_ON_WORDS = frozenset({"1", "true", "yes", "on"})
_OFF_WORDS = frozenset({"0", "false", "no", "off"})


class _State:
    """What the plugin decided for this process, and what it holds until pytest ends."""

    def __init__(self) -> None:
        #: Lines for pytest's header (the controller's, or this process's).
        self.header: list[str] = []
        #: Suite properties for pytest's --junit-xml.
        self.properties: list[tuple[str, str]] = []
        self.domain_id: int | None = None
        self.stack = contextlib.ExitStack()


_STATE = pytest.StashKey[_State]()


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("ros_isolated_test", "ROS isolation (ros-isolated-test)")
    group.addoption(
        "--ros-isolation",
        action="store_const",
        const=True,
        dest="ros_isolation",
        default=None,
        help="reserve a ROS_DOMAIN_ID of its own for this session (each xdist worker), "
        "also outside a ROS package; a preset ROS_DOMAIN_ID is then refused",
    )
    group.addoption(
        "--no-ros-isolation",
        action="store_const",
        const=False,
        dest="ros_isolation",
        help="never reserve a ROS_DOMAIN_ID (as -p no:ros_isolated_test)",
    )
    parser.addini(
        INI,
        "ROS isolation: auto (default: on inside a ROS package), true, or false",
        default="auto",
    )


def _requested(config: pytest.Config) -> bool | None:
    """True/False when asked for explicitly (option first, then ini); None: automatic."""
    option: bool | None = config.getoption("ros_isolation")
    if option is not None:
        return option
    word = str(config.getini(INI)).strip().lower()
    if word in _ON_WORDS:
        return True
    if word in _OFF_WORDS:
        return False
    if word not in {"", "auto"}:
        raise pytest.UsageError(f"ini option {INI}={word!r}: use auto, true or false")
    return None


def _in_ros_package(config: pytest.Config) -> bool:
    """A package.xml at or above the rootdir or a path on the command line: colcon's case."""
    starts = [config.rootpath, *(Path(arg.split("::")[0]) for arg in config.args)]
    seen: set[Path] = set()
    for start in starts:
        folder = start.absolute()
        for candidate in (folder, *folder.parents):
            if candidate in seen:
                break
            seen.add(candidate)
            if (candidate / "package.xml").is_file():
                return True
    return False


@pytest.hookimpl(tryfirst=True)
def pytest_configure(config: pytest.Config) -> None:
    """Decide, and reserve before collection (before any test module imports rclpy)."""
    if getattr(config.option, "help", False):
        return  # pytest --help runs no test
    requested = _requested(config)
    if requested is False or (requested is None and not _in_ros_package(config)):
        return
    state = _State()
    config.stash[_STATE] = state
    if not hasattr(config, "workerinput") and getattr(config.option, "dist", "no") != "no":
        state.header.append("ros-isolated-test: each xdist worker reserves a ROS_DOMAIN_ID")
        return  # the controller runs no test
    _isolate(config, state, explicit=requested is True)


def _isolate(config: pytest.Config, state: _State, explicit: bool) -> None:
    from ros_isolated_test.domain_coordinator.lock_dir import LockDirError
    from ros_isolated_test.domain_coordinator.reservation import PoolExhaustedError
    from ros_isolated_test.runner import environment, session, settings
    from ros_isolated_test.runner.discovery import DiscoveryError

    environ = os.environ
    domain = environ.get(environment.DOMAIN_VAR)
    if environment.held_for_us(environ):
        # Under our runner (a RUNNER that started pytest): its ID, its cleanup.
        state.header.append(f"ros-isolated-test: ROS_DOMAIN_ID {domain}, held by the runner")
        state.properties.append(("ros_domain_id", str(domain)))
        return
    try:
        config_settings = settings.read(environ)
        policy = environment.decide((), config_settings, environ)
    except environment.RefusedError as refusal:
        if explicit:
            raise pytest.UsageError(f"ros-isolated-test: {refusal}") from None
        state.header.append(
            f"ros-isolated-test: ROS_DOMAIN_ID is already set to {domain!r}: left as it is, "
            "this session is NOT isolated (unset it to isolate; --ros-isolation refuses it)"
        )
        state.properties.append(("ros_domain_id", f"{domain} (preset, not isolated)"))
        return
    except (settings.SettingsError, DiscoveryError) as error:
        raise pytest.UsageError(f"ros-isolated-test: {error}") from None
    state.header.extend(f"ros-isolated-test: {note}" for note in policy.notes)
    command = ("pytest", *config.invocation_params.args)
    try:
        held = state.stack.enter_context(
            session.isolation(policy, config_settings, command, _note, KILL_GRACE)
        )
    except (PoolExhaustedError, LockDirError) as error:
        pytest.exit(f"ros-isolated-test: error: {error}", returncode=NO_DOMAIN)
    if held is None:
        state.properties.append(("ros_domain_id", f"{domain or 'unset (0)'} (isolation disabled)"))
        return
    state.domain_id = held.domain_id
    _set_environ(policy.for_domain(held.domain_id))
    line = f"ros-isolated-test: ROS_DOMAIN_ID {held.domain_id}"
    if policy.discovery is not None:
        line += f", {policy.discovery.describe()}"
        state.properties.extend(policy.discovery.properties().items())
        state.header.extend(f"ros-isolated-test: {w}" for w in policy.discovery.warnings)
    state.header.insert(0, line)
    state.properties.insert(0, ("ros_domain_id", str(held.domain_id)))
    workeroutput = getattr(config, "workeroutput", None)
    if workeroutput is not None:
        workeroutput["ros_domain_id"] = held.domain_id


def _set_environ(env: dict[str, str]) -> None:
    """Make os.environ the test environment the policy built (set and removed alike)."""
    for name in [name for name in os.environ if name not in env]:
        del os.environ[name]
    for name, value in env.items():
        if os.environ.get(name) != value:
            os.environ[name] = value


def _note(line: str) -> None:
    """Waiting for an ID, processes ended: said on stderr, which pytest does not capture here."""
    print(f"ros-isolated-test: {line}", file=sys.stderr, flush=True)


def pytest_report_header(config: pytest.Config) -> list[str]:
    state = config.stash.get(_STATE, None)
    return [] if state is None else state.header


def pytest_sessionstart(session: pytest.Session) -> None:
    """The ID as a suite property of pytest's own --junit-xml."""
    state = session.config.stash.get(_STATE, None)
    if (
        state is None
        or not state.properties
        or getattr(session.config.option, "xmlpath", None) is None
    ):
        return
    from _pytest.junitxml import xml_key

    xml = session.config.stash.get(xml_key, None)
    if xml is not None:  # None in an xdist worker: the controller writes the file
        for name, value in state.properties:
            xml.add_global_property(name, value)


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node: object, error: object) -> None:
    """The xdist controller: each worker's ID into the controller's --junit-xml."""
    config: pytest.Config | None = getattr(node, "config", None)
    output = getattr(node, "workeroutput", None)
    if config is None or not output or "ros_domain_id" not in output:
        return
    if config.stash.get(_STATE, None) is None or getattr(config.option, "xmlpath", None) is None:
        return
    from _pytest.junitxml import xml_key

    xml = config.stash.get(xml_key, None)
    worker = getattr(node, "gateway", None)
    name = getattr(worker, "id", "worker")
    if xml is not None:
        xml.add_global_property(f"ros_domain_id.{name}", str(output["ros_domain_id"]))


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config: pytest.Config) -> None:
    """End what the tests left running, block survivors, release: the runner's order."""
    state = config.stash.get(_STATE, None)
    if state is not None:
        state.stack.close()

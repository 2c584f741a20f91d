"""pytest plugin: a ROS_DOMAIN_ID of its own for each pytest session (each xdist worker).

colcon runs an ament_python package's tests with pytest directly: no ctest RUNNER exists
to wrap them. This plugin (entry point ``ros_isolated_test``, off with ``-p
no:ros_isolated_test`` or ``--no-ros-isolation``) reserves an ID from the machine-wide
coordinator before collection, puts it and the discovery range into ``os.environ``, and
holds it until pytest ends; what the tests left running is ended before the release.
It goes through the runner's own policy, reservation and sweep (runner/isolation.py), so
a preset ID, DISABLE_ROS_ISOLATION and the pool mean here what they mean there.
Machine resources (``--ros-isolated-test-resources``, ini ``ros_isolated_test_resources``)
are held with the ID by the same reservation, for the whole session (each xdist worker).

Loaded by every pytest run in the environment, so it imports nothing of its own but its
options (plugin_options.py, light) until it knows it is active: inside a ROS package (a
package.xml at or above the rootdir or the test paths), or asked for with
``--ros-isolation`` or the ``ros_isolation`` ini option.
Where launch_testing's own plugin is loaded, its launch files are reported case by case
(launch_cases.py, whatever isolation decides; ``-p no:ros_isolated_test`` turns it off).
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Generator
from typing import Any

import pytest

TYPE_CHECKING = False  # nothing of the runner is imported until the plugin is active
if TYPE_CHECKING:
    from ros_isolated_test.runner.environment import Policy
    from ros_isolated_test.runner.isolation import Lease
    from ros_isolated_test.runner.settings import Settings

#: Where a worker tells the xdist controller it got no ID (the controller exits with it).
_ERROR_KEY = "ros_isolation_error"


class _State:
    """What the plugin decided for this process, and what it holds until pytest ends."""

    def __init__(self) -> None:
        #: Lines for pytest's header (the controller's, or this process's).
        self.header: list[str] = []
        #: Suite properties for pytest's --junit-xml.
        self.properties: list[tuple[str, str]] = []
        self.stack = contextlib.ExitStack()
        #: No ID could be had (an xdist worker reports it instead of crashing).
        self.error: str | None = None
        #: The ID is being released: a signal now must not cut the sweep short.
        self.closing = False
        #: A signal ended the session (an xdist process: later ones only noted).
        self.interrupted = False
        #: The xdist controller: each local worker (its WorkerController) and PID.
        self.workers: list[tuple[Any, int]] = []
        #: The xdist controller, interrupted: a second signal stops its wait for the workers.
        self.hurry = False


_STATE = pytest.StashKey[_State]()


def pytest_addoption(parser: pytest.Parser) -> None:
    """The plugin's options and ini options (plugin_options.py)."""
    from ros_isolated_test import plugin_options

    plugin_options.add(parser)


@pytest.hookimpl(tryfirst=True)
def pytest_configure(config: pytest.Config) -> None:
    """Decide, and reserve before collection (before any test module imports rclpy)."""
    if "launch_testing.pytest.hooks" in sys.modules:  # its launch files: case by case
        from ros_isolated_test import launch_cases

        if not config.pluginmanager.has_plugin(launch_cases.PLUGIN_NAME):
            config.pluginmanager.register(launch_cases, launch_cases.PLUGIN_NAME)
    from ros_isolated_test import plugin_options

    explicit = plugin_options.decide(config)
    if explicit is None:
        return
    state = _State()
    config.stash[_STATE] = state
    controller = not hasattr(config, "workerinput") and getattr(config.option, "dist", "no") != "no"
    _isolate(config, state, explicit=explicit, controller=controller)


def _isolate(config: pytest.Config, state: _State, explicit: bool, controller: bool) -> None:
    """The runner's decision, then (but in the xdist controller, which runs no test) its ID."""
    from ros_isolated_test import plugin_options
    from ros_isolated_test.domain_coordinator.lock_dir import LockDirError
    from ros_isolated_test.domain_coordinator.resource_holds import CapacityConflictError
    from ros_isolated_test.domain_coordinator.waiting import PoolExhaustedError
    from ros_isolated_test.process.namespace import NamespaceError
    from ros_isolated_test.process.supervisor import KILL_GRACE
    from ros_isolated_test.runner import environment, exit_codes, settings, summary
    from ros_isolated_test.runner.discovery import DiscoveryError
    from ros_isolated_test.runner.isolation import isolation

    environ = os.environ
    asked, asked_by = plugin_options.resources(config)
    if environment.held_for_us(environ):
        _under_the_runner(state, environ.get(environment.DOMAIN_VAR), asked, asked_by)
        return
    try:
        # reruns=0: the plugin never reruns, so a bad ROS_ISOLATED_TEST_RERUNS (for `run`)
        # must not fail the session. Resources: only what pytest's option or ini asks.
        config_settings = settings.read(
            environ, reruns=0, resources=asked, resources_origin=asked_by
        )
        # The tests run in this process (it enters any namespaces itself); xdist's workers
        # run threads, so they cannot.
        xdist = controller or hasattr(config, "workerinput")
        policy = environment.decide((), config_settings, environ, in_process=True, xdist=xdist)
    except environment.RefusedError as refusal:
        if explicit or refusal.variable == settings.ISOLATION_ENV:  # namespaces asked for
            raise pytest.UsageError(f"ros-isolated-test: {refusal}") from None
        _left_alone(state, refusal.variable)
        return
    except (settings.SettingsError, DiscoveryError) as error:
        raise pytest.UsageError(f"ros-isolated-test: {error}") from None
    if not policy.isolate and not config_settings.resources:
        lines, properties = summary.summary(policy, None)
        state.header.extend(f"ros-isolated-test: {line}" for line in lines)
        state.properties.extend(properties.items())
        return
    worker = hasattr(config, "workerinput")
    if controller:
        _for_each_worker(state, policy, config_settings)
        _interruptible(state, once=True)  # passed on to the workers, which hold the IDs
        return  # the controller runs no test
    _interruptible(state, once=worker)
    command = ("pytest", *config.invocation_params.args)
    try:
        held = state.stack.enter_context(
            isolation(policy, config_settings, command, _note, KILL_GRACE)
        )
    except (PoolExhaustedError, LockDirError, CapacityConflictError) as error:
        state.error = f"ros-isolated-test: error: {error}"
        if worker:
            return  # said to the controller (pytest_collection): a crash would be restarted
        pytest.exit(state.error, returncode=exit_codes.NO_DOMAIN)
    except NamespaceError as error:  # probed allowed, then refused to this process
        raise pytest.UsageError(f"ros-isolated-test: {policy.refusal(error)}") from None
    assert held is not None  # isolated, or resources held without an ID
    _holding(config, state, policy, config_settings, held)


def _under_the_runner(state: _State, domain: str | None, asked: str, asked_by: str) -> None:
    """A RUNNER of ours started pytest: its ID, its resources, its cleanup."""
    state.header.append(f"ros-isolated-test: ROS_DOMAIN_ID {domain}, held by the runner")
    state.properties.append(("ros_domain_id", str(domain)))
    if asked.strip():
        # Asking again here would wait for what the runner may hold already.
        state.header.append(
            f"ros-isolated-test: {asked_by} ({asked.strip()}) not held by the plugin: "
            "the runner holds what it was asked (CMake RESOURCES, ENV ROS_ISOLATED_TEST_RESOURCES)"
        )


def _for_each_worker(state: _State, policy: Policy, config_settings: Settings) -> None:
    """The xdist controller's header: what each worker will hold (it holds nothing itself)."""
    from ros_isolated_test.domain_coordinator.resources import describe
    from ros_isolated_test.runner import summary

    if not policy.isolate:
        lines, _properties = summary.summary(policy, None)
        state.header.extend(f"ros-isolated-test: {line}" for line in lines)
    each = ["a ROS_DOMAIN_ID"] if policy.isolate else []
    if config_settings.resources:
        each.append(describe(config_settings.resources))
    state.header.append(f"ros-isolated-test: each xdist worker reserves {' and '.join(each)}")
    if policy.fallback is not None:  # isolation auto: the workers cannot enter namespaces
        state.header.append(
            f"ros-isolated-test: isolation auto: by the domain ID alone, {policy.fallback}"
        )


def _holding(
    config: pytest.Config, state: _State, policy: Policy, config_settings: Settings, held: Lease
) -> None:
    """Into os.environ, pytest's header and --junit-xml: the ID and resources now held."""
    from ros_isolated_test.runner import summary

    if held.domain_id is None:  # DISABLE_ROS_ISOLATION: the resources alone
        lines, properties = summary.summary(policy, None)
    else:
        # Restored first on the way out (LIFO): before the sweep and the release.
        state.stack.callback(_set_environ, dict(os.environ))
        _set_environ(policy.for_domain(held.domain_id))
        lines, properties = summary.summary(policy, held.domain_id, config_settings, held.reserved)
        if policy.discovery is not None:  # its first line: the range, said beside the ID
            lines[0] = f"ROS_DOMAIN_ID {held.domain_id}, {lines[0]}"
        else:
            lines.insert(0, f"ROS_DOMAIN_ID {held.domain_id}")
    if held.resources:  # said right after the ID, as the runner says it
        line, more = summary.resources_summary(held, config_settings)
        lines.insert(1, line)
        properties.update(more)
    state.header.extend(f"ros-isolated-test: {line}" for line in lines)
    state.properties.extend(properties.items())
    workeroutput = getattr(config, "workeroutput", None)
    if workeroutput is not None and held.domain_id is not None:
        workeroutput["ros_domain_id"] = held.domain_id


def _left_alone(state: _State, name: str) -> None:
    """Automatic mode met a preset (ROS_DOMAIN_ID, a Gazebo partition): not isolated, said so."""
    from ros_isolated_test.runner.environment import DOMAIN_VAR

    preset = os.environ.get(name)
    state.header.append(
        f"ros-isolated-test: {name} is already set to {preset!r}: left as it is, "
        "this session is NOT isolated (unset it to isolate; --ros-isolation refuses it)"
    )
    property_name = "ros_domain_id" if name == DOMAIN_VAR else "gz_partition"
    state.properties.append((property_name, f"{preset} (preset, not isolated)"))


def _interruptible(state: _State, once: bool = False) -> None:
    """SIGTERM and SIGHUP (ctest's, colcon's timeout, a CI cancel) end pytest as Ctrl-C does.

    Without this pytest dies at once: no unconfigure, so what the tests left running is
    never ended (a plain fork even inherits the lock) and the ID stays held. Once the
    release began, a signal is ignored: a second Ctrl-C must not cut the sweep short.
    With xdist the workers hold the IDs: the controller passes each signal on to them
    (else they learn of its end only from execnet, 5 s later, and are killed mid-sweep 10 s
    later), then waits for them (pytest_sessionfinish). There a signal may come twice
    (from the process group and passed on): with ``once`` only the first interrupts.
    Outside the main thread (an embedding program) its own handlers stay.
    """
    from ros_isolated_test.process import signals

    def stop(signum: int, _frame: object) -> None:
        passed_on = _pass_on(state, signum)
        if state.closing:
            _note(f"signal {signum} ignored: ending what the tests left running first")
        elif once and state.interrupted:
            if passed_on:
                state.hurry = True  # the controller: no longer waits for its workers
            what = "passed on to the xdist workers" if passed_on else "ignored"
            _note(f"signal {signum} {what}: the session is already ending")
        else:
            state.interrupted = True
            raise KeyboardInterrupt(f"signal {signum}")

    previous = signals.set_handlers(stop)
    state.stack.callback(signals.restore_handlers, previous)


def _pass_on(state: _State, signum: int) -> bool:
    """The xdist controller: ``signum`` to each local worker still running; any sent?"""
    from ros_isolated_test.process import proc

    sent = False
    for _node, pid in state.workers:
        stat = proc.read_stat(pid)
        # Still our child, so its PID names no later process (it is not reaped yet).
        if stat is None or not stat.alive or stat.ppid != os.getpid():
            continue
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signum)
            sent = True
    return sent


def _wait_for_workers(state: _State) -> None:
    """The interrupted xdist controller: until each worker has ended its leftovers.

    That is, until its pytest ended (its channel closed), its ID released; a second
    signal stops the wait. xdist's teardown, which follows, kills a worker still
    running 10 s after it began. Each is also told to run no further test, as xdist
    does when it stops (a test may have swallowed the interrupt).
    """
    for node, _pid in state.workers:
        with contextlib.suppress(Exception):  # gone already: nothing to tell
            node.shutdown()
    for node, _pid in state.workers:
        channel = getattr(node, "channel", None)
        while channel is not None and not state.hurry and not _closed(channel):
            pass


def _closed(channel: Any) -> bool:
    """An execnet channel closed within 0.1 s (a signal's handler runs meanwhile)."""
    try:
        channel.waitclose(0.1)
    except channel.TimeoutError:
        return False
    except Exception:  # closed with the worker's error, which xdist reports
        return True
    return True


def _set_environ(env: dict[str, str]) -> None:
    """Make os.environ ``env`` exactly (set and removed alike)."""
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


@pytest.hookimpl(tryfirst=True)
def pytest_collection(session: pytest.Session) -> None:
    """An xdist worker that got no ID ends here, its error in the controller's hands.

    Not in pytest_configure: a worker dying there is a crash, which xdist restarts (each
    restart waiting the whole timeout again). Ending now still sends the controller its
    workeroutput.
    """
    state = session.config.stash.get(_STATE, None)
    output = getattr(session.config, "workeroutput", None)
    if state is not None and state.error is not None and output is not None:
        output[_ERROR_KEY] = state.error
        from ros_isolated_test.runner import exit_codes

        session.shouldstop = state.error  # the controller stops every worker
        pytest.exit(state.error, returncode=exit_codes.NO_DOMAIN)  # 2 would be a restart


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node: object, error: object) -> None:
    """The xdist controller: each worker's ID into the controller's --junit-xml."""
    config: pytest.Config | None = getattr(node, "config", None)
    output = getattr(node, "workeroutput", None)
    if config is None or not output:
        return
    state = config.stash.get(_STATE, None)
    if state is None:
        return
    if _ERROR_KEY in output and state.error is None:
        state.error = str(output[_ERROR_KEY])
    if "ros_domain_id" not in output or getattr(config.option, "xmlpath", None) is None:
        return
    from _pytest.junitxml import xml_key

    xml = config.stash.get(xml_key, None)
    worker = getattr(node, "gateway", None)
    name = getattr(worker, "id", "worker")
    if xml is not None:
        xml.add_global_property(f"ros_domain_id.{name}", str(output["ros_domain_id"]))


@pytest.hookimpl(optionalhook=True)
def pytest_configure_node(node: Any) -> None:
    """The xdist controller: each local worker's PID, to pass a signal on to it."""
    state = node.config.stash.get(_STATE, None)
    spec = node.gateway.spec
    if state is None or not spec.popen or spec.via:
        return  # nothing to pass on, or a process of another host
    try:
        pid = int(node.gateway._rinfo().pid)  # asked by xdist just before: no round trip
    except Exception:  # an execnet without it: the worker learns of the end from execnet
        return
    state.workers.append((node, pid))


@pytest.hookimpl(hookwrapper=True, trylast=True)
def pytest_sessionfinish(session: pytest.Session) -> Generator[None, None, None]:
    """Release when the session ends, after the fixtures' teardown, whatever raised in it.

    Not only at unconfigure, which pytest skips when a sessionfinish hook raises: as
    xdist's does in a worker whose controller is gone (its report cannot be sent). So a
    worker has released before it reports its end (this wrapper is inside xdist's). An
    interrupted xdist controller first waits for its workers, before xdist's teardown.
    """
    config = session.config
    state = config.stash.get(_STATE, None)
    if state is not None and state.interrupted:
        _wait_for_workers(state)
    yield
    if state is None:
        return
    if state.error is not None and not hasattr(config, "workerinput"):
        # The xdist controller: a worker that got no ID makes the run's code the runner's.
        from ros_isolated_test.runner import exit_codes

        _note(state.error.removeprefix("ros-isolated-test: "))
        session.exitstatus = exit_codes.NO_DOMAIN
    _release(state)


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config: pytest.Config) -> None:
    """Release, if the session never finished (an error before it started)."""
    state = config.stash.get(_STATE, None)
    if state is not None:
        _release(state)


def _release(state: _State) -> None:
    """End what the tests left running, block survivors, release: the runner's order."""
    state.closing = True  # a signal now is only noted
    state.stack.close()

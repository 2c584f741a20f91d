"""What a pytest session holds: the runner's decision, its ID and resources, and their release.

Reserved in pytest_configure, before collection (before any test module imports rclpy),
through the runner's own policy, reservation and sweep (runner/isolation.py), so a preset
ID, DISABLE_ROS_ISOLATION and the pool mean here what they mean there. The ID and the
discovery range go into ``os.environ``; pytest's header and ``--junit-xml`` say them.
Machine resources (``--ros-isolated-test-resources``, ini ``ros_isolated_test_resources``)
are held with the ID by the same reservation, for the whole session (each xdist worker).
At the end, what the tests left running is ended, then everything is released: the
runner's order. Imported only once the plugin is active (plugin.py decides).
"""

from __future__ import annotations

import contextlib
import os

import pytest

from ros_isolated_test.pytest_plugin import options
from ros_isolated_test.pytest_plugin.interrupts import Interrupts, note

TYPE_CHECKING = False
if TYPE_CHECKING:
    from ros_isolated_test.runner.environment import Policy
    from ros_isolated_test.runner.isolation import Lease
    from ros_isolated_test.runner.settings import Settings

#: Where a worker tells the xdist controller it got no ID (the controller exits with it).
ERROR_KEY = "ros_isolation_error"
#: pytest's exit code when no ID (or not the resources asked for) became free in time, or
#: the lock directory is unusable: nothing was run. pytest's own codes are 0 to 5
#: (``pytest.ExitCode``), so the runner's 3 would read as pytest's INTERNAL_ERROR; this
#: is sysexits.h's EX_TEMPFAIL (a temporary failure: try again later), which neither
#: pytest nor the runner uses. A refusal (a preset ID, a bad setting) is pytest's usage
#: error, 4; a signal pytest's 2 (docs/reference.md, "The pytest plugin's exit codes").
NO_ID_EXIT = 75


class State:
    """What the plugin decided for this process, and what it holds until pytest ends."""

    def __init__(self) -> None:
        #: Lines for pytest's header (the controller's, or this process's).
        self.header: list[str] = []
        #: Suite properties for pytest's --junit-xml.
        self.properties: list[tuple[str, str]] = []
        self.stack = contextlib.ExitStack()
        #: No ID could be had (an xdist worker reports it instead of crashing).
        self.error: str | None = None
        self.interrupts = Interrupts()


def isolate(config: pytest.Config, state: State, explicit: bool, controller: bool) -> None:
    """The runner's decision, then (but in the xdist controller, which runs no test) its ID."""
    from ros_isolated_test.not_run import NotRun
    from ros_isolated_test.process.namespace import NamespaceError
    from ros_isolated_test.process.supervisor import KILL_GRACE
    from ros_isolated_test.runner import environment, exit_codes, settings, summary
    from ros_isolated_test.runner.isolation import isolation

    environ = os.environ
    asked, asked_by = options.resources(config)
    if environment.held_for_us(environ):
        _under_the_runner(state, environ.get(environment.DOMAIN_VAR), asked, asked_by)
        return
    try:
        # reruns=0: the plugin never reruns, so a bad ROS_ISOLATED_TEST_RERUNS (for `run`)
        # or ROS_ISOLATED_TEST_RERUNS_FLAKY must not fail the session. Resources: only what
        # pytest's option or ini asks.
        config_settings = settings.read(
            environ, reruns=0, resources=asked, resources_origin=asked_by, reruns_flaky=0
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
    except NotRun as error:  # a bad setting, a discovery that cannot be had
        raise pytest.UsageError(f"ros-isolated-test: {error}") from None
    if not policy.isolate and not config_settings.resources:
        lines, properties = summary.summary(policy, None)
        state.header.extend(f"ros-isolated-test: {line}" for line in lines)
        state.properties.extend(properties.items())
        return
    worker = hasattr(config, "workerinput")
    if controller:
        _for_each_worker(state, policy, config_settings)
        state.interrupts.catch(state.stack, once=True)  # passed on to the workers' IDs
        return  # the controller runs no test
    state.interrupts.catch(state.stack, once=worker)
    command = ("pytest", *config.invocation_params.args)
    try:
        held = state.stack.enter_context(
            isolation(policy, config_settings, command, note, KILL_GRACE)
        )
    except NotRun as error:
        if exit_codes.plugin_code(error) != NO_ID_EXIT:  # capacities that disagree
            raise pytest.UsageError(f"ros-isolated-test: {error}") from None
        state.error = f"ros-isolated-test: error: {error}"
        if worker:
            return  # said to the controller (pytest_collection): a crash would be restarted
        pytest.exit(state.error, returncode=NO_ID_EXIT)
    except NamespaceError as error:  # probed allowed, then refused to this process
        raise pytest.UsageError(f"ros-isolated-test: {policy.refusal(error)}") from None
    assert held is not None  # isolated, or resources held without an ID
    _holding(config, state, policy, config_settings, held)


def _under_the_runner(state: State, domain: str | None, asked: str, asked_by: str) -> None:
    """A RUNNER of ours started pytest: its ID, its resources, its cleanup."""
    state.header.append(f"ros-isolated-test: ROS_DOMAIN_ID {domain}, held by the runner")
    state.properties.append(("ros_domain_id", str(domain)))
    if asked.strip():
        # Asking again here would wait for what the runner may hold already.
        state.header.append(
            f"ros-isolated-test: {asked_by} ({asked.strip()}) not held by the plugin: "
            "the runner holds what it was asked (CMake RESOURCES, ENV ROS_ISOLATED_TEST_RESOURCES)"
        )


def _for_each_worker(state: State, policy: Policy, config_settings: Settings) -> None:
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
    config: pytest.Config, state: State, policy: Policy, config_settings: Settings, held: Lease
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
        first = f"ROS_DOMAIN_ID {held.domain_id}{summary.replacing(policy)}"  # as the runner's
        if policy.discovery is not None:  # its first line: the range, said beside the ID
            lines[0] = f"{first}, {lines[0]}"
        else:
            lines.insert(0, first)
    if held.resources:  # said right after the ID, as the runner says it
        line, more = summary.resources_summary(held, config_settings)
        lines.insert(1, line)
        properties.update(more)
    state.header.extend(f"ros-isolated-test: {line}" for line in lines)
    state.properties.extend(properties.items())
    workeroutput = getattr(config, "workeroutput", None)
    if workeroutput is not None and held.domain_id is not None:
        workeroutput["ros_domain_id"] = held.domain_id


def _left_alone(state: State, name: str) -> None:
    """Automatic mode met a preset (ROS_DOMAIN_ID, a Gazebo partition): not isolated, said so."""
    from ros_isolated_test.runner.environment import DOMAIN_VAR

    preset = os.environ.get(name)
    state.header.append(
        f"ros-isolated-test: {name} is already set to {preset!r}: left as it is, "
        "this session is NOT isolated (unset it to isolate; --ros-isolation refuses it)"
    )
    property_name = "ros_domain_id" if name == DOMAIN_VAR else "gz_partition"
    state.properties.append((property_name, f"{preset} (preset, not isolated)"))


def _set_environ(env: dict[str, str]) -> None:
    """Make os.environ ``env`` exactly (set and removed alike)."""
    for name in [name for name in os.environ if name not in env]:
        del os.environ[name]
    for name, value in env.items():
        if os.environ.get(name) != value:
            os.environ[name] = value


def release(state: State) -> None:
    """End what the tests left running, block survivors, release: the runner's order."""
    state.interrupts.closing = True  # a signal now is only noted
    state.stack.close()

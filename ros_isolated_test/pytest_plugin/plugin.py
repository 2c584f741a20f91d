"""pytest plugin: a ROS_DOMAIN_ID of its own for each pytest session (each xdist worker).

colcon runs an ament_python package's tests with pytest directly: no ctest RUNNER exists
to wrap them. This plugin (entry point ``ros_isolated_test``, off with ``-p
no:ros_isolated_test`` or ``--no-ros-isolation``) reserves an ID from the machine-wide
coordinator before collection and holds it until pytest ends (holding.py); SIGTERM and
SIGHUP end the session as Ctrl-C does (interrupts.py). This module holds only pytest's
hooks and hands each to the module that does its work.

Loaded by every pytest run in the environment, so it imports nothing of its own but its
options (options.py, light) until it knows it is active: inside a ROS package (a
package.xml at or above the rootdir or the test paths), or asked for with
``--ros-isolation`` or the ``ros_isolation`` ini option.
Where launch_testing's own plugin is loaded, its launch files are reported case by case
(launch_testing_cases.py); where launch_pytest's is, each of its tests is reported as
itself and a launch that fails is one error (launch_pytest_tests.py). Both whatever
isolation decides (``-p no:ros_isolated_test`` turns them off); pytest-xdist keeps a
launch's tests on one worker (scheduling.py).
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Generator
from typing import Any

import pytest

TYPE_CHECKING = False  # nothing of the runner is imported until the plugin is active
if TYPE_CHECKING:
    from ros_isolated_test.pytest_plugin.holding import State
    from ros_isolated_test.pytest_plugin.shard import Sharding

_STATE: pytest.StashKey[State] = pytest.StashKey()
_SHARDING: pytest.StashKey[Sharding] = pytest.StashKey()


def pytest_addoption(parser: pytest.Parser) -> None:
    """The plugin's options and ini options (options.py)."""
    from ros_isolated_test.pytest_plugin import options

    options.add(parser)


@pytest.hookimpl(tryfirst=True)
def pytest_configure(config: pytest.Config) -> None:
    """Decide, and reserve before collection (before any test module imports rclpy)."""
    if _launch_testing_loaded():  # its launch files: case by case
        from ros_isolated_test.pytest_plugin import launch_testing_cases

        if not config.pluginmanager.has_plugin(launch_testing_cases.PLUGIN_NAME):
            config.pluginmanager.register(launch_testing_cases, launch_testing_cases.PLUGIN_NAME)
    if _launch_pytest_loaded(config):  # each test as itself, a failed launch one error
        from ros_isolated_test.pytest_plugin import launch_pytest_tests

        if not config.pluginmanager.has_plugin(launch_pytest_tests.PLUGIN_NAME):
            tests = launch_pytest_tests.LaunchPytestTests()
            config.pluginmanager.register(tests, launch_pytest_tests.PLUGIN_NAME)
    from ros_isolated_test.pytest_plugin import options

    explicit = options.decide(config)
    _split(config, explicit is not None)  # before isolating: that takes the split's variables
    if explicit is None:
        return
    from ros_isolated_test.pytest_plugin import holding

    state = holding.State()
    config.stash[_STATE] = state
    controller = not hasattr(config, "workerinput") and getattr(config.option, "dist", "no") != "no"
    holding.isolate(config, state, explicit=explicit, controller=controller)


def _split(config: pytest.Config, active: bool) -> None:
    """The session's share of a split, and the naming of its items (shard.py)."""
    from ros_isolated_test.pytest_plugin import shard as sharding

    decided = sharding.decide(config, active)
    if decided is not None:
        config.stash[_SHARDING] = decided
        sharding.leave_record(decided, config)


def _launch_testing_loaded() -> bool:
    return "launch_testing.pytest.hooks" in sys.modules


def _launch_pytest_loaded(config: pytest.Config) -> bool:
    return config.pluginmanager.has_plugin("launch_pytest")


def pytest_report_header(config: pytest.Config) -> list[str]:
    state = config.stash.get(_STATE, None)
    split = config.stash.get(_SHARDING, None)
    return [*([] if state is None else state.header), *([] if split is None else split.header)]


def pytest_sessionstart(session: pytest.Session) -> None:
    """The ID and the share as suite properties of pytest's own --junit-xml."""
    state = session.config.stash.get(_STATE, None)
    split = session.config.stash.get(_SHARDING, None)
    properties = [
        *([] if state is None else state.properties),
        *([] if split is None else split.properties),
    ]
    if not properties or getattr(session.config.option, "xmlpath", None) is None:
        return
    from _pytest.junitxml import xml_key

    xml = session.config.stash.get(xml_key, None)
    if xml is not None:  # None in an xdist worker: the controller writes the file
        for name, value in properties:
            xml.add_global_property(name, value)


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Each item named by its identity; the other shares' items deselected (shard.py).

    Last: the split places what pytest's own selection (``-k``, ``-m``) kept, so a share
    it empties is told apart from a session that selected nothing.
    """
    split = config.stash.get(_SHARDING, None)
    if split is not None:
        from ros_isolated_test.pytest_plugin import shard as sharding

        sharding.select_items(split, config, items)


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
        from ros_isolated_test.pytest_plugin.holding import ERROR_KEY, NO_ID_EXIT

        output[ERROR_KEY] = state.error
        session.shouldstop = state.error  # the controller stops every worker
        pytest.exit(state.error, returncode=NO_ID_EXIT)  # 2 would be a restart


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_protocol(item: pytest.Item) -> None:
    """No test starts once a signal ended the session, though a test caught it."""
    state = item.config.stash.get(_STATE, None)
    if state is not None:
        state.interrupts.stop_if_interrupted()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item) -> Generator[None, Any, None]:
    """An item the plugin names: its run time, to the microsecond, on its teardown's report."""
    outcome = yield
    split = item.config.stash.get(_SHARDING, None)
    if split is not None and split.named:
        from ros_isolated_test.pytest_plugin import shard as sharding

        sharding.timed(item, outcome.get_result())


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node: object, error: object) -> None:
    """The xdist controller: each worker's ID into the controller's --junit-xml."""
    config: pytest.Config | None = getattr(node, "config", None)
    output = getattr(node, "workeroutput", None)
    if config is None or not output:
        return
    split = config.stash.get(_SHARDING, None)
    if split is not None:  # what the worker's split deselected: the controller's exit code
        from ros_isolated_test.pytest_plugin import shard as sharding

        sharding.worker_done(split, output)
    state = config.stash.get(_STATE, None)
    if state is None:
        return
    from ros_isolated_test.pytest_plugin.holding import ERROR_KEY

    if ERROR_KEY in output and state.error is None:
        state.error = str(output[ERROR_KEY])
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
    if state is not None:
        state.interrupts.add_worker(node)


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> Any:
    """A launch's tests as one unit of work (scheduling.py); else xdist's own."""
    launch_pytest = _launch_pytest_loaded(config)
    if not launch_pytest and not _launch_testing_loaded():
        return None
    from ros_isolated_test.pytest_plugin import scheduling

    return scheduling.scheduler(config, log, launch_pytest)


@pytest.hookimpl(hookwrapper=True, trylast=True)
def pytest_sessionfinish(session: pytest.Session) -> Generator[None, None, None]:
    """Release when the session ends, after the fixtures' teardown, whatever raised in it.

    Not only at unconfigure, which pytest skips when a sessionfinish hook raises: as
    xdist's does in a worker whose controller is gone (its report cannot be sent). So a
    worker has released before it reports its end (this wrapper is inside xdist's). An
    interrupted xdist controller first waits for its workers, before xdist's teardown.
    """
    config = session.config
    split = config.stash.get(_SHARDING, None)
    if split is not None:  # a session whose share the split emptied passed: not 5
        from ros_isolated_test.pytest_plugin import shard as sharding

        session.exitstatus = sharding.exit_status(split, session.exitstatus)
    state = config.stash.get(_STATE, None)
    if state is not None and state.interrupts.interrupted:
        state.interrupts.wait_for_workers()
    yield
    if split is not None:  # --junit-xml is written now (junitxml's sessionfinish)
        sharding.complete_record(split, config)
        _record(config, split)
    if state is None:
        return
    from ros_isolated_test.pytest_plugin import holding

    if state.error is not None and not hasattr(config, "workerinput"):
        # The xdist controller: a worker that got no ID makes the run's code the plugin's.
        from ros_isolated_test.pytest_plugin.interrupts import note

        note(state.error.removeprefix("ros-isolated-test: "))
        session.exitstatus = holding.NO_ID_EXIT
    holding.release(state)


def _record(config: pytest.Config, split: Sharding) -> None:
    """With ``ROS_ISOLATED_TEST_HISTORY`` set, the written --junit-xml into the test history.

    Only the file's writer (not an xdist worker) and only for items the plugin names
    (under a runner's ID the runner records the whole test). Recording never raises:
    a database that cannot be used is one warning line, the exit status stays pytest's.
    """
    xmlpath = getattr(config.option, "xmlpath", None)
    if not split.named or not xmlpath or hasattr(config, "workerinput"):
        return
    from ros_isolated_test.runner.settings import history_to_record

    db = history_to_record()  # None under colcon test: colcon records the whole run
    if db is None:
        return
    from pathlib import Path

    from ros_isolated_test.history.record import record_trees

    written = config.invocation_params.dir / Path(xmlpath).expanduser()
    if not written.is_file():
        return
    warning = record_trees(db, [written])
    if warning is not None:
        with contextlib.suppress(OSError, ValueError):
            print(warning, file=sys.stderr, flush=True)


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config: pytest.Config) -> None:
    """Release, if the session never finished (an error before it started)."""
    state = config.stash.get(_STATE, None)
    if state is not None:
        from ros_isolated_test.pytest_plugin import holding

        holding.release(state)

"""launch_pytest files under the plugin: each test as itself, a launch that fails one error.

launch_pytest (pytest-native launch tests: a ``@launch_pytest.fixture`` returns a launch
description, ``@pytest.mark.launch(fixture=...)`` marks the tests that run while it is up,
``shutdown=True`` and the second half of a generator test those that run after it ended)
makes ordinary pytest items, so isolation needs nothing of its own: the launch's
processes inherit the session's ROS_DOMAIN_ID. What this sets right is launch_pytest's
own (Jazzy's, 3.4.3):

- the post-shutdown half of a generator test is an item named ``test_x[shutdown_test]``
  that keeps the node ID of its active half, so pytest-xdist, ``--junit-xml`` and ``-rA``
  see one test twice: here its node ID is its name;
- a launch fixture that raises is an error of each of its tests: here it is one error, on
  the first of them, the others skipped;
- a launch that ends before it is ready to test (its processes could not start, and its
  ``ReadyToTest`` waits for them) leaves launch_pytest waiting for ever: here it is one
  error, on the first of its tests, the others skipped;
- a launch that fails on its own while its tests run (its service returns non-zero: a
  process that could not be started) is checked by launch_pytest only when it is still
  running at its end: here it is one error, at the teardown of its last test, whenever
  it failed.

With pytest-xdist a launch_pytest file's tests stay on one worker (scheduling.py). The
pytest plugin registers this where launch_pytest's plugin is loaded. A launch that is not
as read here (no launch description, two ``ReadyToTest``) is left as launch_pytest runs it.
"""

from __future__ import annotations

import functools
import importlib
import inspect
from collections.abc import Generator, Sequence
from typing import Any

import pytest

#: The name the pytest plugin registers this module's plugin under.
PLUGIN_NAME = "ros_isolated_test.launch_pytest_tests"
#: launch_pytest's name for the post-shutdown half of a generator test.
SHUTDOWN_SUFFIX = "[shutdown_test]"


class _Launch:
    """One launch of a launch_pytest fixture, watched from inside: ready, ended, failed."""

    def __init__(self, fixture: str, description: Any, service: Any) -> None:
        self.fixture = fixture
        self.description = description  # kept alive: its id() is the key
        self.service = service
        self.ready = False
        #: Why it ended before it was ready to test (its Shutdown's reason), else None.
        self.not_ready: str | None = None
        #: It ended while no launch_pytest finalize ran: launch_pytest never checks its code.
        self.ended_alone = False
        #: The one error of its tests, once one of them reported it.
        self.error: BaseException | None = None

    def return_code(self) -> int | None:
        """What its service's run returned, once it did."""
        task = getattr(self.service, "task", None)
        if task is None or not task.done() or task.cancelled() or task.exception() is not None:
            return None
        code = task.result()
        return code if isinstance(code, int) else None


class _OneError:
    """An error several tests would each report: reported by the first, the others skipped."""

    def __init__(self, error: BaseException, what: str) -> None:
        self.error = error  # kept alive: its id() is the key
        self.what = what
        self.carrier: str | None = None


class LaunchPytestTests:
    """The hooks, with what this session learnt of its launches."""

    def __init__(self) -> None:
        self._launches: dict[int, _Launch] = {}  # by id() of the launch description
        self._errors: dict[int, _OneError] = {}  # by id() of the error
        #: The launches whose fixtures were set up for the test being set up.
        self._fresh: list[_Launch] = []
        #: A launch_pytest finalize may run now (a post-shutdown test, a teardown).
        self._finalizing = False

    @pytest.hookimpl(hookwrapper=True)
    def pytest_pycollect_makeitem(
        self, collector: pytest.Collector, name: str, obj: object
    ) -> Generator[None, Any, None]:
        """A post-shutdown half gets the node ID of its name (launch_pytest renamed it)."""
        outcome = yield
        if outcome.excinfo is not None:
            return
        made = outcome.get_result()
        for item in made if isinstance(made, list) else ():
            parent = getattr(item, "parent", None)
            if parent is None or not getattr(item, "_launch_pytest_is_shutdown", False):
                continue
            own = f"{parent.nodeid}::{item.name}"
            if item.name.endswith(SHUTDOWN_SUFFIX) and item.nodeid != own:
                item._nodeid = own  # as xdist names an xdist_group's tests

    @pytest.hookimpl(hookwrapper=True)
    def pytest_fixture_setup(
        self, fixturedef: pytest.FixtureDef[Any], request: pytest.FixtureRequest
    ) -> Generator[None, Any, None]:
        """A launch fixture: its error noted, else its launch watched before it starts.

        Inside launch_pytest's own wrapper (``tryfirst``): this sees the launch
        description before launch_pytest starts it and waits for ``ReadyToTest``.
        """
        outcome = yield
        if not getattr(fixturedef.func, "_launch_pytest_fixture", False):
            return
        if outcome.excinfo is not None:
            error = outcome.excinfo[1]
            what = f"its launch (fixture {fixturedef.argname!r}) could not start"
            self._errors[id(error)] = _OneError(error, what)
            return
        launch = self._watch(fixturedef.argname, outcome.get_result(), request)
        if launch is not None:  # after launch_pytest's own end of the launch (LIFO)
            fixturedef.addfinalizer(functools.partial(self._check_end, launch))
            self._fresh.append(launch)

    def _watch(self, fixture: str, value: object, request: pytest.FixtureRequest) -> _Launch | None:
        """A handler of the launch's Shutdown, first in its description: did it get ready?"""
        try:
            launch_actions = importlib.import_module("launch.actions")
            handlers = importlib.import_module("launch.event_handlers")
            find_ready = importlib.import_module("launch_pytest.plugin").get_ready_to_test_action
            described = importlib.import_module("launch").LaunchDescription
        except (ImportError, AttributeError):
            return None
        description = _description(value)
        if not isinstance(description, described):
            return None  # launch_pytest says what is wrong
        try:
            ready = find_ready(description)  # launch_pytest finds the same one again
        except RuntimeError:
            return None  # two ReadyToTest: launch_pytest's own error follows
        on_ready = getattr(ready, "_add_callback", None)
        if not callable(on_ready):
            return None
        launch = _Launch(fixture, description, request.getfixturevalue("launch_service"))

        def is_ready() -> None:
            launch.ready = True

        def ended(event: object, context: object) -> None:
            if not self._finalizing:
                launch.ended_alone = True
            if not launch.ready:
                launch.not_ready = str(getattr(event, "reason", "")) or "no reason given"
                ready.execute(context)  # launch_pytest's wait ends; the tests report it

        on_ready(is_ready)
        watcher = launch_actions.RegisterEventHandler(handlers.OnShutdown(on_shutdown=ended))
        description.entities.insert(0, watcher)
        self._launches[id(description)] = launch
        return launch

    def _check_end(self, launch: _Launch) -> None:
        """A launch that failed on its own, which launch_pytest never checked: one error."""
        code = launch.return_code()
        if launch.not_ready is None and launch.ended_alone and code:
            raise pytest.fail.Exception(
                f"the launch of fixture {launch.fixture!r} failed while its tests ran: its "
                f"launch service returned {code} (an exception in the launch, such as a "
                "process that could not be started: see the launch's output)",
                pytrace=False,
            )

    @pytest.hookimpl(trylast=True)
    def pytest_runtest_setup(self, item: pytest.Item) -> None:
        """A test of a launch that ended before it was ready: its launch's one error."""
        launch = self._launch_of(item)
        if launch is not None and launch.not_ready is not None:
            raise self._not_ready(launch).error.with_traceback(None)

    def _not_ready(self, launch: _Launch) -> _OneError:
        """The one error of a launch that ended before it was ready to test."""
        if launch.error is None:
            reason = launch.not_ready
            why = "all its processes ended" if reason == "idle" else reason
            message = (
                f"the launch of fixture {launch.fixture!r} ended before it was ready to test "
                f"(ReadyToTest never ran: {why}): its processes could not start or ended "
                "first (the launch's output is in this test's captured output)"
            )
            launch.error = pytest.fail.Exception(message, pytrace=False)
            what = f"its launch (fixture {launch.fixture!r}) ended before it was ready to test"
            self._errors[id(launch.error)] = _OneError(launch.error, what)
        return self._errors[id(launch.error)]

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_call(self, item: pytest.Item) -> Generator[None, None, None]:
        self._finalizing = _may_finalize(item)
        yield
        self._finalizing = False

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_teardown(self, item: pytest.Item) -> Generator[None, None, None]:
        self._finalizing = True
        yield
        self._finalizing = False

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_makereport(
        self, item: pytest.Item, call: pytest.CallInfo[None]
    ) -> Generator[None, Any, None]:
        """A launch's one error: the first test reports it, the others are skipped."""
        outcome = yield
        if call.when != "setup":
            return
        fresh, self._fresh = self._fresh, []
        if call.excinfo is None:
            return
        report = outcome.get_result()
        one = self._errors.get(id(call.excinfo.value))
        if one is None or one.error is not call.excinfo.value:
            unready = [launch for launch in fresh if launch.not_ready is not None]
            if not unready:
                return
            # launch_pytest's own checks after its wait failed (the launch had ended): the
            # first of its tests says why instead.
            one = self._not_ready(unready[0])
            report.longrepr = item.repr_failure(_info(one.error))
        if one.carrier is None:
            one.carrier = item.nodeid
        if one.carrier == item.nodeid:
            return
        path, line = item.reportinfo()[:2]
        report.outcome = "skipped"
        why = f"Skipped: not run: {one.what}; the one error is on {one.carrier}"
        report.longrepr = (str(path), (line or 0) + 1, why)

    def _launch_of(self, item: pytest.Item) -> _Launch | None:
        """The watched launch a launch_pytest test runs with, once its fixtures are set up."""
        marker = item.get_closest_marker("launch")
        name = getattr(marker.kwargs.get("fixture"), "__name__", None) if marker else None
        funcargs: dict[str, object] = getattr(item, "funcargs", {})
        if name is None or name not in funcargs:
            return None
        return self._launches.get(id(_description(funcargs[name])))


def _info(error: BaseException) -> pytest.ExceptionInfo[BaseException]:
    """``error`` as pytest reports an exception."""
    try:
        raise error.with_traceback(None)
    except BaseException:
        return pytest.ExceptionInfo.from_current()


def _description(value: object) -> object:
    """A launch fixture's launch description: its value, or its value's first item."""
    if isinstance(value, Sequence) and not isinstance(value, str) and value:
        return value[0]
    return value


def _may_finalize(item: pytest.Item) -> bool:
    """Whether launch_pytest may end the launch in this test's call (and check its code)."""
    if getattr(item, "_launch_pytest_is_shutdown", False):
        return True  # a post-shutdown test: the launch is ended first
    function = inspect.unwrap(getattr(item, "obj", None))  # type: ignore[arg-type]
    return inspect.isgeneratorfunction(function) or inspect.isasyncgenfunction(function)

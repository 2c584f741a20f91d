"""launch_testing files under pytest, reported case by case: the one seam with launch_testing.

launch_testing's pytest plugin makes one item per launch file: it runs the launch once
and folds every ``unittest`` case into one pass or fail. The pytest plugin registers this
module when launch_testing's plugin is loaded. Right after launch_testing collects a
file, its one item is replaced by one item per ``unittest`` case of the active and
post-shutdown tests, named as launch_testing names them (``TestWhileRunning.test_x``,
with the parameter set of a ``launch_testing.parametrize`` run, ``test_x[a, 1]``). The
first case of a run to execute launches it with launch_testing's own runner, once per
parameter set; each case then reports what ``unittest`` recorded for it (read into
verdicts by launch_testing_verdicts.py). A launch that cannot start, or stops before its tests
finished, is one error; its other cases are skipped, none passed.

Everything read of launch_testing is read here and in launch_testing_verdicts.py, and
checked when a file is collected.
Where launch_testing is not as expected, the file stays the one test launch_testing made,
with one warning per session: the run goes on as before, never broken. Other collectors
(launch_pytest's among them) are left alone. With pytest-xdist, a launch file's cases
are scheduled onto one worker (scheduling.py).
"""

from __future__ import annotations

import copy
import inspect
import re
import sys
import traceback
import unittest
from collections.abc import Callable, Generator
from typing import TYPE_CHECKING, Any

import pytest

from ros_isolated_test.pytest_plugin.launch_testing_verdicts import (
    ERROR,
    FAILED,
    SKIPPED,
    XFAILED,
    XPASSED,
    Mismatch,
    Verdict,
    as_one,
    fail_result_type,
    message,
    read,
    texts,
)

if TYPE_CHECKING:
    from _pytest._code.code import ExceptionInfo, TerminalRepr, TracebackStyle

#: The name the pytest plugin registers this module under.
PLUGIN_NAME = "ros_isolated_test.launch_testing_cases"
#: Packages whose pytest items are launch_testing's (launch_testing_ros subclasses them).
_LAUNCH_PACKAGES = ("launch_testing", "launch_testing_ros")

_FRAME = re.compile(r'^\s*File "(.+)", line (\d+)')


class LaunchCasesWarning(pytest.PytestWarning):
    """launch_testing is not as this module knows it: its files stay one test each."""


class _Run:
    """One launch of a file (one parameter set): its cases' verdicts once launched."""

    def __init__(self, index: int, label: str, size: int) -> None:
        self.index = index
        self.label = label
        self.size = size
        #: By case position; None until launched, or when the launch as a whole failed.
        self.verdicts: list[Verdict] | None = None
        #: Errors after a case (a tearDownClass that failed), by case position.
        self.after: dict[int, list[str]] = {}
        #: The launch's own outcome when its cases have none of their own.
        self.whole: Verdict | None = None
        #: The case that reports ``whole``: the first to ask.
        self.carrier: str | None = None
        #: Cases that got their verdict from this launch (a second ask launches again).
        self.reported: set[str] = set()


class LaunchFile:
    """A launch file's runs, each launched once when its first case runs."""

    def __init__(
        self, item: pytest.Item, runs: list[Any], sizes: list[int], runner: Callable[..., Any]
    ) -> None:
        self._config = item.config
        self._path = item.path
        self._runs = runs
        self._runner = runner
        pairs = enumerate(zip(runs, sizes, strict=True))
        self.runs = [_Run(i, str(run), size) for i, (run, size) in pairs]
        #: A run whose launch stopped early: later runs are not launched (launch_testing's
        #: own rule: most likely a Ctrl-C).
        self.stopped: _Run | None = None

    def verdict(self, case: LaunchCase) -> tuple[Verdict, list[str]]:
        """``case``'s verdict and the errors after it, launching its run if needed."""
        run = self.runs[case.run]
        if (run.verdicts is None and run.whole is None) or case.nodeid in run.reported:
            self._launch(run)  # first ask, or a rerun of a case (pytest-rerunfailures)
        run.reported.add(case.nodeid)
        if run.whole is not None:
            if run.carrier is None or run.carrier == case.nodeid:
                run.carrier = case.nodeid
                return run.whole, []
            return Verdict(SKIPPED, _together(run, run.carrier)), []
        assert run.verdicts is not None
        return run.verdicts[case.case], run.after.get(case.case, [])

    def _launch(self, run: _Run) -> None:
        """Launch one run with launch_testing's runner and read its result case by case."""
        run.verdicts, run.after, run.whole, run.carrier = None, {}, None, None
        run.reported = set()
        if self.stopped is not None and self.stopped is not run:
            why = (
                f"not launched: the launch {self.stopped.label} stopped before its tests "
                "finished (launch_testing launches no later parameter set then)"
            )
            run.verdicts = [Verdict(SKIPPED, why)] * run.size
            return
        self.stopped = None
        test_run = copy.deepcopy(self._runs[run.index])  # as launch_testing: a rerun is fresh
        cases = list(test_run.all_cases())  # before unittest may let go of them
        given: list[list[str]] = self._config.getoption("--launch-args", default=None) or []
        arguments = [argument for group in given for argument in group]
        try:
            runner = self._runner(
                test_runs=[test_run],
                launch_file_arguments=arguments,
                debug=self._config.getoption("verbose"),
            )
            runner.validate()
            results = runner.run()
        except Exception as error:  # the file's own code failed: its description, a check
            text = "".join(traceback.format_exception(error))
            why = f"the launch could not start: {type(error).__name__}: {error}"
            run.whole = Verdict(ERROR, why, text)
            self.stopped = run
            return
        result: Any = results.get(test_run) if len(results) != 1 else next(iter(results.values()))
        if isinstance(result, fail_result_type()):
            said = texts(result.failures[:1]).strip()
            run.whole = Verdict(ERROR, _STOPPED, f"{_STOPPED}\nlaunch_testing: {said}")
            self.stopped = run
            return
        try:
            run.verdicts, run.after = read(cases, result)
        except Exception as error:  # as launch_testing reports it: one result for the run
            reason = str(error) if isinstance(error, Mismatch) else repr(error)
            _warn_once(self._config, self._path, reason, _ONE_PER_RUN)
            run.whole = as_one(result)


_STOPPED = (
    "the launch stopped before its active tests finished: it never got ready to test "
    "(ReadyToTest within its timeout) or its processes ended first (launch_testing's "
    "output is in the captured stdout)"
)


def _together(run: _Run, carrier: str) -> str:
    """Why a case of a run with one outcome for all reports nothing of its own."""
    if run.whole is not None and run.whole.kind == ERROR:
        return f"not run: its launch ({run.label}) failed, the one error is on {carrier}"
    return f"reported with {carrier}: launch_testing's result was not read case by case"


def _crash_site(text: str, path: str, lineno: int) -> tuple[str, int]:
    """The last frame a traceback names, else the case's own place."""
    frames = [_FRAME.match(line) for line in text.splitlines()]
    last = [match for match in frames if match is not None]
    return (last[-1].group(1), int(last[-1].group(2))) if last else (path, lineno)


class _Reported(Exception):
    """A case's failure or error as ``unittest`` wrote it; shown as that text."""

    def __init__(self, verdict: Verdict) -> None:
        super().__init__(verdict.message)
        self.verdict = verdict


class LaunchCase(pytest.Item):
    """One ``unittest`` case of a launch file: its launch's first case to run starts it."""

    def __init__(
        self, *, launch: LaunchFile, run: int, case: int, line: int, **kwargs: Any
    ) -> None:
        super().__init__(**kwargs)
        self.launch = launch
        self.run = run
        self.case = case
        self.line = line
        self._verdict = Verdict(ERROR, "not run")
        self._after: list[str] = []

    def setup(self) -> None:
        """Launch (first case of its run), then an error or a skip is reported at setup."""
        self._verdict, self._after = self.launch.verdict(self)
        if self._verdict.kind == ERROR:
            raise _Reported(self._verdict)
        if self._verdict.kind == SKIPPED:
            raise pytest.skip.Exception(self._verdict.message, _use_item_location=True)

    def runtest(self) -> None:
        if self._verdict.kind in (FAILED, XPASSED):
            raise _Reported(self._verdict)
        if self._verdict.kind == XFAILED:
            pytest.xfail(self._verdict.message)

    def teardown(self) -> None:
        """A class or module fixture that failed after this, its class's last case."""
        after, self._after = self._after, []
        if after:
            text = "\n".join(after)
            raise _Reported(Verdict(ERROR, message(text), text))

    def repr_failure(
        self, excinfo: ExceptionInfo[BaseException], style: TracebackStyle | None = None
    ) -> str | TerminalRepr:
        if isinstance(excinfo.value, _Reported):
            return self._shown(excinfo.value.verdict)
        return super().repr_failure(excinfo, style)

    def _repr_failure_py(
        self, excinfo: ExceptionInfo[BaseException], style: TracebackStyle | None = None
    ) -> TerminalRepr:
        """Setup and teardown errors: pytest shows them through this, not repr_failure."""
        if isinstance(excinfo.value, _Reported):
            return self._shown(excinfo.value.verdict)
        return super()._repr_failure_py(excinfo, style)

    def _shown(self, verdict: Verdict) -> TerminalRepr:
        """The text unittest wrote, and its last line (the exception) as the short message."""
        from _pytest._code.code import ExceptionChainRepr, ReprFileLocation, ReprTracebackNative

        text = verdict.text or verdict.message
        path, lineno = _crash_site(text, str(self.path), self.line)
        lines = [f"{line}\n" for line in text.rstrip("\n").splitlines()]
        crash = ReprFileLocation(path, lineno, verdict.message or message(text))
        return ExceptionChainRepr([(ReprTracebackNative(lines), crash, None)])

    def reportinfo(self) -> tuple[Any, int | None, str]:
        """Marked as pytest marks doctests: ``-v`` then shows the node ID as it is."""
        return self.path, self.line - 1 if self.line else None, f"[launch_testing] {self.name}"


def _cases(item: pytest.Item) -> list[LaunchCase]:
    """launch_testing's one item of a file as one item per case; Mismatch if it cannot be."""
    runs = getattr(item, "test_runs", None)
    runner = getattr(item, "runner_cls", None)
    if not isinstance(runs, list) or not runs:
        raise Mismatch("its test item has no list of test runs (test_runs)")
    if not callable(runner):
        raise Mismatch("its test item has no runner class (runner_cls)")
    try:
        inspect.signature(runner).bind(test_runs=[], launch_file_arguments=[], debug=0)
    except (TypeError, ValueError) as error:
        raise Mismatch(f"its runner takes other arguments ({error})") from None
    for name in ("validate", "run"):
        if not callable(getattr(runner, name, None)):
            raise Mismatch(f"its runner has no {name}()")
    fail_result_type()
    cases = [_run_cases(run) for run in runs]
    launch = LaunchFile(item, runs, [len(of_run) for of_run in cases], runner)
    parent = item.parent
    assert parent is not None
    made: list[LaunchCase] = []
    for index, of_run in enumerate(cases):
        for position, case in enumerate(of_run):
            made.append(LaunchCase.from_parent(
                parent, name=_name(case), launch=launch, run=index, case=position,
                line=_line(case),
            ))  # fmt: skip
    names = [case.name for case in made]
    twice = sorted({name for name in names if names.count(name) > 1})
    if twice:
        raise Mismatch(f"two cases are named {twice[0]}")
    return made


def _run_cases(run: Any) -> list[unittest.TestCase]:
    all_cases = getattr(run, "all_cases", None)
    if not callable(all_cases):
        raise Mismatch("its test runs have no all_cases()")
    cases = list(all_cases())
    if not all(isinstance(case, unittest.TestCase) for case in cases):
        raise Mismatch("its test runs hold other things than unittest cases")
    return cases


def _name(case: unittest.TestCase) -> str:
    """launch_testing's name of a case: its unittest id without the module."""
    module = f"{type(case).__module__}."
    whole = case.id()
    return whole[len(module) :] if whole.startswith(module) else whole


def _line(case: unittest.TestCase) -> int:
    """The line the case's method starts on (0: unknown)."""
    method = getattr(case, case._testMethodName, None)
    try:
        code = inspect.unwrap(method).__code__  # type: ignore[arg-type]
    except (AttributeError, TypeError, ValueError):
        return 0
    return int(code.co_firstlineno)


def _from_launch_testing(node: object) -> bool:
    return type(node).__module__.split(".")[0] in _LAUNCH_PACKAGES


_WARNED = pytest.StashKey[bool]()
_ONE_PER_FILE = "its launch files are reported as one test each"
_ONE_PER_RUN = "each launch's result is reported on its first case"


def _warn_once(config: pytest.Config, where: object, reason: str, instead: str) -> None:
    """One warning a session, at ``where`` (a path): launch_testing differs, and so what."""
    if config.stash.get(_WARNED, False):
        return
    config.stash[_WARNED] = True
    warning = (
        f"ros-isolated-test: {_launch_testing_version()} is not as expected ({reason}): "
        f"{instead}, as launch_testing reports them"
    )
    import warnings

    try:
        warnings.warn_explicit(LaunchCasesWarning(warning), None, str(where), 0)
    except Exception:  # -W error, or anything else: said all the same, the run goes on
        print(warning, file=sys.stderr, flush=True)


def _launch_testing_version() -> str:
    from importlib import metadata

    try:
        return f"launch_testing {metadata.version('launch_testing')}"
    except metadata.PackageNotFoundError:
        return "launch_testing"


@pytest.hookimpl(hookwrapper=True)
def pytest_make_collect_report(collector: pytest.Collector) -> Generator[None, Any, None]:
    """launch_testing's one item of a launch file, replaced by its cases."""
    outcome = yield
    report = outcome.get_result()
    if report.outcome != "passed" or not _from_launch_testing(collector):
        return
    result: list[pytest.Item | pytest.Collector] = []
    for node in report.result:
        if isinstance(node, pytest.Item) and _from_launch_testing(node):
            try:
                result.extend(_cases(node) or [node])
            except Mismatch as mismatch:
                _warn_once(node.config, node.path, str(mismatch), _ONE_PER_FILE)
                result.append(node)
            except Exception as error:  # whatever else it is: never break collection
                reason = f"{type(error).__name__}: {error}"
                _warn_once(node.config, node.path, reason, _ONE_PER_FILE)
                result.append(node)
        else:
            result.append(node)
    report.result = result

"""Launch files and the packages around them, written into a test's temp dir.

The token launch file starts the crosstalk demo's talker (a token of its own, failing on
any other) and holds four cases: the listener (fails on any foreign token), one that
passes, one that always fails, and the talker's exit code after shutdown. Every launch
and every case writes a line to ``$LAUNCH_CASES_LOG`` (launch or case, token, the pytest
process's PID, ROS_DOMAIN_ID), so a test can count launches and see where each case ran.
The other launch files are for one behaviour each: parameter sets, a launch that cannot
start, every ``unittest`` outcome.
"""

from __future__ import annotations

from pathlib import Path

from helpers.commands import REPO

TALKER = REPO / "examples" / "crosstalk_demo" / "test" / "token_talker.py"
#: The cases of a token launch file as launch_testing names them, the failing one first.
TOKEN_CASES = (
    "TestWhileRunning.test_always_fails",
    "TestWhileRunning.test_only_own_token",
    "TestWhileRunning.test_passes",
    "TestAfterShutdown.test_exit_code",
)
ALWAYS_FAILS = TOKEN_CASES[0]

#: The function every launch and test file defines: one line in $LAUNCH_CASES_LOG a call.
NOTE = '''

def note(*words):
    """One line in $LAUNCH_CASES_LOG: what ran, in which pytest process, on which ID."""
    log = os.environ.get("LAUNCH_CASES_LOG")
    if log:
        line = " ".join(map(str, (*words, os.getpid(), os.environ.get("ROS_DOMAIN_ID", "-"))))
        with open(log, "a") as out:
            out.write(line + "\\n")
'''

#: The imports of a file that listens for the crosstalk demo's talker (``talker`` to format).
LISTENER = """\
from collections import Counter
from pathlib import Path

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from std_msgs.msg import String

TALKER = Path({talker!r})
sys.path.insert(0, str(TALKER.parent))
import token_talker  # noqa: E402
"""

#: Lines every launch file starts with: the log every launch and case writes to.
_PREAMBLE = (
    """\
import os
import sys
import time
import unittest

import launch
import launch.actions
import launch.event_handlers
import launch_testing
import launch_testing.actions
import launch_testing.asserts
import launch_testing.util
import pytest
"""
    + NOTE
)

TOKEN_LAUNCH = (
    _PREAMBLE
    + "\n"
    + LISTENER
    + """
TOKEN = os.environ.get("LAUNCH_CASES_TOKEN") or {token!r}


@pytest.mark.launch_test
def generate_test_description():
    note("launch", TOKEN)
    talker = launch.actions.ExecuteProcess(
        cmd=[sys.executable, str(TALKER), TOKEN], name=f"talker_{{TOKEN}}", output="screen"
    )
    keep_alive = launch_testing.util.KeepAliveProc()
    ready = launch_testing.actions.ReadyToTest()
    return launch.LaunchDescription([talker, keep_alive, ready]), {{"talker": talker}}


class TestWhileRunning(unittest.TestCase):
    def test_only_own_token(self, proc_info, talker):
        note("case", TOKEN, "test_only_own_token")
        heard = Counter()
        context = Context()
        rclpy.init(args=[], context=context)
        executor = SingleThreadedExecutor(context=context)
        node = rclpy.create_node(f"listener_{{TOKEN}}", context=context)
        try:
            node.create_subscription(
                String, token_talker.TOPIC, lambda m: heard.update([m.data]), token_talker.QOS
            )
            executor.add_node(node)
            token_talker.spin_until(
                executor,
                time.monotonic() + token_talker.OWN_TOKEN_DEADLINE_S,
                lambda: heard[TOKEN] > 0,
            )
            if heard[TOKEN]:
                token_talker.spin_until(executor, time.monotonic() + token_talker.LISTEN_S)
        finally:
            executor.shutdown()
            node.destroy_node()
            context.try_shutdown()
        proc_info.assertWaitForShutdown(process=talker, timeout=60)
        self.assertGreater(heard[TOKEN], 0, f"never heard its own token {{TOKEN}}")
        foreign = {{token: count for token, count in heard.items() if token != TOKEN}}
        self.assertEqual(foreign, {{}}, f"crosstalk: heard tokens not its own: {{foreign}}")

    def test_passes(self):
        note("case", TOKEN, "test_passes")

    def test_always_fails(self):
        note("case", TOKEN, "test_always_fails")
        self.fail(f"fails on purpose ({{TOKEN}})")


@launch_testing.post_shutdown_test()
class TestAfterShutdown(unittest.TestCase):
    def test_exit_code(self, proc_info, talker):
        note("case", TOKEN, "test_exit_code")
        launch_testing.asserts.assertExitCodes(proc_info, process=talker)
"""
)

#: Two parameter sets: one launch each, each case named with its set.
PARAMETRIZED_LAUNCH = (
    _PREAMBLE
    + """

@pytest.mark.launch_test
@launch_testing.parametrize("colour, size", [("red", 1), ("blue", 2)])
def generate_test_description(colour, size):
    note("launch", f"param-{colour}")
    keep_alive = launch_testing.util.KeepAliveProc()
    return launch.LaunchDescription([keep_alive, launch_testing.actions.ReadyToTest()])


class TestWhileRunning(unittest.TestCase):
    def test_is_red(self, colour):
        note("case", f"param-{colour}", "test_is_red")
        self.assertEqual(colour, "red")

    def test_size(self, colour, size):
        note("case", f"param-{colour}", "test_size")
        self.assertGreater(size, 0)


@launch_testing.post_shutdown_test()
class TestAfterShutdown(unittest.TestCase):
    def test_after(self, colour):
        note("case", f"param-{colour}", "test_after")
"""
)

#: Its one process cannot be started, and ReadyToTest waits for that start: the launch
#: ends before any test ran.
CANNOT_START_LAUNCH = (
    _PREAMBLE
    + """

@pytest.mark.launch_test
def generate_test_description():
    note("launch", "cannot-start")
    missing = launch.actions.ExecuteProcess(cmd=["/nonexistent/no-such-program"], name="missing")
    ready = launch.actions.RegisterEventHandler(launch.event_handlers.OnProcessStart(
        target_action=missing, on_start=[launch_testing.actions.ReadyToTest()]))
    return launch.LaunchDescription([ready, missing])


class TestWhileRunning(unittest.TestCase):
    def test_first(self):
        note("case", "cannot-start", "test_first")

    def test_second(self):
        note("case", "cannot-start", "test_second")


@launch_testing.post_shutdown_test()
class TestAfterShutdown(unittest.TestCase):
    def test_after(self):
        note("case", "cannot-start", "test_after")
"""
)

#: Its process exits at once, while the first test waits for ever: the launch ends (all
#: its processes gone) before its tests finished.
DIES_EARLY_LAUNCH = (
    _PREAMBLE
    + """
import threading


@pytest.mark.launch_test
def generate_test_description():
    note("launch", "dies-early")
    dies = launch.actions.ExecuteProcess(cmd=[sys.executable, "-c", "raise SystemExit(3)"])
    ready = launch.actions.RegisterEventHandler(launch.event_handlers.OnProcessStart(
        target_action=dies, on_start=[launch_testing.actions.ReadyToTest()]))
    return launch.LaunchDescription([ready, dies])


class TestWhileRunning(unittest.TestCase):
    def test_first(self):
        threading.Event().wait()  # never done: the launch must end first

    def test_second(self):
        note("case", "dies-early", "test_second")
"""
)

#: generate_test_description itself fails (a file it needs is not there).
BROKEN_DESCRIPTION_LAUNCH = (
    _PREAMBLE
    + """

@pytest.mark.launch_test
def generate_test_description():
    note("launch", "broken")
    raise FileNotFoundError("no such map: /maps/missing.yaml")


class TestWhileRunning(unittest.TestCase):
    def test_first(self):
        note("case", "broken", "test_first")

    def test_second(self):
        note("case", "broken", "test_second")
"""
)

#: Every unittest outcome, each its own result; a class whose setUpClass fails.
OUTCOMES_LAUNCH = (
    _PREAMBLE
    + """

@pytest.mark.launch_test
def generate_test_description():
    note("launch", "outcomes")
    keep_alive = launch_testing.util.KeepAliveProc()
    return launch.LaunchDescription([keep_alive, launch_testing.actions.ReadyToTest()])


class TestOutcomes(unittest.TestCase):
    def test_error(self):
        raise RuntimeError("boom in test_error")

    def test_failure(self):
        self.assertEqual(1, 2, "one is not two")

    def test_passed(self):
        pass

    @unittest.skip("skipped on purpose")
    def test_skipped(self):
        pass

    def test_subtests(self):
        for value in (1, 2, 3):
            with self.subTest(value=value):
                self.assertLess(value, 2, f"subtest value {value}")


class TestBrokenSetUp(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        raise OSError("setUpClass could not open its device")

    def test_never_runs(self):
        pass
"""
)

#: A case that passes only once the file was launched twice (pytest-rerunfailures).
FLAKY_LAUNCH = (
    _PREAMBLE
    + """

@pytest.mark.launch_test
def generate_test_description():
    note("launch", "flaky")
    keep_alive = launch_testing.util.KeepAliveProc()
    return launch.LaunchDescription([keep_alive, launch_testing.actions.ReadyToTest()])


class TestWhileRunning(unittest.TestCase):
    def test_second_launch_only(self):
        with open(os.environ["LAUNCH_CASES_LOG"]) as log:
            launches = [line for line in log if line.startswith("launch flaky ")]
        self.assertEqual(len(launches), 2, "passes on the second launch only")

    def test_steady(self):
        note("case", "flaky", "test_steady")
"""
)

#: Not a launch file: an ordinary pytest test beside them, reported as ever.
PLAIN_TEST = """\
import os


def test_plain_pytest_has_the_workers_id():
    assert os.environ.get("ROS_DOMAIN_ID")
"""


def token_launch(token: str) -> str:
    """The token launch file with ``token`` (``$LAUNCH_CASES_TOKEN`` wins when set)."""
    return TOKEN_LAUNCH.format(talker=str(TALKER), token=token)


PACKAGE_XML = """\
<?xml version="1.0"?>
<package format="3">
  <name>{name}</name>
  <version>0.1.0</version>
  <description>Launch tests reported case by case: {name}.</description>
  <maintainer email="maintainers@ros-isolated-test.org">ros-isolated-test maintainers</maintainer>
  <license>Apache-2.0</license>
{depends}
  <export>
    <build_type>{build_type}</build_type>
  </export>
</package>
"""

SETUP_PY = """\
from setuptools import setup

PACKAGE = {name!r}

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=[],
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{{PACKAGE}}"]),
        (f"share/{{PACKAGE}}", ["package.xml"]),
    ],
    install_requires=["setuptools"],
    extras_require={{"test": ["pytest"]}},  # colcon tests with pytest, not unittest
    zip_safe=True,
    license="Apache-2.0",
)
"""


def python_package(root: Path, name: str, token: str) -> Path:
    """An ament_python package whose one test is the token launch file, as colcon tests it."""
    package = root / name
    (package / "resource").mkdir(parents=True)
    (package / "resource" / name).write_text("")
    (package / "test").mkdir()
    depends = "  <test_depend>launch_testing</test_depend>\n  <test_depend>rclpy</test_depend>\n"
    (package / "package.xml").write_text(
        PACKAGE_XML.format(name=name, depends=depends, build_type="ament_python")
    )
    (package / "setup.py").write_text(SETUP_PY.format(name=name))
    (package / "test" / f"test_{token}_launch.py").write_text(token_launch(token))
    return package


#: One launch file, three ways: our pytest macro, ament's under ros_isolated_test_all(),
#: and add_launch_test (launch_testing's own runner, a case per unittest case already).
CMAKE_LISTS = """\
cmake_minimum_required(VERSION 3.20)
project({name} NONE)

find_package(ament_cmake REQUIRED)

if(BUILD_TESTING)
  find_package(ros_isolated_test REQUIRED)
  find_package(ament_cmake_pytest REQUIRED)
  find_package(launch_testing_ament_cmake REQUIRED)
  ros_isolated_test_all()

  ros_isolated_add_pytest_test(by_macro test/test_tokens_launch.py
    ENV LAUNCH_CASES_TOKEN=macro TIMEOUT 120)
  ament_add_pytest_test(by_all test/test_tokens_launch.py
    ENV LAUNCH_CASES_TOKEN=all TIMEOUT 120)
  add_launch_test(test/test_tokens_launch.py TARGET by_launch
    ENV LAUNCH_CASES_TOKEN=launch TIMEOUT 120)
endif()

ament_package()
"""
#: The tests CMAKE_LISTS registers, by the token each one's talker gets.
CMAKE_TESTS = {"by_macro": "macro", "by_all": "all", "by_launch": "launch"}


def cmake_package(
    root: Path,
    name: str,
    cmake_lists: str | None = None,
    token: str = "unset",
    test_depends: tuple[str, ...] = ("ament_cmake_pytest", "launch_testing_ament_cmake", "rclpy"),
) -> Path:
    """An ament_cmake package registering the token launch file (test/test_tokens_launch.py).

    As ``cmake_lists`` says (CMAKE_LISTS when None), its talker's token ``token``.
    """
    package = root / name
    (package / "test").mkdir(parents=True)
    depends = "".join(
        f"  <{kind}>{dep}</{kind}>\n"
        for kind, dep in (
            ("buildtool_depend", "ament_cmake"),
            *(("test_depend", dep) for dep in test_depends),
        )
    )
    (package / "package.xml").write_text(
        PACKAGE_XML.format(name=name, depends=depends, build_type="ament_cmake")
    )
    lists = CMAKE_LISTS.format(name=name) if cmake_lists is None else cmake_lists
    (package / "CMakeLists.txt").write_text(lists)
    (package / "test" / "test_tokens_launch.py").write_text(token_launch(token))
    return package


def read_log(path: Path) -> list[list[str]]:
    """``$LAUNCH_CASES_LOG``'s lines, split: [launch|case, token, (case,) pid, domain]."""
    if not path.is_file():
        return []
    return [line.split() for line in path.read_text().splitlines() if line.strip()]


#: A stand-in launch_testing for the fallback: its pytest plugin, one item per file as
#: the real one makes, shaped as ``$FAKE_LAUNCH_TESTING_SHAPE`` says: ``expected`` (what
#: ros-isolated-test reads), ``renamed`` (the item keeps its runs under another name) or
#: ``results`` (its results lack ``testCases``). It runs on pytest 9, with no launch at all.
FAKE_HOOKS = '''\
"""A stand-in for launch_testing's pytest plugin (see tests/helpers/launch_files.py)."""

import importlib.util
import os
import unittest

import pytest

SHAPE = os.environ.get("FAKE_LAUNCH_TESTING_SHAPE", "expected")


class TestResult(unittest.TestResult):
    def __init__(self):
        super().__init__()
        self.ran = []

    def startTest(self, test):
        self.ran.append(test)
        super().startTest(test)

    @property
    def testCases(self):
        return list(self.ran)


class BareResult(unittest.TestResult):
    """Another shape of result: no testCases."""


def _cases(suite):
    for test in suite:
        if isinstance(test, unittest.TestSuite):
            yield from _cases(test)
        else:
            yield test


class TestRun:
    def __init__(self, module):
        self.name = module.__name__
        self.suite = unittest.defaultTestLoader.loadTestsFromModule(module)

    def all_cases(self):
        return list(_cases(self.suite))

    def __str__(self):
        return self.name


class Runner:
    def __init__(self, test_runs, launch_file_arguments=(), debug=False):
        self.test_runs = test_runs

    def validate(self):
        pass

    def run(self):
        results = {}
        for run in self.test_runs:
            results[run] = BareResult() if SHAPE == "results" else TestResult()
            run.suite.run(results[run])
        return results


class LaunchTestItem(pytest.Item):
    def runtest(self):
        runs = self.test_runs if SHAPE != "renamed" else self.launch_runs
        results = Runner(runs).run()
        failed = [text for r in results.values() for _, text in r.failures + r.errors]
        if failed:
            raise AssertionError("some test cases have failed:\\n" + "\\n".join(failed))


class LaunchTestModule(pytest.File):
    def collect(self):
        spec = importlib.util.spec_from_file_location(self.path.stem, self.path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        item = LaunchTestItem.from_parent(self, name=module.__name__)
        if SHAPE == "renamed":
            item.launch_runs = [TestRun(module)]
        else:
            item.test_runs = [TestRun(module)]
        item.runner_cls = Runner
        yield item


def pytest_pycollect_makemodule(module_path, parent):
    if module_path.name.endswith("_launch.py"):
        return LaunchTestModule.from_parent(parent, path=module_path)
    return None
'''

FAKE_TEST_RESULT = '''\
import unittest


class FailResult(unittest.TestResult):
    """A launch that stopped early (never made by the stand-in)."""
'''

#: Two files for the stand-in: one with a failing case, one passing.
FAKE_LAUNCH_FILES = {
    "test_mixed_launch.py": """\
import unittest


class TestMixed(unittest.TestCase):
    def test_bad(self):
        self.fail("bad on purpose")

    def test_good(self):
        pass
""",
    "test_fine_launch.py": """\
import unittest


class TestFine(unittest.TestCase):
    def test_fine(self):
        pass
""",
}


def fake_launch_testing(root: Path, version: str = "0.0.1") -> Path:
    """A folder for PYTHONPATH holding the stand-in, registered as pytest11 ``launch_testing``."""
    site = root / "site"
    package = site / "launch_testing"
    (package / "pytest").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "pytest" / "__init__.py").write_text("")
    (package / "pytest" / "hooks.py").write_text(FAKE_HOOKS)
    (package / "test_result.py").write_text(FAKE_TEST_RESULT)
    info = site / f"launch_testing-{version}.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(
        f"Metadata-Version: 2.1\nName: launch_testing\nVersion: {version}\n"
    )
    (info / "entry_points.txt").write_text(
        "[pytest11]\nlaunch_testing = launch_testing.pytest.hooks\n"
    )
    return site

"""Result files of real producers, made during the test run, through the RUNNER.

googletest (Debian's, built here with cmake), pytest in both junit families and
unittest-xml-reporting, each run the way ament runs it; whatever they write (or do not
write, when they crash) must come out as the canonical result with the right counts.
"""

from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.canonical import Canonical, check_canonical
from helpers.commands import run_cli, run_runner

PACKAGE = "pkg"

# --- googletest ----------------------------------------------------------------------------

CMAKE_LISTS = """\
cmake_minimum_required(VERSION 3.20)
project(producers CXX)
set(CMAKE_CXX_STANDARD 17)
find_package(GTest REQUIRED)
foreach(target mixed_test env_failure_test suite_setup_test crash_test)
  add_executable(${target} ${target}.cpp)
  target_link_libraries(${target} GTest::gtest_main)
endforeach()
"""

GTEST_SOURCES = {
    "mixed_test.cpp": """\
#include <gtest/gtest.h>
#include <stdexcept>

TEST(Basic, Pass) { EXPECT_EQ(1, 1); }
TEST(Basic, TwoFailures) {
  EXPECT_EQ(1, 2) << "first assertion";
  EXPECT_TRUE(false) << "second assertion";
}
TEST(Basic, Skip) { GTEST_SKIP() << "skip reason"; }
TEST(Basic, DISABLED_Off) { FAIL() << "never runs"; }
TEST(Basic, Throws) { throw std::runtime_error("boom"); }
TEST(Basic, Property) { RecordProperty("key", "value"); }

template <typename T> class Typed : public ::testing::Test {};
using TypeList = ::testing::Types<int, double>;
TYPED_TEST_SUITE(Typed, TypeList);
TYPED_TEST(Typed, Zero) { EXPECT_EQ(TypeParam(0), TypeParam(0)); }

class Param : public ::testing::TestWithParam<int> {};
TEST_P(Param, BelowThree) { EXPECT_LT(GetParam(), 3); }
INSTANTIATE_TEST_SUITE_P(Inst, Param, ::testing::Values(1, 2, 3));
""",
    "env_failure_test.cpp": """\
#include <gtest/gtest.h>

class BrokenEnvironment : public ::testing::Environment {
 public:
  void SetUp() override { ADD_FAILURE() << "global set-up broke"; }
};
static ::testing::Environment* const environment =
    ::testing::AddGlobalTestEnvironment(new BrokenEnvironment);

TEST(Env, Pass) { EXPECT_TRUE(true); }
""",
    "suite_setup_test.cpp": """\
#include <gtest/gtest.h>

class Broken : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { FAIL() << "suite set-up broke"; }
};
TEST_F(Broken, Runs) { EXPECT_TRUE(true); }
TEST(Fine, Pass) { EXPECT_TRUE(true); }
""",
    "crash_test.cpp": """\
#include <gtest/gtest.h>
#include <cstdlib>
#include <iostream>

TEST(Crash, Pass) { EXPECT_TRUE(true); }
TEST(Crash, Abort) {
  std::cout << "about to abort" << std::endl;
  std::abort();
}
""",
}


@pytest.fixture(scope="module")
def gtest_build(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The four gtest binaries, built once with cmake and make against Debian's googletest."""
    capabilities.require(capabilities.GTEST)
    source = tmp_path_factory.mktemp("gtest_src")
    (source / "CMakeLists.txt").write_text(CMAKE_LISTS)
    for name, text in GTEST_SOURCES.items():
        (source / name).write_text(text)
    build = source / "build"
    for command in (
        ["cmake", "-S", str(source), "-B", str(build), "-DCMAKE_BUILD_TYPE=Release"],
        ["make", "-C", str(build), f"-j{min(os.cpu_count() or 1, 4)}"],
    ):
        proc = subprocess.run(command, check=False, capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, f"{command} failed:\n{proc.stdout}\n{proc.stderr}"
    return build


def _ament(
    runner_script: str,
    env: dict[str, str],
    result: Path,
    command: Sequence[str],
    cwd: Path,
    **kwargs: object,
) -> subprocess.CompletedProcess[str]:
    """``RUNNER RESULT --package-name pkg --command CMD``, as ament_add_test registers it."""
    args = [str(result), "--package-name", PACKAGE, "--command", *command]
    return run_runner(runner_script, args, env, cwd=cwd, **kwargs)


def _gtest(
    runner_script: str, env: dict[str, str], build: Path, target: str, tmp_path: Path
) -> tuple[subprocess.CompletedProcess[str], Path]:
    """Run ``target`` as ament_add_gtest does: ``<binary> --gtest_output=xml:<RESULT_FILE>``."""
    result = tmp_path / "test_results" / PACKAGE / f"{target}.gtest.xml"
    command = [str(build / target), f"--gtest_output=xml:{result}"]
    return _ament(runner_script, env, result, command, tmp_path), result


def _outcomes(result: Canonical) -> dict[tuple[str, str], str]:
    return {(case.classname, case.name): case.outcome for case in result.summary.cases}


def test_gtest_mixed_binary(
    runner_script: str, env: dict[str, str], gtest_build: Path, tmp_path: Path
) -> None:
    proc, path = _gtest(runner_script, env, gtest_build, "mixed_test", tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    result = check_canonical(path, PACKAGE, "mixed_test")
    # 11 tests (DISABLED_Off included): TwoFailures, Throws and BelowThree/2 fail; Skip
    # and DISABLED_Off are skipped.
    assert result.counts == (11, 3, 0, 2)
    assert _outcomes(result) == {
        ("pkg.Basic", "Pass"): "passed",
        ("pkg.Basic", "TwoFailures"): "failure",
        ("pkg.Basic", "Skip"): "skipped",
        ("pkg.Basic", "DISABLED_Off"): "skipped",
        ("pkg.Basic", "Throws"): "failure",
        ("pkg.Basic", "Property"): "passed",
        ("pkg.Typed/0", "Zero"): "passed",
        ("pkg.Typed/1", "Zero"): "passed",
        ("pkg.Inst/Param", "BelowThree/0"): "passed",
        ("pkg.Inst/Param", "BelowThree/1"): "passed",
        ("pkg.Inst/Param", "BelowThree/2"): "failure",
    }
    both = result.case("TwoFailures")
    for part in ("first assertion", "second assertion", "Expected equality"):
        assert part in both.message
        assert part in both.text
    assert 'C++ exception with description "boom"' in result.case("Throws").text
    assert "skip reason" in result.case("Skip").message
    assert "actual: 3 vs 3" in result.case("BelowThree/2").text
    assert result.properties["exit"] == "exited with code 1"
    assert result.properties["exit_code"] == "1"
    original = path.with_name(path.name + ".orig")
    assert b'name="AllTests"' in original.read_bytes()


def test_gtest_global_environment_failure(
    runner_script: str, env: dict[str, str], gtest_build: Path, tmp_path: Path
) -> None:
    proc, path = _gtest(runner_script, env, gtest_build, "env_failure_test", tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    result = check_canonical(path, PACKAGE, "env_failure_test")
    assert result.counts == (2, 1, 0, 0)
    assert result.case("Pass", "pkg.Env").outcome == "passed"
    failed = result.case("global environment set-up or tear-down")
    assert failed.outcome == "failure"
    assert "global set-up broke" in failed.message
    assert "global set-up broke" in failed.text


def test_gtest_suite_setup_failure_is_not_lost(
    runner_script: str, env: dict[str, str], gtest_build: Path, tmp_path: Path
) -> None:
    """gtest <= 1.15 writes the suite's tests as skipped and the failure nowhere, exit 1."""
    proc, path = _gtest(runner_script, env, gtest_build, "suite_setup_test", tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    result = check_canonical(path, PACKAGE, "suite_setup_test")
    assert result.counts == (3, 1, 0, 1)
    assert result.case("Runs", "pkg.Broken").outcome == "skipped"
    assert result.case("Pass", "pkg.Fine").outcome == "passed"
    failed = next(case for case in result.summary.cases if case.outcome == "failure")
    # >= 1.16 reports it as a nameless case; older versions only through the exit code.
    assert failed.name in ("suite set-up or tear-down", "test process exit"), failed
    assert "suite set-up broke" in path.read_text("utf-8")


def _no_core_dump() -> None:
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))


def test_gtest_crash_leaves_no_file_and_the_result_says_so(
    runner_script: str, env: dict[str, str], gtest_build: Path, tmp_path: Path
) -> None:
    result_path = tmp_path / "test_results" / PACKAGE / "crash_test.gtest.xml"
    command = [str(gtest_build / "crash_test"), f"--gtest_output=xml:{result_path}"]
    proc = _ament(runner_script, env, result_path, command, tmp_path, preexec_fn=_no_core_dump)
    assert proc.returncode == 128 + signal.SIGABRT, proc.stdout + proc.stderr
    assert not result_path.with_name(result_path.name + ".orig").exists()
    result = check_canonical(result_path, PACKAGE, "crash_test")
    case = result.summary.only
    assert (case.classname, case.name, case.outcome) == ("pkg.crash_test", "crash_test", "failure")
    for text in (case.message, case.text):
        assert "killed by SIGABRT (signal 6)" in text
        assert "[ RUN      ] Crash.Abort" in text
        assert "about to abort" in text
    assert result.properties["signal"] == "SIGABRT"
    assert "exit_code" not in result.properties


# --- pytest --------------------------------------------------------------------------------

PYTEST_MODULE = """\
import pytest


@pytest.fixture
def broken_setup():
    raise RuntimeError("fixture setup broke")


@pytest.fixture
def broken_teardown():
    yield
    raise RuntimeError("teardown broke")


def test_pass():
    assert True


def test_fail():
    assert 1 == 2, "one is not two"


def test_fixture_error(broken_setup):
    pass


def test_skip():
    pytest.skip("skip reason")


@pytest.mark.xfail(reason="known bug")
def test_xfail():
    assert False


class TestGroup:
    @pytest.mark.parametrize("value", [1, 2, 3])
    def test_param(self, value):
        assert value < 3


def test_fail_and_teardown(broken_teardown):
    assert False, "call failed"
"""


def _pytest_run(
    runner_script: str, env: dict[str, str], tmp_path: Path, family: str
) -> tuple[subprocess.CompletedProcess[str], Path]:
    """pytest as ament_add_pytest_test runs it, with the junit family chosen."""
    tests = tmp_path / "src"
    tests.mkdir()
    (tests / "pytest.ini").write_text("[pytest]\n")  # keep this repo's config out
    (tests / "test_mod.py").write_text(PYTEST_MODULE)
    result = tmp_path / "test_results" / PACKAGE / f"test_mod_{family}.xunit.xml"
    command = [
        sys.executable,
        "-u",
        "-m",
        "pytest",
        str(tests / "test_mod.py"),
        "-o",
        f"cache_dir={tmp_path / 'cache'}",
        "-o",
        f"junit_family={family}",
        f"--junit-xml={result}",
        f"--junit-prefix={PACKAGE}",
    ]
    clean = {key: value for key, value in env.items() if not key.startswith("PYTEST_")}
    return _ament(runner_script, clean, result, command, tests), result


@pytest.mark.parametrize("family", ["xunit1", "xunit2"])
def test_pytest_in_both_families(
    runner_script: str, env: dict[str, str], tmp_path: Path, family: str
) -> None:
    proc, path = _pytest_run(runner_script, env, tmp_path, family)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    result = check_canonical(path, PACKAGE, f"test_mod_{family}")
    # 10 testcase elements for 9 tests: test_fail_and_teardown is written twice (call
    # failure, teardown error) and merged. Failures: test_fail, test_param[3] and the
    # merged one; error: the fixture; skipped: skip and xfail.
    assert result.counts == (9, 3, 1, 2)
    assert _outcomes(result) == {
        ("pkg.test_mod", "test_pass"): "passed",
        ("pkg.test_mod", "test_fail"): "failure",
        ("pkg.test_mod", "test_fixture_error"): "error",
        ("pkg.test_mod", "test_skip"): "skipped",
        ("pkg.test_mod", "test_xfail"): "skipped",
        ("pkg.test_mod.TestGroup", "test_param[1]"): "passed",
        ("pkg.test_mod.TestGroup", "test_param[2]"): "passed",
        ("pkg.test_mod.TestGroup", "test_param[3]"): "failure",
        ("pkg.test_mod", "test_fail_and_teardown"): "failure",
    }
    merged = result.case("test_fail_and_teardown")
    for part in ("call failed", "teardown broke"):
        assert part in merged.message
        assert part in merged.text
    assert "fixture setup broke" in result.case("test_fixture_error").message
    assert "one is not two" in result.case("test_fail").text
    original = path.with_name(path.name + ".orig").read_text("utf-8")
    assert original.count('name="test_fail_and_teardown"') == 2


# --- unittest-xml-reporting ----------------------------------------------------------------

UNITTEST_MODULE = """\
import unittest


class TestMixed(unittest.TestCase):
    def test_pass(self):
        print("stdout of a passing test")

    def test_fail(self):
        self.assertEqual(1, 2, "one is not two")

    def test_error(self):
        raise ValueError("boom")

    @unittest.skip("skip reason")
    def test_skip(self):
        pass

    @unittest.expectedFailure
    def test_xfail(self):
        self.assertEqual(1, 2)


class TestBrokenClass(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        raise RuntimeError("class set-up broke")

    def test_never_runs(self):
        pass
"""

XMLRUNNER_OUTCOMES = {
    ("pkg.test_umod.TestMixed", "test_pass"): "passed",
    ("pkg.test_umod.TestMixed", "test_fail"): "failure",
    ("pkg.test_umod.TestMixed", "test_error"): "error",
    ("pkg.test_umod.TestMixed", "test_skip"): "skipped",
    ("pkg.test_umod.TestMixed", "test_xfail"): "skipped",
    # The class comes from the parentheses; xmlrunner writes classname="".
    ("pkg.test_umod.TestBrokenClass", "setUpClass (test_umod.TestBrokenClass)"): "error",
}


def _unittest_dir(tmp_path: Path) -> Path:
    tests = tmp_path / "src"
    tests.mkdir()
    (tests / "test_umod.py").write_text(UNITTEST_MODULE)
    return tests


def test_xmlrunner_single_file(runner_script: str, env: dict[str, str], tmp_path: Path) -> None:
    tests = _unittest_dir(tmp_path)
    result_path = tmp_path / "test_results" / PACKAGE / "umod.xunit.xml"
    command = [
        sys.executable,
        "-m",
        "xmlrunner",
        "--output-file",
        str(result_path),
        "discover",
        "-p",
        "test_umod.py",
    ]
    proc = _ament(runner_script, env, result_path, command, tests)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    result = check_canonical(result_path, PACKAGE, "umod")
    assert result.counts == (6, 1, 2, 2)
    assert _outcomes(result) == XMLRUNNER_OUTCOMES
    broken = result.case("setUpClass (test_umod.TestBrokenClass)")
    assert "class set-up broke" in broken.message
    assert "RuntimeError: class set-up broke" in broken.text
    passing = result.element("test_pass")
    assert "stdout of a passing test" in (passing.findtext("system-out") or "")
    original = result_path.with_name(result_path.name + ".orig").read_text("utf-8")
    assert 'name="test_umod.TestMixed-2' in original  # the timestamped suite name


def test_xmlrunner_output_directory(env: dict[str, str], tmp_path: Path) -> None:
    """One file per class, each named and suffixed with a timestamp, through ``normalise``."""
    tests = _unittest_dir(tmp_path)
    out = tmp_path / "reports"
    proc = subprocess.run(
        [sys.executable, "-m", "xmlrunner", "discover", "-o", str(out), "-p", "test_umod.py"],
        check=False,
        capture_output=True,
        text=True,
        cwd=tests,
        env=env,
        timeout=60,
    )
    assert proc.returncode == 1, proc.stdout + proc.stderr
    files = sorted(out.glob("TEST-*.xml"))
    assert len(files) == 2, files
    seen: dict[tuple[str, str], str] = {}
    for source in files:
        canonical = tmp_path / f"canonical-{source.name}"
        done = run_cli(
            ["normalise", "--package-name", PACKAGE, "-o", str(canonical), str(source)], env
        )
        assert done.returncode == 1, done.stdout + done.stderr
        result = check_canonical(canonical, PACKAGE, source.name[: -len(".xml")])
        seen.update(_outcomes(result))
    assert seen == XMLRUNNER_OUTCOMES

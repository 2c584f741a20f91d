"""Make the result-file samples in tests/data/xunit again, with the real producers.

Run by hand, never by the suite: ``.venv/bin/python tests/data/regenerate.py [PRODUCER...]``
(producers: gtest, pytest, xmlrunner, ctest, ctest4, ament, launch_testing; all when none is
named). Each producer is checked for the version its file names say; when it differs its
committed files are kept, the run says why and exits 1, so a name never lies. Every
program runs in a fresh temporary folder; that folder's path is replaced by ``/ws`` (and
the host name by ``vm``) so no file names this machine. Timestamps and durations change
from run to run; everything the tests rely on does not (tests/data/README.md).

ctest 4.4.4 comes from PyPI's ``cmake`` wheel: pass ``--cmake4 BIN_DIR`` holding its
``cmake`` and ``ctest``, or let the script install it into a throwaway venv. launch_testing
is read from the real Jazzy sources beside the checkout (``../shared/vendor``); only its
result serialiser and result classes are loaded, which need nothing but the standard
library.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import textwrap
from collections.abc import Callable, Sequence
from pathlib import Path

HERE = Path(__file__).resolve().parent
OUT = HERE / "xunit"
REPO = HERE.parents[1]
LAUNCH_SOURCES = (
    REPO.parent / "shared" / "vendor" / "ros2-launch-jazzy" / "launch_testing" / "launch_testing"
)
NEUTRAL = "/ws"


class Unavailable(Exception):
    """A producer (or the version the file names) is not on this machine."""


def run(command: Sequence[str], cwd: Path, ok: Sequence[int] = (0,)) -> str:
    """Run ``command`` in ``cwd``; its output, or an error unless it exits with one of ``ok``."""
    env = {**os.environ, "LC_ALL": "C.UTF-8", "TZ": "UTC"}
    env.pop("ROS_DOMAIN_ID", None)
    done = subprocess.run(list(command), cwd=cwd, env=env, capture_output=True, check=False)
    if done.returncode not in ok:
        raise RuntimeError(
            f"{command} exited {done.returncode}, expected {list(ok)}:\n"
            f"{done.stdout.decode(errors='replace')}{done.stderr.decode(errors='replace')}"
        )
    return done.stdout.decode(errors="replace")


def scrub(data: bytes, work: Path) -> bytes:
    """Replace the work folder (as given and as resolved) and the host name."""
    for folder in {str(work), os.path.realpath(work)}:
        data = data.replace(folder.encode(), NEUTRAL.encode())
    host = socket.gethostname().encode()
    return data.replace(b'hostname="' + host + b'"', b'hostname="vm"')


def save(source: Path, name: str, work: Path) -> None:
    data = scrub(source.read_bytes(), work)
    for place in (REPO.parent, Path(tempfile.gettempdir()), Path.home()):
        if str(place) != "/" and str(place).encode() + b"/" in data:
            raise RuntimeError(f"{name} still names a path of this machine: {place}")
    (OUT / name).write_bytes(data)
    print(f"  wrote {name}")


def write(folder: Path, files: dict[str, str]) -> None:
    for name, text in files.items():
        path = folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(text).lstrip("\n"), encoding="utf-8")


def need_version(what: str, found: str, wanted: str) -> None:
    if not found.startswith(wanted):
        raise Unavailable(f"{what} {found} is here, the samples name {wanted}")


# --- googletest ----------------------------------------------------------------------------

# Line numbers matter to nobody, but each test sits on its own line as in the old samples.
GTEST_MIXED = r"""
#include <gtest/gtest.h>
#include <stdexcept>

TEST(Suite1, Pass) {}
TEST(Suite1, Fail) {
  EXPECT_EQ(1, 2) << "msg with <angle> & \"quotes\" and ]]> end"; EXPECT_TRUE(false); }
TEST(Suite1, Skip) { GTEST_SKIP() << "skipping reason"; }
TEST(Suite1, DISABLED_Dis) {}
TEST(Suite1, Prop) { RecordProperty("mykey", "myval"); RecordProperty("num", 42); }
TEST(Suite1, Ctrl) { FAIL() << "ctrl chars \x1b[31m and bad utf8 \xff\xfe end"; }
TEST(Suite1, Throws) { throw std::runtime_error("boom"); }
struct Fix : ::testing::Test {
  static void SetUpTestSuite() { RecordProperty("suitekey", "suiteval"); } };
TEST_F(Fix, A) {}
struct P : ::testing::TestWithParam<int> {};
TEST_P(P, Param) { EXPECT_LT(GetParam(), 2); }
INSTANTIATE_TEST_SUITE_P(Inst, P, ::testing::Values(1, 2));
template <typename T> struct Ty : ::testing::Test {};
using Types = ::testing::Types<int, double>;
TYPED_TEST_SUITE(Ty, Types);
TYPED_TEST(Ty, T1) {}
struct SF : ::testing::Test { static void SetUpTestSuite() { FAIL() << "suite setup failure"; } };
TEST_F(SF, X) {}
"""
GTEST_ENV = r"""
#include <gtest/gtest.h>
struct Env : ::testing::Environment {
  void SetUp() override {
    ::testing::Test::RecordProperty("envkey", "envval"); ADD_FAILURE() << "env failure"; }
};
TEST(A, B) {}
TEST(A, Crash) {}
int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  ::testing::AddGlobalTestEnvironment(new Env);
  return RUN_ALL_TESTS();
}
"""
#: A shuffle seed that keeps B before Crash (the root then carries random_seed).
GTEST_SEED = "2"


def gtest(work: Path) -> None:
    found = run(["dpkg-query", "-W", "-f=${Version}", "libgtest-dev"], work).split("-")[0]
    need_version("libgtest-dev", found, "1.12.1")
    write(work, {"t.cpp": GTEST_MIXED, "env.cpp": GTEST_ENV})
    libs = ["-lgtest", "-pthread"]
    run(["g++", "-std=c++17", "t.cpp", "-o", "t", *libs, "-lgtest_main"], work)
    run(["g++", "-std=c++17", "env.cpp", "-o", "env", *libs], work)
    run(["./t", "--gtest_output=xml:mixed.xml"], work, ok=(1,))
    seed = f"--gtest_random_seed={GTEST_SEED}"
    run(["./env", "--gtest_output=xml:env.xml", "--gtest_shuffle", seed], work, ok=(1,))
    save(work / "mixed.xml", f"gtest-{found}_mixed.gtest.xml", work)
    save(work / "env.xml", f"gtest-{found}_env_failure.xml", work)


# --- pytest --------------------------------------------------------------------------------

PYTEST_SOURCES = {
    "test_sample.py": """
        import logging
        import sys

        import pytest


        def test_pass(record_property):
            record_property("mykey", "myval")


        def test_fail():
            print("stdout of failing test \\x01\\x1b[31m ctrl ]]> end")
            sys.stderr.write("stderr of failing test\\n")
            logging.getLogger(__name__).warning("a log record")
            assert 1 == 2, "one is not two <&>"


        @pytest.fixture
        def broken():
            raise RuntimeError("fixture setup broke")


        def test_setup_error(broken):
            pass


        @pytest.fixture
        def broken_teardown():
            yield
            raise RuntimeError("teardown broke")


        def test_teardown_error(broken_teardown):
            pass


        @pytest.mark.skip(reason="skip reason here")
        def test_skip():
            pass


        def test_skip_inside():
            pytest.skip("skipped at runtime")


        @pytest.mark.xfail(reason="known bug")
        def test_xfail():
            assert False


        @pytest.mark.xfail(reason="not strict")
        def test_xpass():
            pass


        @pytest.mark.xfail(reason="strict", strict=True)
        def test_xpass_strict():
            pass


        class TestClass:
            @pytest.mark.parametrize("value", ["1", "a b"])
            def test_param(self, value, record_xml_attribute):
                record_xml_attribute("custom_attr", "x")


        def test_suite_prop(record_testsuite_property):
            record_testsuite_property("suitekey", "suiteval")
        """,
    "test_out.py": """
        import logging
        import sys

        def test_pass_out():
            print("pass stdout")
            sys.stderr.write("pass stderr\\n")

        def test_fail_out():
            print("fail stdout ctrl:\\x01\\x02\\x1b[0m surrogate:\\ud800 nonchar:\\ufffe "
                  "emoji:\\U0001F600 cdata-end:]]> amp:&")
            sys.stderr.write("fail stderr\\n")
            logging.getLogger("x").warning("log warning")
            assert False
        """,
    "dbl/test_dbl.py": """
        import pytest
        @pytest.fixture
        def td():
            yield
            raise RuntimeError("teardown broke")
        def test_fail_and_teardown(td):
            assert False
        """,
    "dbl/test_collect_err.py": """
        import nonexistent_module_xyz
        """,
    "rr/test_flaky.py": """
        from pathlib import Path
        def test_flaky():
            marker = Path(__file__).with_name("ran-once")
            ran_before = marker.exists()
            marker.touch()
            assert ran_before, "fails the first time only"
        def test_always_fails():
            assert False, "always"
        """,
    "empty/test_nothing.py": """
        VALUE = 1
        """,
}


def pytest(work: Path) -> None:
    found = importlib.metadata.version("pytest")
    need_version("pytest", found, "9.2.")
    importlib.metadata.version("pytest-rerunfailures")  # raises when it is missing
    write(work, PYTEST_SOURCES)
    base = [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-q"]
    runs: dict[str, tuple[list[str], int]] = {
        "xunit1": (["-o", "junit_family=xunit1", "--junit-prefix=mypkg", "test_sample.py"], 1),
        "xunit2": (["-o", "junit_family=xunit2", "--junit-prefix=mypkg", "test_sample.py"], 1),
        "xunit2_junit_logging_all": (["-o", "junit_logging=all", "test_out.py"], 1),
        "fail_plus_teardown_error": (["dbl/test_dbl.py"], 1),
        "collection_error": (["--junit-prefix=mypkg", "dbl/test_collect_err.py"], 2),
        "rerunfailures": (["--reruns", "1", "--junit-prefix=mypkg", "rr/test_flaky.py"], 1),
        "no_tests": (["empty/test_nothing.py"], 5),
    }
    short = ".".join(found.split(".")[:2])
    for name, (args, code) in runs.items():
        xml = work / f"{name}.xml"
        run([*base, f"--junit-xml={xml}", *args], work, ok=(code,))
        save(xml, f"pytest-{short}_{name}.xml", work)


# --- unittest-xml-reporting ----------------------------------------------------------------

XMLRUNNER_SOURCES = {
    "test_u.py": '''
        import sys
        import unittest

        class TestA(unittest.TestCase):
            def test_pass(self):
                """Docstring -- here"""
                print("stdout text ]]> xy")
            def test_fail(self):
                sys.stderr.write("err text\\n")
                self.assertEqual(1, 2, "msg <&>")
            def test_error(self):
                raise ValueError("boom")
            @unittest.skip("why skipped")
            def test_skip(self):
                pass
            @unittest.expectedFailure
            def test_xfail(self):
                raise AssertionError("x")
            @unittest.expectedFailure
            def test_xpass(self):
                pass
            def test_sub(self):
                for i in range(2):
                    with self.subTest(i=i):
                        self.assertEqual(i, 0)

        class TestB(unittest.TestCase):
            def test_b(self):
                pass
        ''',
    "test_suc.py": """
        import unittest
        class T(unittest.TestCase):
            @classmethod
            def setUpClass(cls): raise RuntimeError("class setup broke")
            def test_never(self):
                pass
        """,
}


def xmlrunner(work: Path) -> None:
    found = importlib.metadata.version("unittest-xml-reporting")
    need_version("unittest-xml-reporting", found, "4.0.")
    write(work, XMLRUNNER_SOURCES)
    base = [sys.executable, "-m", "xmlrunner"]
    run([*base, "--output-file", "single.xml", "test_u"], work, ok=(1,))
    run([*base, "-o", "per_class", "test_u"], work, ok=(1,))
    run([*base, "--output-file", "suc.xml", "test_suc"], work, ok=(1,))
    (per_class,) = (work / "per_class").glob("TEST-test_u.TestB-*.xml")
    short = ".".join(found.split(".")[:2])
    save(work / "single.xml", f"xmlrunner-{short}_single_file.xml", work)
    save(per_class, f"xmlrunner-{short}_per_class_file.xml", work)
    save(work / "suc.xml", f"xmlrunner-{short}_setUpClass_error.xml", work)


# --- ctest ---------------------------------------------------------------------------------

CTEST_PROJECT = {
    "CMakeLists.txt": """
        cmake_minimum_required(VERSION 3.21)
        project(samples NONE)
        enable_testing()
        set(S ${CMAKE_CURRENT_SOURCE_DIR})
        add_test(NAME pass COMMAND sh ${S}/pass.sh)
        add_test(NAME fail COMMAND sh ${S}/fail.sh)
        add_test(NAME skip COMMAND sh ${S}/skip.sh)
        set_tests_properties(skip PROPERTIES SKIP_RETURN_CODE 77)
        add_test(NAME disabled COMMAND true)
        set_tests_properties(disabled PROPERTIES DISABLED TRUE)
        add_test(NAME timeout COMMAND sleep 30)
        set_tests_properties(timeout PROPERTIES TIMEOUT 1)
        add_test(NAME notfound COMMAND /nonexistent/binary)
        add_test(NAME willfail COMMAND false)
        set_tests_properties(willfail PROPERTIES WILL_FAIL TRUE LABELS "lab1;lab2")
        add_test(NAME regexfail COMMAND sh ${S}/regexfail.sh)
        set_tests_properties(regexfail PROPERTIES FAIL_REGULAR_EXPRESSION "ERROR")
        add_test(NAME segv COMMAND sh ${S}/segv.sh)
        add_test(NAME bigout COMMAND sh ${S}/bigout.sh)
        """,
    "pass.sh": """
        echo "hello stdout"
        echo "hello stderr" >&2
        """,
    # A control character, ANSI colour and a byte that is not UTF-8, as tests print them.
    "fail.sh": r"""
        printf 'failing <&> ]]> out\nctrl\001\033[31mred\033[0m bad\377utf8\n'
        exit 1
        """,
    "skip.sh": """
        echo skipping
        exit 77
        """,
    "regexfail.sh": """
        echo "ERROR happened"
        """,
    "segv.sh": """
        kill -SEGV $$
        """,
    "bigout.sh": """
        yes abcdefghij | head -n 2000
        """,
}


def _ctest(work: Path, bin_dir: Path | None) -> tuple[str, Path]:
    ctest = str(bin_dir / "ctest") if bin_dir else "ctest"
    cmake = str(bin_dir / "cmake") if bin_dir else "cmake"
    version = run([ctest, "--version"], work).split()[2]
    source, build = work / "src", work / "build"
    write(source, CTEST_PROJECT)
    run([cmake, "-S", str(source), "-B", str(build)], work)
    junit = work / "junit.xml"
    run([ctest, "--output-junit", str(junit)], build, ok=(8,))
    return version, junit


def ctest(work: Path) -> None:
    version, junit = _ctest(work, None)
    need_version("ctest", version, "3.25.1")
    save(junit, f"ctest-{version}_output-junit.xml", work)


def ctest4(work: Path, bin_dir: Path | None) -> None:
    if bin_dir is None:
        venv = work / "cmake4-venv"
        run([sys.executable, "-m", "venv", str(venv)], work)
        run([str(venv / "bin" / "pip"), "install", "-q", "cmake==4.4.4"], work)
        bin_dir = venv / "bin"
    version, junit = _ctest(work, bin_dir)
    need_version("ctest", version, "4.4.4")
    save(junit, f"ctest-{version}_output-junit.xml", work)


# --- ament_cmake_test run_test.py ----------------------------------------------------------


def ament(work: Path) -> None:
    need_version("ament_cmake_test", importlib.metadata.version("ament_cmake_test"), "2.5.")
    script = Path(sys.prefix) / "share" / "ament_cmake_test" / "cmake" / "run_test.py"
    if not script.is_file():
        raise Unavailable(f"no run_test.py at {script} (the ros extra installs it)")
    cases = {
        # (result file, run_test.py options, command, exit code): run_test.py's own results.
        "ament_run_test_missing_result.xml": (
            "pkg/missing_result.xml",
            [],
            ["sh", "-c", "echo some output; exit 1"],
            1,
        ),
        "ament_run_test_missing_result_tidied_ansi.xml": (
            "mypkg/ansi.xml",
            [],
            ["sh", "-c", r"printf '\033[31mred\033[0m\n'; exit 1"],
            1,
        ),
        "ament_run_test_skip_result.xml": ("pkg/skipped_test.xml", ["--skip-test"], ["true"], 0),
        "ament_run_test_success_result.xml": (
            "mypkg/e.xml",
            ["--generate-result-on-success"],
            ["true"],
            0,
        ),
    }
    for name, (result, options, command, code) in cases.items():
        path = work / result
        package = path.parent.name
        args = [str(path), "--package-name", package, *options, "--command", *command]
        run([sys.executable, "-u", str(script), *args], work, ok=(code,))
        save(path, name, work)


# --- launch_testing ------------------------------------------------------------------------

LAUNCH_DRIVER = '''
    """Real unittest results through launch_testing's own result classes and serialiser."""
    import importlib.util
    import io
    import sys
    import unittest

    def load(name):
        spec = importlib.util.spec_from_file_location(name, f"{sys.argv[1]}/{name}.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module

    junitxml, test_result = load("junitxml"), load("test_result")
    MESSAGE = sys.argv[3]

    class TestActive(unittest.TestCase):
        def test_ok(self): pass
        def test_fail(self): self.assertEqual(1, 2, MESSAGE)
        def test_err(self): raise RuntimeError("boom")
        @unittest.skip("skipme")
        def test_skip(self): pass

    class TestPost(unittest.TestCase):
        def test_exit_codes(self): pass

    class Run:
        """The cases of one launch test run, as SkipResult and FailResult ask for them."""
        def all_cases(self):
            return [TestPost("test_exit_codes")]

    def ran(case_class):
        stream = unittest.runner._WritelnDecorator(io.StringIO())
        result = test_result.TestResult(stream, True, 1)
        unittest.TestLoader().loadTestsFromTestCase(case_class).run(result)
        return result

    active = ran(TestActive)
    active.append(ran(TestPost))
    results = {
        "mypkg.test_file.launch_tests": active,
        "mypkg.test_file.launch_tests[skipped_run]": test_result.SkipResult(
            Run(), "skip decorator reason"
        ),
        "mypkg.test_file.launch_tests[died_run]": test_result.FailResult(
            Run(), "Launch stopped before the active tests finished."
        ),
    }
    tree = junitxml.unittestResultsToXml(name="mypkg.test_file", test_results=results)
    tree.write(sys.argv[2], encoding="utf-8", xml_declaration=True)
'''


def launch_testing(work: Path) -> None:
    if not (LAUNCH_SOURCES / "junitxml.py").is_file():
        raise Unavailable(f"needs the real launch_testing sources at {LAUNCH_SOURCES}")
    write(work, {"drive.py": LAUNCH_DRIVER})
    for name, message in (
        ("launch_testing_junitxml.xml", "bad <&>"),
        # launch_testing writes a control character in a message raw: not well-formed.
        ("launch_testing_junitxml_ctrlchar_INVALID.xml", "bad \x01 <&>"),
    ):
        xml = work / name
        run([sys.executable, "drive.py", str(LAUNCH_SOURCES), str(xml), message], work)
        save(xml, name, work)


# --- main ----------------------------------------------------------------------------------


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    producers: dict[str, Callable[[Path], None]] = {
        "gtest": gtest,
        "pytest": pytest,
        "xmlrunner": xmlrunner,
        "ctest": ctest,
        "ctest4": lambda work: ctest4(work, options.cmake4),
        "ament": ament,
        "launch_testing": launch_testing,
    }
    parser.add_argument("producers", nargs="*", help=f"any of {', '.join(producers)}")
    parser.add_argument("--cmake4", type=Path, help="bin folder with cmake and ctest 4.4.4")
    options = parser.parse_args()
    unknown = set(options.producers) - set(producers)
    if unknown:
        parser.error(f"unknown producers {sorted(unknown)}; choose from {', '.join(producers)}")
    failed = []
    for name in options.producers or producers:
        print(name)
        with tempfile.TemporaryDirectory(prefix=f"rit-samples-{name}-") as folder:
            try:
                producers[name](Path(folder))
            except Unavailable as why:
                print(f"  kept the committed files: {why}")
                failed.append(name)
    shutil.rmtree(HERE / "__pycache__", ignore_errors=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())

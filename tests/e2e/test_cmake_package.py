"""The CMake package shipped in the Python distribution: find_package(ros_isolated_test).

Real colcon, CMake and ctest on examples/isolated_all, found from PATH alone (no
CMAKE_PREFIX_PATH): ros_isolated_test_all() puts six plain ament_add_test token tests on
six distinct domain IDs, where the same package without that line hears crosstalk (the
control); each ros_isolated_add_* macro (gtest, gmock, pytest, plain) runs its test through
our runner, the pytest ones with the pytest plugin on, keeping the runner's ID; a RUNNER a
call names itself wins. Quick configure-only projects check the edges: calling
ros_isolated_test_all() twice, a wrapper defined after it (an error, not a recursion),
every argument passing through the wrapper, macros finding packages once, and the error
when no runner is found. A real wheel installs the CMake files where CMake finds them.
"""

from __future__ import annotations

import importlib
import json
import os
import re
import subprocess
import sys
import zipfile
from pathlib import Path
from typing import Any

import pytest
from helpers import capabilities
from helpers.cmake_package import (
    CMAKE_FILES,
    PackageBuild,
    build_wheel,
    install_wheel,
    installed_prefix,
    path_only_env,
)
from helpers.commands import REPO
from helpers.domains import free_ids
from helpers.results import load_result
from lxml import etree

import ros_isolated_test

pytestmark = [pytest.mark.colcon, capabilities.COLCON.mark]

TOKEN_TESTS = [f"token_talker_{i}" for i in range(1, 7)]
MACRO_TESTS = ["macro_gtest", "macro_gmock", "macro_pytest", "macro_test", "all_pytest"]
PYTEST_TESTS = ("macro_pytest", "all_pytest")


@pytest.fixture(scope="module")
def package_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("isolated_all_ws")


@pytest.fixture(scope="module")
def one_line(package_root: Path) -> PackageBuild:
    """The package with ros_isolated_test_all() and every macro's test, built once."""
    capabilities.require(capabilities.GTEST, capabilities.GMOCK)
    return PackageBuild(package_root, "one_line", ["-DISOLATED_ALL=ON", "-DISOLATED_MACROS=ON"])


@pytest.fixture(scope="module")
def without_the_line(package_root: Path) -> PackageBuild:
    """The control: the same six token tests without ros_isolated_test_all()."""
    return PackageBuild(
        package_root, "without_the_line", ["-DISOLATED_ALL=OFF", "-DISOLATED_MACROS=OFF"]
    )


@pytest.fixture
def one_line_run(one_line: PackageBuild) -> str:
    return one_line.test(jobs=6)


def _properties(result_file: Path) -> dict[str, str]:
    tree = etree.parse(str(result_file))
    return {p.get("name", ""): p.get("value", "") for p in tree.iter("property")}


def _runner_path() -> str:
    done = subprocess.run(
        [str(Path(sys.executable).parent / "ros-isolated-test"), "runner-path"],
        capture_output=True,
        text=True,
        check=True,
    )
    return done.stdout.strip()


def test_found_from_path_alone(one_line: PackageBuild) -> None:
    assert "CMAKE_PREFIX_PATH" not in one_line.env
    found = Path(one_line.cache_value("ros_isolated_test_DIR"))
    assert found == installed_prefix(one_line.base.parent) / "share/ros_isolated_test/cmake"


def test_one_line_six_token_tests_pass_on_distinct_ids(
    one_line: PackageBuild, one_line_run: str
) -> None:
    runners = one_line.runners()
    assert {runners[name] for name in TOKEN_TESTS} == {_runner_path()}, runners
    records = one_line.records_by_token()
    assert len(records) == 6, f"records: {sorted(records)}\n{one_line_run}"
    failed = {r.token: r.foreign for r in records.values() if not r.passed}
    assert not failed, f"crosstalk despite ros_isolated_test_all(): {failed}\n{one_line_run}"
    ids = [r.domain_id for r in records.values()]
    assert None not in ids and len(set(ids)) == 6, f"domain IDs: {ids}"
    summary = one_line.result_summary()
    assert (summary.returncode, summary.errors, summary.failures) == (0, 0, 0), (
        f"{summary.line}\n{one_line_run}"
    )


def test_without_the_line_the_token_tests_hear_crosstalk(without_the_line: PackageBuild) -> None:
    output = without_the_line.test(jobs=6)
    runners = without_the_line.runners()
    assert all(runners[name].endswith("/run_test.py") for name in TOKEN_TESTS), runners
    records = without_the_line.records_by_token()
    assert len(records) == 6, f"records: {sorted(records)}\n{output}"
    assert all(r.domain_id is None for r in records.values())
    heard = [r for r in records.values() if not r.passed and r.foreign]
    assert len(heard) >= 4, f"only {len(heard)} of 6 heard crosstalk: control too weak\n{output}"
    assert without_the_line.result_summary().failures > 0


@pytest.mark.parametrize("name", MACRO_TESTS)
def test_each_macro_runs_through_our_runner(
    one_line: PackageBuild, one_line_run: str, name: str
) -> None:
    assert one_line.runners()[name] == _runner_path()
    (result_file,) = one_line.results_dir.glob(f"{name}.*xml")
    properties = _properties(result_file)
    assert properties.get("ros_domain_id", "").isdigit(), f"{properties}\n{one_line_run}"
    assert "runner_version" in properties  # written by our runner, not by the test
    failures = etree.parse(str(result_file)).xpath("//failure | //error")
    assert not failures, f"{result_file}:\n{result_file.read_text()}"
    if name in PYTEST_TESTS:
        # Runner, ament_add_pytest_test and the pytest plugin together: the plugin keeps
        # the runner's ID (no second reservation) and says so in pytest's header.
        output = (one_line.build_dir / "ament_cmake_pytest" / f"{name}.txt").read_text()
        held = f"ros-isolated-test: ROS_DOMAIN_ID {properties['ros_domain_id']}, held by the runner"
        assert held in output.splitlines(), output


def test_a_runner_of_the_call_own_wins(one_line: PackageBuild, one_line_run: str) -> None:
    assert one_line.runners()["own_runner"].endswith("/ament_cmake_test/cmake/run_test.py")
    result_file = one_line.results_dir / "own_runner.xml"
    assert "ros_domain_id" not in _properties(result_file), one_line_run
    assert not etree.parse(str(result_file)).xpath("//failure | //error"), one_line_run


def _configure(
    tmp_path: Path, body: str, *cmake_args: str, ament: str = "find_package(ament_cmake REQUIRED)\n"
) -> subprocess.CompletedProcess[str]:
    """Configure a tiny ament_cmake project (no build, no tests run) from PATH alone."""
    source = tmp_path / "src"
    source.mkdir(exist_ok=True)
    (source / "CMakeLists.txt").write_text(
        "cmake_minimum_required(VERSION 3.20)\nproject(tiny NONE)\n"
        f"{ament}find_package(ros_isolated_test 0.1 REQUIRED)\n"
        "enable_testing()\n" + body
    )
    env = path_only_env(installed_prefix(tmp_path))
    return subprocess.run(
        ["cmake", "-S", str(source), "-B", str(tmp_path / "build"),
         f"-DPython3_EXECUTABLE={sys.executable}", *cmake_args],
        env=env, capture_output=True, text=True, check=False,
    )  # fmt: skip


def test_calling_ros_isolated_test_all_twice_does_not_recurse(tmp_path: Path) -> None:
    done = _configure(
        tmp_path,
        "ros_isolated_test_all()\nros_isolated_test_all()\n"
        "ament_add_test(twice COMMAND true GENERATE_RESULT_FOR_RETURN_CODE_ZERO)\n",
    )
    assert done.returncode == 0, done.stderr
    ctest_file = (tmp_path / "build" / "CTestTestfile.cmake").read_text()
    assert f'"-u" "{_runner_path()}"' in ctest_file, ctest_file


def test_every_argument_passes_through_the_wrapper_intact(tmp_path: Path) -> None:
    """ENV with spaces, APPEND_ENV, TIMEOUT, WORKING_DIRECTORY and RUNNER "" reach ctest.

    Two tests in a row also show the wrapper's re-entry guard is cleared after each call.
    """
    workdir = tmp_path / "work dir"
    done = _configure(
        tmp_path,
        "ros_isolated_test_all()\n"
        'ament_add_test(first COMMAND true ENV "GREETING=hello there" OTHER=1\n'
        f'  APPEND_ENV "EXTRA_PATH=/a b" TIMEOUT 77 WORKING_DIRECTORY "{workdir}"\n'
        '  RUNNER "" GENERATE_RESULT_FOR_RETURN_CODE_ZERO)\n'
        "ament_add_test(second COMMAND echo second)\n",
    )
    assert done.returncode == 0, done.stderr
    ctest_file = (tmp_path / "build" / "CTestTestfile.cmake").read_text()
    first = next(line for line in ctest_file.splitlines() if "[=[first]=]" in line)
    runner = _runner_path()
    assert f'"-u" "{runner}"' in first, first
    assert '"--env" "GREETING=hello there" "OTHER=1"' in first, first
    assert '"--append-env" "EXTRA_PATH=/a b"' in first, first
    assert '"--generate-result-on-success" ' in first, first
    assert '"--command" "true"' in first, first
    assert f'WORKING_DIRECTORY "{workdir}"' in ctest_file, ctest_file
    assert 'TIMEOUT "77"' in ctest_file, ctest_file
    second = next(line for line in ctest_file.splitlines() if "[=[second]=]" in line)
    assert f'"-u" "{runner}"' in second and '"--command" "echo" "second"' in second, second


def test_a_wrapper_defined_after_the_line_is_a_clear_error_not_a_recursion(
    tmp_path: Path,
) -> None:
    """Another package wrapping ament_add_test after ros_isolated_test_all() made CMake recurse
    until its depth limit; the wrapper's guard names the cause and the fix instead."""
    done = _configure(
        tmp_path,
        "ros_isolated_test_all()\n"
        "function(ament_add_test testname)\n  _ament_add_test(${testname} ${ARGN})\n"
        "endfunction()\n"
        "ament_add_test(wrapped_twice COMMAND true)\n",
    )
    assert done.returncode != 0, done.stdout
    message = " ".join(done.stderr.split())
    assert "recursion" not in message.lower(), message
    assert (
        "ament_add_test(wrapped_twice) reached the wrapper of ros_isolated_test_all() "
        "twice" in message
    ), message
    assert "redefined ament_add_test after ros_isolated_test_all() was called" in message
    assert "use the ros_isolated_add_* macros" in message, message


def test_the_macros_find_ament_packages_once_for_the_caller(tmp_path: Path) -> None:
    """What a ros_isolated_add_* macro finds stays found: the next call looks up nothing."""
    (tmp_path / "src").mkdir()
    (tmp_path / "src" / "test_x.py").write_text("def test_x() -> None:\n    pass\n")
    done = _configure(
        tmp_path,
        "ros_isolated_add_pytest_test(first test_x.py)\n"
        'message(STATUS "after the first: FOUND=[${ament_cmake_pytest_FOUND}]")\n'
        "ros_isolated_add_pytest_test(second test_x.py)\n",
    )
    assert done.returncode == 0, done.stderr
    assert "after the first: FOUND=[1]" in done.stdout or (
        "after the first: FOUND=[TRUE]" in done.stdout
    ), done.stdout
    assert done.stdout.count("Found ament_cmake_pytest") == 1, done.stdout
    ctest_file = (tmp_path / "build" / "CTestTestfile.cmake").read_text()
    assert ctest_file.count(f'"-u" "{_runner_path()}"') == 2, ctest_file


def test_the_macros_read_the_escapes_of_a_call_once(tmp_path: Path) -> None:
    r"""``"a\\\\b"`` reaches the test as ``a\b``, ``"c\\$d"`` as ``c$d``: read once, as in a macro.

    The one wrapper behind the macros is itself a macro: had it been handed the call's
    ARGN, CMake would read the escapes a second time (``a\b`` is then an invalid escape,
    ``c$d`` a variable). The control: ament_add_test itself, a function, reads none.
    """
    done = _configure(
        tmp_path,
        r"""ros_isolated_add_test(wrapped COMMAND echo "a\\\\b" "c\\$d" "e f")
ament_add_test(by_hand RUNNER "${ros_isolated_test_RUNNER}" COMMAND echo "a\\\\b" "c\\$d")
""",
    )
    assert done.returncode == 0, done.stderr
    lines = (tmp_path / "build" / "CTestTestfile.cmake").read_text().splitlines()
    wrapped = next(line for line in lines if "[=[wrapped]=]" in line)
    by_hand = next(line for line in lines if "[=[by_hand]=]" in line)
    assert f'"-u" "{_runner_path()}"' in wrapped, wrapped
    assert r'"--command" "echo" "a\\b" "c\$d" "e f"' in wrapped, wrapped
    assert r'"--command" "echo" "a\\\\b" "c\\\$d"' in by_hand, by_hand


def test_ros_isolated_add_test_finds_ament_cmake_test_as_the_other_macros_find_theirs(
    tmp_path: Path,
) -> None:
    """A package that never found ament_cmake gets its test, not an unknown-command error."""
    body = "ros_isolated_add_test(alone COMMAND true)\n"
    done = _configure(tmp_path, body, ament="")
    assert done.returncode == 0, done.stderr
    ctest_file = (tmp_path / "build" / "CTestTestfile.cmake").read_text()
    assert f'"-u" "{_runner_path()}"' in ctest_file, ctest_file
    (tmp_path / "control").mkdir()
    control = _configure(tmp_path / "control", "ament_add_test(alone COMMAND true)\n", ament="")
    assert control.returncode != 0, control.stdout
    assert "Unknown CMake command" in control.stderr, control.stderr


def _skip_codes(build: Path) -> dict[str, str | None]:
    """Each test's SKIP_RETURN_CODE in a CTestTestfile.cmake (None: none set)."""
    found: dict[str, str | None] = {}
    for line in (build / "CTestTestfile.cmake").read_text().splitlines():
        named = re.match(r"^set_tests_properties\(\[=\[([^\]]+)\]=\] PROPERTIES (.*)\)$", line)
        if named:
            code = re.search(r' SKIP_RETURN_CODE "(\d+)"', f" {named[2]}")
            found[named[1]] = code[1] if code else None
    return found


def test_every_test_of_ours_is_skipped_by_ctest_on_77_unless_it_has_its_own_code(
    tmp_path: Path,
) -> None:
    """In a split the RUNNER exits 77 for a test of another share: ctest must show it
    skipped. The macros and ros_isolated_test_all() give every test they register that
    SKIP_RETURN_CODE, unless it has its own; a test with another RUNNER gets none."""
    (tmp_path / "src").mkdir()
    (tmp_path / "src" / "test_x.py").write_text("def test_x() -> None:\n    pass\n")
    done = _configure(
        tmp_path,
        "ros_isolated_add_test(plain COMMAND true)\n"
        "ros_isolated_add_test(own_code COMMAND true SKIP_RETURN_CODE 4)\n"
        "ros_isolated_add_test(skipped COMMAND true SKIP_TEST)\n"
        "ros_isolated_add_pytest_test(py test_x.py)\n"
        "ament_add_test(by_hand COMMAND true)\n"
        "ros_isolated_test_all()\n"
        "ament_add_test(wrapped COMMAND true)\n"
        'ament_add_test(other COMMAND true RUNNER "${ament_cmake_test_DIR}/run_test.py")\n',
    )
    assert done.returncode == 0, done.stderr
    assert _skip_codes(tmp_path / "build") == {
        "plain": "77", "own_code": "4", "skipped": "0", "py": "77",
        "by_hand": None,  # before ros_isolated_test_all(), no macro: ament's runner, the control
        "wrapped": "77", "other": None,
    }  # fmt: skip


def test_no_runner_is_a_clear_configure_error(tmp_path: Path) -> None:
    missing = tmp_path / "no-such-ros-isolated-test"
    done = _configure(tmp_path, "", f"-DROS_ISOLATED_TEST_EXECUTABLE={missing}")
    assert done.returncode != 0
    message = " ".join(done.stderr.split())
    assert f"'{missing} runner-path' did not print the path of the RUNNER" in message, message
    assert "see Install it in its README" in message, message
    assert "-DROS_ISOLATED_TEST_EXECUTABLE=" in message, message


@capabilities.TOMLLIB
def test_pip_installs_every_cmake_file_beside_the_command() -> None:
    tomllib = importlib.import_module("tomllib")  # 3.11+; the suite also runs on 3.10
    config: dict[str, Any] = tomllib.loads((REPO / "pyproject.toml").read_text())
    shipped = config["tool"]["setuptools"]["data-files"]["share/ros_isolated_test/cmake"]
    on_disk = sorted(str(p.relative_to(REPO)) for p in CMAKE_FILES.glob("*.cmake"))
    assert sorted(shipped) == on_disk
    version = ros_isolated_test.__version__  # pyproject.toml reads it from there
    text = (CMAKE_FILES / "ros_isolated_testConfigVersion.cmake").read_text()
    assert f'set(PACKAGE_VERSION "{version}")' in text


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A real wheel of the project, built once from a copy (the checkout is never written)."""
    return build_wheel(tmp_path_factory.mktemp("wheel"))


def test_the_wheel_ships_every_cmake_file_as_share_data(wheel: Path) -> None:
    with zipfile.ZipFile(wheel) as archive:
        names = archive.namelist()
    prefix = ".data/data/share/ros_isolated_test/cmake/"
    shipped = sorted(name.split(prefix, 1)[1] for name in names if prefix in name)
    assert shipped == sorted(p.name for p in CMAKE_FILES.glob("*.cmake")), names
    assert "ros_isolated_test/ament/run_test_isolated.py" in names, names
    # The old path, for workspaces configured before the script moved: it forwards.
    assert "ros_isolated_test/runner/ament/run_test_isolated.py" in names, names


def test_installed_from_the_wheel_cmake_finds_it_from_path_alone(
    wheel: Path, tmp_path: Path
) -> None:
    """pip install --prefix, then a CMake project configured with only that bin/ on PATH."""
    prefix = tmp_path / "installed"
    site = install_wheel(wheel, prefix)
    assert (Path(sys.executable).parent / "ros-isolated-test").is_file(), ".venv's install gone"
    cmake_dir = prefix / "share" / "ros_isolated_test" / "cmake"
    assert sorted(p.name for p in cmake_dir.iterdir()) == sorted(
        p.name for p in CMAKE_FILES.glob("*.cmake")
    )
    source = tmp_path / "src"
    source.mkdir()
    (source / "CMakeLists.txt").write_text(
        "cmake_minimum_required(VERSION 3.20)\nproject(tiny NONE)\n"
        "find_package(ament_cmake REQUIRED)\nfind_package(ros_isolated_test 0.1 REQUIRED)\n"
        "enable_testing()\nros_isolated_test_all()\n"
        "ament_add_test(installed COMMAND true GENERATE_RESULT_FOR_RETURN_CODE_ZERO)\n"
    )
    env = path_only_env(prefix)  # the installed bin/ first on PATH, no CMAKE_PREFIX_PATH
    env["PYTHONPATH"] = os.pathsep.join(filter(None, (site, env.get("PYTHONPATH"))))
    build = tmp_path / "build"
    done = subprocess.run(
        ["cmake", "-S", str(source), "-B", str(build), f"-DPython3_EXECUTABLE={sys.executable}"],
        env=env, capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    cache = (build / "CMakeCache.txt").read_text()
    assert f"ros_isolated_test_DIR:PATH={cmake_dir}" in cache.splitlines(), cache
    runner = Path(site) / "ros_isolated_test" / "ament" / "run_test_isolated.py"
    assert f'"-u" "{runner}"' in (build / "CTestTestfile.cmake").read_text()


#: Fails the first time it runs (no state file yet), passes after.
_FLAKY_SH = (
    'if [ -e "$1" ]; then echo "passed on $ROS_DOMAIN_ID"; exit 0; fi\n'
    ': > "$1"; echo "failed on $ROS_DOMAIN_ID"; exit 1\n'
)


@capabilities.CTEST.mark
def test_reruns_reach_a_real_ctest_run(tmp_path: Path, env: dict[str, str]) -> None:
    """RERUNS of a macro and of ros_isolated_test_all(): a flaky test passes under ctest,
    its first failure kept as a flakyFailure; the same test without RERUNS fails (control)."""
    (tmp_path / "flaky.sh").write_text(_FLAKY_SH)
    calls = "\n".join(
        f"ros_isolated_add_test({name} COMMAND sh {tmp_path / 'flaky.sh'} {tmp_path / name}"
        f" GENERATE_RESULT_FOR_RETURN_CODE_ZERO{extra})"
        for name, extra in (("macro_flaky", " RERUNS 1"), ("once", ""))
    )
    done = _configure(
        tmp_path,
        f"{calls}\nros_isolated_test_all(RERUNS 1)\n"
        f"ament_add_test(all_flaky COMMAND sh {tmp_path / 'flaky.sh'} {tmp_path / 'all_flaky'}\n"
        "  GENERATE_RESULT_FOR_RETURN_CODE_ZERO)\n",
    )
    assert done.returncode == 0, done.stderr
    ctest_file = (tmp_path / "build" / "CTestTestfile.cmake").read_text()
    assert ctest_file.count('"--env" "ROS_ISOLATED_TEST_RERUNS=1"') == 2, ctest_file
    ctest_env = {
        **path_only_env(installed_prefix(tmp_path)),
        "ROS_ISOLATED_TEST_LOCK_DIR": env["ROS_ISOLATED_TEST_LOCK_DIR"],
        "ROS_ISOLATED_TEST_DOMAINS": ",".join(map(str, free_ids(2))),
    }
    ctest_env.pop("ROS_DOMAIN_ID", None)
    results = tmp_path / "build" / "test_results" / "tiny"
    for name, passes in (("macro_flaky", True), ("all_flaky", True), ("once", False)):
        run = subprocess.run(
            ["ctest", "--test-dir", str(tmp_path / "build"), "-R", f"^{name}$", "-V"],
            env=ctest_env, capture_output=True, text=True, check=False,
        )  # fmt: skip
        assert (run.returncode == 0) is passes, f"{name}: {run.stdout}{run.stderr}"
        root = etree.parse(str(results / f"{name}.xml")).getroot()
        properties = {p.get("name"): p.get("value") for p in root.iter("property")}
        if passes:
            assert root.find(".//flakyFailure") is not None and root.find(".//failure") is None
            first, second = (properties.get("ros_domain_ids") or "").split(", ")
            assert first != second, properties
            assert properties["attempts"] == "2", properties
        else:
            assert root.find(".//failure") is not None and "attempts" not in properties


def test_a_bad_reruns_value_stops_configuring(tmp_path: Path) -> None:
    done = _configure(tmp_path, "ros_isolated_add_test(t COMMAND true RERUNS two)\n")
    assert done.returncode != 0
    message = " ".join(done.stderr.split())
    assert "RERUNS 'two' is not a number of reruns" in message, message
    good = _configure(tmp_path, "ros_isolated_add_test(t COMMAND true RERUNS 2)\n")
    assert good.returncode == 0, good.stderr  # the control


def _ctest(build: Path, env: dict[str, str], *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        ["ctest", "--test-dir", str(build), "--output-on-failure", *args],
        env=env, capture_output=True, text=True, check=False,
    )  # fmt: skip


@capabilities.CTEST.mark
def test_resources_reach_a_real_ctest_run(tmp_path: Path, env: dict[str, str]) -> None:
    """RESOURCES of a macro and of ros_isolated_test_all() become the test's holding, in its
    result file; a call's own ENV wins; a test without them holds nothing (control). The
    capacity comes from ctest's environment: gpu=2 fits ROS_ISOLATED_TEST_CAPACITY=gpu=2,
    and without it (a default capacity of 1) the same test is refused."""
    done = _configure(
        tmp_path,
        "ros_isolated_add_test(macro_gpu COMMAND true GENERATE_RESULT_FOR_RETURN_CODE_ZERO\n"
        "  RESOURCES gpu=2)\n"
        "ros_isolated_add_test(plain COMMAND true GENERATE_RESULT_FOR_RETURN_CODE_ZERO)\n"
        "ros_isolated_test_all(RESOURCES gpu=2)\n"
        "ament_add_test(all_gpu COMMAND true GENERATE_RESULT_FOR_RETURN_CODE_ZERO)\n"
        "ament_add_test(own_env COMMAND true GENERATE_RESULT_FOR_RETURN_CODE_ZERO\n"
        "  ENV ROS_ISOLATED_TEST_RESOURCES=lidar=1)\n",
    )
    assert done.returncode == 0, done.stderr
    ctest_env = {
        **path_only_env(installed_prefix(tmp_path)),
        "ROS_ISOLATED_TEST_LOCK_DIR": env["ROS_ISOLATED_TEST_LOCK_DIR"],
        "ROS_ISOLATED_TEST_DOMAINS": ",".join(map(str, free_ids(2))),
        "ROS_ISOLATED_TEST_CAPACITY": "gpu=2",
    }
    for name in ("ROS_DOMAIN_ID", "ROS_ISOLATED_TEST_RESOURCES"):
        ctest_env.pop(name, None)
    build = tmp_path / "build"
    results = build / "test_results" / "tiny"
    run = _ctest(build, ctest_env)
    assert run.returncode == 0, run.stdout + run.stderr
    held = {
        name: _properties(results / f"{name}.xml").get("resources")
        for name in ("macro_gpu", "all_gpu", "own_env", "plain")
    }
    assert held == {"macro_gpu": "gpu=2", "all_gpu": "gpu=2", "own_env": "lidar=1", "plain": None}
    assert _properties(results / "macro_gpu.xml")["capacity"] == "gpu=2"
    # Without the capacity variable, gpu=2 is more than the machine has: refused, never run.
    del ctest_env["ROS_ISOLATED_TEST_CAPACITY"]
    refused = _ctest(build, ctest_env, "-R", "^macro_gpu$")
    assert refused.returncode != 0, refused.stdout + refused.stderr
    case = load_result(results / "macro_gpu.xml").only
    message = case.message
    assert case.outcome == "error", case
    assert "--env ROS_ISOLATED_TEST_RESOURCES: gpu=2 is more than" in message, message
    assert "ROS_ISOLATED_TEST_CAPACITY=gpu=<amount>" in message, message


@pytest.mark.parametrize(
    ("body", "says"),
    [
        (
            "ros_isolated_add_test(t COMMAND true RESOURCES gpu)\n",
            "RESOURCES 'gpu' is not a request of resources",
        ),
        ("ros_isolated_add_test(t COMMAND true RESOURCES)\n", "RESOURCES '' is not a request"),
        ("ros_isolated_test_all(RESOURCES gpu)\n", "RESOURCES 'gpu' is not a request"),
        ("ros_isolated_test_all(RESOURCES)\n", "RESOURCES '' is not a request"),
    ],
)
def test_a_bad_resources_value_stops_configuring(tmp_path: Path, body: str, says: str) -> None:
    done = _configure(tmp_path, body)
    assert done.returncode != 0, done.stdout
    message = " ".join(done.stderr.split())
    assert says in message and "(e.g. RESOURCES cpu=2,mem=4G,gpu=1)" in message, message


def test_resources_and_reruns_pass_into_ctest(tmp_path: Path) -> None:
    """The control of the errors above, and how the two arguments combine: a later
    ros_isolated_test_all() replaces only what it names; a test with its own RUNNER gets
    neither."""
    done = _configure(
        tmp_path,
        "ros_isolated_add_test(macro COMMAND true RERUNS 1 RESOURCES cpu=1,mem=1G)\n"
        "ros_isolated_test_all(RERUNS 2)\n"
        "ros_isolated_test_all(RESOURCES gpu=1)\n"
        "ament_add_test(wrapped COMMAND true)\n"
        'ament_add_test(own COMMAND true RUNNER "${ament_cmake_test_DIR}/run_test.py")\n',
    )
    assert done.returncode == 0, done.stderr
    lines = (tmp_path / "build" / "CTestTestfile.cmake").read_text().splitlines()
    macro, wrapped, own = (
        next(line for line in lines if f"[=[{name}]=]" in line)
        for name in ("macro", "wrapped", "own")
    )
    assert (
        '"--env" "ROS_ISOLATED_TEST_RERUNS=1" "ROS_ISOLATED_TEST_RESOURCES=cpu=1,mem=1G"' in macro
    ), macro
    assert '"--env" "ROS_ISOLATED_TEST_RERUNS=2" "ROS_ISOLATED_TEST_RESOURCES=gpu=1"' in wrapped, (
        wrapped
    )
    assert "ROS_ISOLATED_TEST_" not in own, own


#: The registered test: its arguments, one a line, then what ``status --json`` shows it
#: holding while it runs (the ROS_DOMAIN_ID the runner gave it finds its hold).
_PROBE_SH = (
    'out="$1"; shift; printf "%s\\n" "$@" > "$out.args"\n'
    'ros-isolated-test status --json > "$out.json"\n'
    'echo "$ROS_DOMAIN_ID" > "$out.id"\n'
)

RESOURCE_FORMS = [
    pytest.param('ros_isolated_add_test(t COMMAND {probe} RESOURCES "gpu=1;cpu=1"{tail})',
                 id="macro-cmake-list"),
    pytest.param("ros_isolated_add_test(t COMMAND {probe} RESOURCES gpu=1 cpu=1{tail})",
                 id="macro-separate-words"),
    pytest.param('ros_isolated_test_all(RESOURCES "gpu=1;cpu=1")\n'
                 "ament_add_test(t COMMAND {probe}{tail})", id="all-cmake-list"),
    pytest.param("ros_isolated_add_test(t COMMAND {probe} RESOURCES gpu=1,cpu=1{tail})",
                 id="control-macro-commas"),
    pytest.param("ros_isolated_test_all(RESOURCES gpu=1,cpu=1)\n"
                 "ament_add_test(t COMMAND {probe}{tail})", id="control-all-commas"),
]  # fmt: skip


@capabilities.CTEST.mark
@pytest.mark.parametrize("call", RESOURCE_FORMS)
def test_a_resources_list_holds_every_request_and_leaves_the_command_alone(
    tmp_path: Path, env: dict[str, str], call: str
) -> None:
    """``RESOURCES "gpu=1;cpu=1"`` held gpu=1 only and appended cpu=1 to the COMMAND (and
    ros_isolated_test_all() refused it). Every form is one request on every path: the
    test, while it runs, sees both held by its runner, and gets only its own arguments.
    The comma-separated forms, which always worked, are the controls."""
    probe = tmp_path / "probe.sh"
    probe.write_text(_PROBE_SH)
    out = tmp_path / "out"
    command = f"sh {probe} {out} first second"
    done = _configure(
        tmp_path, call.format(probe=command, tail=" GENERATE_RESULT_FOR_RETURN_CODE_ZERO") + "\n"
    )
    assert done.returncode == 0, done.stderr
    ctest_env = {
        **path_only_env(installed_prefix(tmp_path)),
        "ROS_ISOLATED_TEST_LOCK_DIR": env["ROS_ISOLATED_TEST_LOCK_DIR"],
        "ROS_ISOLATED_TEST_DOMAINS": ",".join(map(str, free_ids(1))),
        "ROS_ISOLATED_TEST_CAPACITY": "cpu=1,gpu=1",
    }
    for name in ("ROS_DOMAIN_ID", "ROS_ISOLATED_TEST_RESOURCES"):
        ctest_env.pop(name, None)
    build = tmp_path / "build"

    run = _ctest(build, ctest_env)

    assert run.returncode == 0, run.stdout + run.stderr
    assert Path(f"{out}.args").read_text().splitlines() == ["first", "second"]
    domain_id = int(Path(f"{out}.id").read_text())
    rows = json.loads(Path(f"{out}.json").read_text())
    holds = [row for row in rows if row["via"] == "hold"]
    assert [(row["domain_id"], row["resources"]) for row in holds] == [
        (domain_id, {"cpu": 1, "gpu": 1})
    ], rows
    properties = _properties(build / "test_results" / "tiny" / "t.xml")
    assert properties.get("resources") == "cpu=1,gpu=1", properties


def test_a_resources_list_takes_only_the_requests_right_after_it(tmp_path: Path) -> None:
    """The list ends at the first word that is no name=amount request: a name=value word
    in the COMMAND after it stays in the COMMAND, and a RERUNS after it is still read."""
    done = _configure(
        tmp_path,
        'ros_isolated_add_test(t RESOURCES "gpu=1;cpu=1" RERUNS 1 COMMAND env a=b true)\n',
    )
    assert done.returncode == 0, done.stderr
    lines = (tmp_path / "build" / "CTestTestfile.cmake").read_text().splitlines()
    line = next(line for line in lines if "[=[t]=]" in line)
    assert '"--command" "env" "a=b" "true"' in line, line
    assert (
        '"--env" "ROS_ISOLATED_TEST_RERUNS=1" "ROS_ISOLATED_TEST_RESOURCES=gpu=1,cpu=1"' in line
    ), line

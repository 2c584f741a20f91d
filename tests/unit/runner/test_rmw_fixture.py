"""Kilted's rmw_test_fixture inside a test: it keeps the runner's ID, or starts the RMW's own.

The variables the runner sets or leaves for each RMW, read as data: a DDS RMW (or none
set) gets RMW_TEST_FIXTURE_DISABLE_ISOLATION=1, so the default fixture, which chooses an
ID, stays off; an RMW with a fixture library of its own (rmw_zenoh_cpp's starts its
router) keeps the fixture on and gets ``run_rmw_isolated`` in front; what a user set is
kept. Then real runs under Kilted: ``run_rmw_isolated`` and the fixture's Python binding
(what launch_ros's EnableRmwIsolation calls; launch_ros itself has no Kilted wheel) see
exactly the ID the result file records, and, the control, with the variable set empty
they see another, which the result file says may happen. An RMW with a fixture of its own
is a stand-in library (no rmw_zenoh wheel exists) loaded by the real ``run_rmw_isolated``.
"""

from __future__ import annotations

import os
import re
import stat
import subprocess
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import run_process
from helpers.distros import KILTED
from helpers.results import domain_of, load_result

from ros_isolated_test.runner import rmw_fixture
from ros_isolated_test.runner.rmw_fixture import DISABLE_VAR, RUNNER, RUNNER_PACKAGE

#: Prints what the test sees: its ID, and what a fixture of its RMW left it.
SEEN = 'echo "id=$ROS_DOMAIN_ID router=$FAKE_ROUTER disable=$RMW_TEST_FIXTURE_DISABLE_ISOLATION"'
#: The fixture's Python binding around a print: the very call EnableRmwIsolation makes.
BINDING = (
    "import os\n"
    "from rmw_test_fixture_implementation import RMWTestIsolator\n"
    "with RMWTestIsolator():\n"
    "    print('id=' + os.environ['ROS_DOMAIN_ID'], flush=True)\n"
)
#: An RMW's own fixture, as rmw_zenoh_cpp's is to the loader: ``rmw_test_isolation_start``
#: and ``_stop``, here marking the process instead of starting a router.
FAKE_FIXTURE = """
#include <stdlib.h>
int rmw_test_isolation_start(void) { return setenv("FAKE_ROUTER", "started", 1); }
int rmw_test_isolation_stop(void) { return unsetenv("FAKE_ROUTER"); }
"""


def _prefix_with_runner(root: Path) -> Path:
    """A ROS prefix holding ``run_rmw_isolated`` as Kilted's package installs it."""
    marker = root / "share" / "ament_index" / "resource_index" / "packages" / RUNNER_PACKAGE
    marker.parent.mkdir(parents=True)
    marker.write_text("")
    runner = root / "lib" / RUNNER_PACKAGE / RUNNER
    runner.parent.mkdir(parents=True)
    runner.write_text('#!/bin/sh\nexec "$@"\n')
    runner.chmod(runner.stat().st_mode | stat.S_IXUSR)
    return runner


@pytest.mark.parametrize("rmw", ["", "rmw_fastrtps_cpp", "rmw_cyclonedds_cpp", "rmw_zenoh_cpp"])
def test_where_the_default_fixture_would_choose_an_id_it_is_kept_off(
    rmw: str, tmp_path: Path
) -> None:
    """DDS RMWs, none set, and rmw_zenoh_cpp without its fixture library installed."""
    _prefix_with_runner(tmp_path)
    env = {"RMW_IMPLEMENTATION": rmw, "AMENT_PREFIX_PATH": str(tmp_path)}
    fixture = rmw_fixture.decide(env)
    assert fixture.variables() == {DISABLE_VAR: "1"}
    assert fixture.wrapped(["sh", "-c", "true"]) == ("sh", "-c", "true")
    assert fixture.summary(11) == ([], {})  # the silent default


def test_an_rmw_with_a_fixture_of_its_own_keeps_it_and_runs_under_run_rmw_isolated(
    tmp_path: Path,
) -> None:
    runner = _prefix_with_runner(tmp_path / "prefix")
    libs = tmp_path / "libs"
    libs.mkdir()
    (libs / "librmw_zenoh_cpp_test_fixture.so").write_bytes(b"")
    env = {
        "RMW_IMPLEMENTATION": "rmw_zenoh_cpp",
        "LD_LIBRARY_PATH": str(libs),
        "AMENT_PREFIX_PATH": str(tmp_path / "prefix"),
    }
    fixture = rmw_fixture.decide(env)
    assert fixture.variables() == {}
    assert fixture.wrapped(["t"]) == (str(runner), "t")
    # Once, even where the test itself is run_rmw_isolated: one fixture per process.
    assert fixture.wrapped([str(runner), "t"]) == (str(runner), "t")
    lines, properties = fixture.summary(11)
    assert lines and "leaves ROS_DOMAIN_ID 11 as it is" in lines[0]
    assert properties[rmw_fixture.PROPERTY].startswith(f"{RUNNER} in front")
    # Without run_rmw_isolated installed: said, and the test runs as it is.
    alone = rmw_fixture.decide({**env, "AMENT_PREFIX_PATH": str(tmp_path / "none")})
    assert alone.wrapped(["t"]) == ("t",) and alone.variables() == {}
    assert alone.summary(11)[1][rmw_fixture.PROPERTY].startswith("not started")


def test_what_a_user_set_is_kept_and_an_empty_value_is_said_to_move_the_test(
    tmp_path: Path,
) -> None:
    off = rmw_fixture.decide({DISABLE_VAR: "yes"})
    assert off.variables() == {} and off.summary(11) == ([], {})
    on = rmw_fixture.decide({DISABLE_VAR: ""})
    assert on.variables() == {}
    lines, properties = on.summary(11)
    assert lines[0].startswith(f"WARNING: {DISABLE_VAR} is set empty")
    assert "not on 11" in properties[rmw_fixture.PROPERTY]


def _kilted_env(env: dict[str, str], **extra: str) -> dict[str, str]:
    return {**KILTED.env(env), **extra}


def _kilted_run(
    env: dict[str, str], result: Path, *command: str
) -> tuple[subprocess.CompletedProcess[str], int, dict[str, str]]:
    """Our runner, the Kilted venv's (as its ctest runs it), around ``command``: its
    output, the ID it printed first, and the result file's properties."""
    cli = str(KILTED.bin / "ros-isolated-test")
    done = run_process([cli, "run", "--junit-xml", str(result), "--", *command], env)
    assert done.returncode == 0, done.stdout + done.stderr
    return done, domain_of(done.stdout), load_result(result).properties


def _seen(stdout: str) -> int:
    found = re.findall(r"^id=(\d+)", stdout, re.M)
    assert len(found) == 1, stdout
    return int(found[0])


@capabilities.KILTED
def test_kilteds_fixture_sees_the_id_the_result_records(
    env: dict[str, str], tmp_path: Path
) -> None:
    fixture = KILTED.run_rmw_isolated
    assert fixture is not None
    kilted = _kilted_env(env)
    done, header, properties = _kilted_run(
        kilted, tmp_path / "a.xml", str(fixture), "sh", "-c", SEEN
    )
    assert _seen(done.stdout) == header == int(properties["ros_domain_id"])
    assert "disable=1" in done.stdout and rmw_fixture.PROPERTY not in properties
    done, header, properties = _kilted_run(
        kilted, tmp_path / "b.xml", str(KILTED.python), "-c", BINDING
    )
    assert _seen(done.stdout) == header == int(properties["ros_domain_id"])


@capabilities.KILTED
def test_without_the_runners_variable_kilteds_fixture_moves_the_test_and_the_result_says_so(
    env: dict[str, str], tmp_path: Path
) -> None:
    """The control: the variable set empty (the fixture on), as before this runner kept it
    off. Both the wrapper and the binding choose an ID of their own."""
    fixture = KILTED.run_rmw_isolated
    assert fixture is not None
    kilted = _kilted_env(env, **{DISABLE_VAR: ""})
    for command, name in (
        ([str(fixture), "sh", "-c", SEEN], "a"),
        ([str(KILTED.python), "-c", BINDING], "b"),
    ):
        done, header, properties = _kilted_run(kilted, tmp_path / f"{name}.xml", *command)
        assert _seen(done.stdout) != header == int(properties["ros_domain_id"]), done.stdout
        assert f"not on {header}" in properties[rmw_fixture.PROPERTY]


@capabilities.KILTED
@capabilities.GCC
def test_an_rmw_with_its_own_fixture_gets_it_started_by_the_real_run_rmw_isolated(
    env: dict[str, str], tmp_path: Path
) -> None:
    """A stand-in for rmw_zenoh_cpp's fixture library (``rmw_fake_cpp``), loaded by
    Kilted's real fixture in front of the test: it ran (FAKE_ROUTER), the ID is ours.
    The control: a DDS RMW, no wrapper, the fixture kept off."""
    library = tmp_path / "librmw_fake_cpp_test_fixture.so"
    source = tmp_path / "fake_fixture.c"
    source.write_text(FAKE_FIXTURE)
    subprocess.run(["gcc", "-shared", "-fPIC", "-o", str(library), str(source)], check=True)
    base = _kilted_env(env)
    fake = {
        **base,
        "RMW_IMPLEMENTATION": "rmw_fake_cpp",
        "LD_LIBRARY_PATH": os.pathsep.join([str(tmp_path), base.get("LD_LIBRARY_PATH", "")]),
    }
    done, header, properties = _kilted_run(fake, tmp_path / "fake.xml", "sh", "-c", SEEN)
    assert f"id={header} router=started disable=\n" in done.stdout, done.stdout
    assert properties[rmw_fixture.PROPERTY].startswith(f"{RUNNER} in front"), properties
    assert f"{RUNNER} sh -c" in done.stdout  # the invoking line names it
    dds = {**fake, "RMW_IMPLEMENTATION": "rmw_fastrtps_cpp"}
    done, header, properties = _kilted_run(dds, tmp_path / "dds.xml", "sh", "-c", SEEN)
    assert f"id={header} router= disable=1\n" in done.stdout, done.stdout
    assert rmw_fixture.PROPERTY not in properties

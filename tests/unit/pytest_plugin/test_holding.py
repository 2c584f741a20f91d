"""``holding``: each pytest session on a domain ID of its own, as the runner decides.

Real pytest processes with the installed plugin (entry point ``ros_isolated_test``) on a
project of their own (helpers/pytest_sessions.py): a preset ROS_DOMAIN_ID or Gazebo
partition is refused when isolation is asked for and left alone (said so) when it is
automatic; DISABLE_ROS_ISOLATION and a runner of ours around pytest are respected; a pool
with no free ID waits, then fails with the plugin's exit code; os.environ is restored
after the session. Each refusal has its control. The rules that turn the plugin on are
test_options.py's, what the plugin costs where it is not active test_plugin.py's; xdist,
resources and the release have topic files beside this one, signals test_interrupts.py.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import CLI, HUNG
from helpers.distros import KILTED
from helpers.pytest_sessions import (
    NO_ID_EXIT,
    PYTEST,
    header_lines,
    hold_the_one_id,
    project,
    recorded,
    run_in,
    run_pytest,
)

# --- presets, DISABLE_ROS_ISOLATION, a runner around pytest --------------------------------------


def test_a_bad_rerun_variable_does_not_concern_the_plugin(
    tmp_path: Path, plain_env: dict[str, str]
) -> None:
    """ROS_ISOLATED_TEST_RERUNS is `run`'s: the plugin never reruns, so never reads it."""
    root = project(tmp_path / "pkg")
    done = run_pytest(root, {**plain_env, "ROS_ISOLATED_TEST_RERUNS": "two"}, "test")
    assert done.returncode == 0, done.stdout + done.stderr
    domain = recorded(tmp_path)["ROS_DOMAIN_ID"]
    assert domain is not None and int(domain) > 0  # isolated, as without the variable
    # The control: a bad variable the plugin does use still stops the session.
    bad = {**plain_env, "ROS_ISOLATED_TEST_WAIT_TIMEOUT": "ten"}
    refused = run_pytest(root, bad, "test")
    assert refused.returncode == pytest.ExitCode.USAGE_ERROR, refused.stdout + refused.stderr
    assert "ROS_ISOLATED_TEST_WAIT_TIMEOUT='ten'" in refused.stderr, refused.stderr


def test_explicit_isolation_refuses_a_preset_id(tmp_path: Path, plain_env: dict[str, str]) -> None:
    root = project(tmp_path / "pkg")
    done = run_pytest(root, {**plain_env, "ROS_DOMAIN_ID": "5"}, "--ros-isolation", "test")
    assert done.returncode == pytest.ExitCode.USAGE_ERROR, done.stdout + done.stderr
    assert "refusing to run: ROS_DOMAIN_ID is already set to '5'" in done.stderr
    assert "DISABLE_ROS_ISOLATION=1" in done.stderr
    assert not (tmp_path / "record.json").exists()


def test_automatic_isolation_keeps_a_preset_id_and_says_so(
    tmp_path: Path, plain_env: dict[str, str]
) -> None:
    root = project(tmp_path / "pkg")
    done = run_pytest(root, {**plain_env, "ROS_DOMAIN_ID": "5"}, "test")
    assert done.returncode == 0, done.stdout + done.stderr
    assert recorded(tmp_path)["ROS_DOMAIN_ID"] == "5"
    (line,) = header_lines(done.stdout)
    assert "ROS_DOMAIN_ID is already set to '5'" in line and "NOT isolated" in line


def test_disable_ros_isolation_runs_without_an_id(
    tmp_path: Path, plain_env: dict[str, str]
) -> None:
    root = project(tmp_path / "pkg")
    env = {**plain_env, "DISABLE_ROS_ISOLATION": "1", "ROS_DOMAIN_ID": "5"}
    done = run_pytest(root, env, "--ros-isolation", "test")
    assert done.returncode == 0, done.stdout + done.stderr
    assert recorded(tmp_path) == {"ROS_DOMAIN_ID": "5", "ROS_AUTOMATIC_DISCOVERY_RANGE": None}
    (line,) = header_lines(done.stdout)
    assert "WARNING: DISABLE_ROS_ISOLATION is set: running WITHOUT isolation" in line


def test_under_the_runner_it_uses_the_runners_id(
    tmp_path: Path, plain_env: dict[str, str], one_id: dict[str, str]
) -> None:
    """Nested: the runner holds the pool's only ID; the plugin takes none (or it would wait)."""
    root = project(tmp_path / "pkg")
    env = {**plain_env, **one_id, "ROS_ISOLATED_TEST_WAIT_TIMEOUT": "0"}
    done = run_in(root, env, [CLI, "run", "--", *PYTEST, "--ros-isolation", "test"])
    assert done.returncode == 0, done.stdout + done.stderr
    domain = one_id["ROS_ISOLATED_TEST_DOMAINS"]
    assert done.stdout.startswith(f"Running with ROS_DOMAIN_ID {domain} (Gazebo partition ")
    assert recorded(tmp_path)["ROS_DOMAIN_ID"] == domain
    assert f"ros-isolated-test: ROS_DOMAIN_ID {domain}, held by the runner" in done.stdout


@pytest.mark.ros
@capabilities.KILTED.mark
def test_an_id_kilteds_fixture_set_is_said_replaced_as_the_runner_says_it(
    tmp_path: Path, env: dict[str, str]
) -> None:
    """Kilted's real run_rmw_isolated around pytest: the header's first line says whose ID
    it replaced, in the runner's words; the control: the runner under the same fixture."""
    fixture = KILTED.run_rmw_isolated
    assert fixture is not None
    kilted = KILTED.env(env)
    root = project(tmp_path / "pkg", "def test_x():\n    pass\n")
    done = run_in(root, kilted, [str(fixture), str(KILTED.python), *PYTEST[1:], "test"])
    assert done.returncode == 0, done.stdout + done.stderr
    said = header_lines(done.stdout)
    replaced = re.search(r"ROS_DOMAIN_ID (\d+) was set by Kilted's rmw_test_fixture", "".join(said))
    assert replaced is not None, said
    assert re.match(
        rf"ros-isolated-test: ROS_DOMAIN_ID \d+, replacing ROS_DOMAIN_ID {replaced[1]} of "
        "Kilted's rmw_test_fixture(,|$)",
        said[0],
    ), said
    runner = run_in(root, kilted, [str(fixture), str(KILTED.cli), "run", "--", "true"])
    assert runner.returncode == 0, runner.stdout + runner.stderr
    assert re.match(
        r"Running with ROS_DOMAIN_ID \d+ .*, replacing ROS_DOMAIN_ID \d+ of Kilted's "
        "rmw_test_fixture$",
        runner.stdout.splitlines()[0],
    ), runner.stdout


def test_a_mark_for_another_id_is_no_runner(tmp_path: Path, plain_env: dict[str, str]) -> None:
    """The control for nesting: only the runner's mark naming that very ID counts."""
    root = project(tmp_path / "pkg")
    env = {**plain_env, "ROS_DOMAIN_ID": "5", "ROS_ISOLATED_TEST_HELD_DOMAIN_ID": "6"}
    done = run_pytest(root, env, "--ros-isolation", "test")
    assert done.returncode == pytest.ExitCode.USAGE_ERROR, done.stdout + done.stderr
    assert "refusing to run" in done.stderr


# --- the pool, the session's end -----------------------------------------------------------------


def test_pool_exhausted_waits_then_fails(
    tmp_path: Path,
    exhausted_env: dict[str, str],
    one_id: dict[str, str],
    started: list[subprocess.Popen[bytes]],
) -> None:
    """Exit 75, the plugin's own code: pytest's 3 would say pytest itself broke."""
    root = project(tmp_path / "pkg")
    holder = hold_the_one_id(tmp_path, exhausted_env, started)
    done = run_pytest(root, exhausted_env, "test")
    assert done.returncode == NO_ID_EXIT, done.stdout + done.stderr
    assert NO_ID_EXIT not in set(pytest.ExitCode)
    assert "waiting for a free ROS_DOMAIN_ID" in done.stderr
    assert "after waiting 1 s, no free ROS_DOMAIN_ID" in done.stderr
    assert "INTERNALERROR" not in done.stdout + done.stderr
    assert not (tmp_path / "record.json").exists()
    holder.terminate()  # the runner ends its test, then releases the ID
    holder.wait(HUNG)
    again = run_pytest(root, exhausted_env, "test")  # the control: the ID free, the same run passes
    assert again.returncode == 0, again.stdout + again.stderr
    assert recorded(tmp_path)["ROS_DOMAIN_ID"] == one_id["ROS_ISOLATED_TEST_DOMAINS"]


def test_control_pytests_own_internal_error_keeps_its_3_under_the_plugin(
    tmp_path: Path, plain_env: dict[str, str]
) -> None:
    """The control for the plugin's own code: pytest's 3 means pytest broke, and still does."""
    root = project(tmp_path / "pkg")
    hook = "def pytest_collection_modifyitems():\n    raise RuntimeError('a broken hook')\n"
    (root / "conftest.py").write_text(hook)
    done = run_pytest(root, plain_env, "test")
    output = done.stdout + done.stderr
    assert done.returncode == pytest.ExitCode.INTERNAL_ERROR, output
    assert "INTERNALERROR> RuntimeError: a broken hook" in output, output
    assert "ros-isolated-test: ROS_DOMAIN_ID" in done.stdout, output  # isolated meanwhile


#: Two pytest sessions in one process (an embedding program).
TWICE = """\
import ctypes, json, os
import pytest

def subreaper():
    flag = ctypes.c_int(0)
    ctypes.CDLL(None).prctl(37, ctypes.byref(flag), 0, 0, 0)  # PR_GET_CHILD_SUBREAPER
    return flag.value

seen = []
for _ in range(2):
    code = pytest.main(["-p", "no:cacheprovider", "test"])
    seen.append([int(code), os.environ.get("ROS_DOMAIN_ID"),
                 os.environ.get("ROS_ISOLATED_TEST_HELD_DOMAIN_ID"), subreaper()])
print("SEEN " + json.dumps(seen))
"""


def test_os_environ_is_restored_after_the_session(
    tmp_path: Path, plain_env: dict[str, str], one_id: dict[str, str]
) -> None:
    """The second session reserves again: the first left nothing of its isolation behind."""
    root = project(tmp_path / "pkg")
    env = {**plain_env, **one_id, "ROS_ISOLATED_TEST_WAIT_TIMEOUT": "1"}
    done = run_in(root, env, [sys.executable, "-c", TWICE])
    assert done.returncode == 0, done.stdout + done.stderr
    (seen,) = (line for line in done.stdout.splitlines() if line.startswith("SEEN "))
    # No ID, no held mark, no subreaper left to the embedding program.
    assert json.loads(seen[5:]) == [[0, None, None, 0], [0, None, None, 0]]
    domain = one_id["ROS_ISOLATED_TEST_DOMAINS"]
    starts = f"ros-isolated-test: ROS_DOMAIN_ID {domain},"
    assert sum(line.startswith(starts) for line in header_lines(done.stdout)) == 2
    assert "held by the runner" not in done.stdout


# --- a Gazebo transport partition of the session's own -------------------------------------------


#: A test that records the Gazebo partition it ran with, its domain ID and its process.
PARTITION_TEST = """\
import json, os

def test_records():
    names = ("ROS_DOMAIN_ID", "GZ_PARTITION", "IGN_PARTITION")
    record = {name: os.environ.get(name) for name in names}
    record["pid"] = os.getpid()
    with open(os.environ["PLUGIN_RECORD"], "w") as out:
        json.dump(record, out)
"""


def test_the_session_gets_a_gazebo_partition_of_its_own(
    tmp_path: Path, plain_env: dict[str, str]
) -> None:
    """The name ``status`` shows for the session's holder record: host, ID, pytest's PID."""
    from ros_isolated_test.runner import partition

    root = project(tmp_path / "pkg", PARTITION_TEST)
    junit = tmp_path / "junit.xml"
    done = run_pytest(root, plain_env, "test", f"--junit-xml={junit}")
    assert done.returncode == 0, done.stdout + done.stderr
    seen = json.loads((tmp_path / "record.json").read_text())
    name = partition.name(os.uname().nodename, int(seen["ROS_DOMAIN_ID"]), seen["pid"])
    assert seen["GZ_PARTITION"] == seen["IGN_PARTITION"] == name
    assert f"ros-isolated-test: Gazebo transport partition {name} " in done.stdout
    assert f'name="gz_partition" value="{name}"' in junit.read_text()


@pytest.mark.parametrize("variable", ["GZ_PARTITION", "IGN_PARTITION"])
def test_explicit_isolation_refuses_a_preset_partition(
    tmp_path: Path, plain_env: dict[str, str], variable: str
) -> None:
    root = project(tmp_path / "pkg", PARTITION_TEST)
    done = run_pytest(root, {**plain_env, variable: "sim"}, "--ros-isolation", "test")
    assert done.returncode == pytest.ExitCode.USAGE_ERROR, done.stdout + done.stderr
    assert f"refusing to run: {variable} is already set to 'sim'" in done.stderr
    assert not (tmp_path / "record.json").exists()


def test_automatic_isolation_keeps_a_preset_partition_and_says_so(
    tmp_path: Path, plain_env: dict[str, str]
) -> None:
    root = project(tmp_path / "pkg", PARTITION_TEST)
    done = run_pytest(root, {**plain_env, "GZ_PARTITION": "sim"}, "test")
    assert done.returncode == 0, done.stdout + done.stderr
    seen = json.loads((tmp_path / "record.json").read_text())
    assert (seen["GZ_PARTITION"], seen["ROS_DOMAIN_ID"]) == ("sim", None)
    (line,) = header_lines(done.stdout)
    assert "GZ_PARTITION is already set to 'sim'" in line and "NOT isolated" in line

"""``options``: the rules that turn the plugin on, and its options.

On: asked for (``--ros-isolation``, the ``ros_isolation`` ini option in any on word), a
resource request (outside a ROS package too), or, automatically, inside a ROS package (a
package.xml at or above the rootdir or a test path). Off: ``--no-ros-isolation``, the ini
option's off words, ``-p no:ros_isolated_test``, anywhere else, and any run of no test
(``--help``, ``--collect-only``, ...), which must answer at once even with no ID free.
An ini word neither on nor off is a usage error: a typo must not silently flip it.

Two ways, both real pytest processes on a project of their own: the whole plugin (the
test records the ROS_DOMAIN_ID it ran with), and ``decide`` itself, called by a plugin of
the test's own that registers the options as the plugin does (the plugin off, so nothing
is reserved): it tells the explicit True from the automatic False the session cannot show.
Each rule has its control in the same table.
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import pytest
from helpers.pytest_sessions import (
    NO_ID_EXIT,
    OFF,
    PACKAGE_XML,
    header_lines,
    hold_the_one_id,
    project,
    recorded,
    run_pytest,
)

from ros_isolated_test.pytest_plugin.options import RESOURCES_OPTION

# --- the whole plugin: isolated or not -----------------------------------------------------------


@pytest.mark.parametrize(
    ("package", "args", "isolated"),
    [
        (True, (), True),  # inside a ROS package: on by itself
        (False, (), False),  # elsewhere: off
        (False, ("--ros-isolation",), True),
        (False, ("-o", "ros_isolation=true"), True),
        (True, ("--no-ros-isolation",), False),
        (True, ("-o", "ros_isolation=false"), False),
        (True, OFF, False),
        # The ini option's other words, read as every on/off switch reads them; auto and
        # blank leave it to the package.
        (False, ("-o", "ros_isolation= Yes "), True),
        (True, ("-o", "ros_isolation=0"), False),
        (True, ("-o", "ros_isolation=AUTO"), True),
        (True, ("-o", "ros_isolation="), True),
        (False, ("-o", "ros_isolation=auto"), False),
    ],
)
def test_activation(
    tmp_path: Path,
    plain_env: dict[str, str],
    package: bool,
    args: tuple[str, ...],
    isolated: bool,
) -> None:
    root = project(tmp_path / "pkg", package=package)
    done = run_pytest(root, plain_env, *args, "test")
    assert done.returncode == 0, done.stdout + done.stderr
    seen = recorded(tmp_path)
    if isolated:
        domain = seen["ROS_DOMAIN_ID"]
        assert domain is not None and int(domain) > 0
        assert seen["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
        assert header_lines(done.stdout)[0].startswith(
            f"ros-isolated-test: ROS_DOMAIN_ID {domain},"
        )
    else:
        assert seen == {"ROS_DOMAIN_ID": None, "ROS_AUTOMATIC_DISCOVERY_RANGE": None}
        assert header_lines(done.stdout) == []


def test_an_ini_word_neither_on_nor_off_is_a_usage_error(
    tmp_path: Path, plain_env: dict[str, str]
) -> None:
    root = project(tmp_path / "pkg")
    done = run_pytest(root, plain_env, "-o", "ros_isolation=maybe", "test")
    assert done.returncode == 4, done.stdout + done.stderr  # pytest's usage error
    assert "ini option ros_isolation='maybe': use auto, true or false" in done.stderr, done.stderr
    assert not (tmp_path / "record.json").exists()  # nothing ran


@pytest.mark.parametrize("option", ["--help", "--markers", "--fixtures", "--collect-only"])
def test_options_that_run_no_test_reserve_nothing(
    tmp_path: Path,
    plain_env: dict[str, str],
    one_id: dict[str, str],
    started: list[subprocess.Popen[bytes]],
    option: str,
) -> None:
    """The pool's one ID held: they still answer at once (a reservation would fail: 75)."""
    root = project(tmp_path / "pkg")
    env = {**plain_env, **one_id, "ROS_ISOLATED_TEST_WAIT_TIMEOUT": "0"}
    hold_the_one_id(tmp_path, env, started)
    done = run_pytest(root, env, option, "test")
    assert done.returncode == 0, done.stdout + done.stderr
    assert "no free ROS_DOMAIN_ID" not in done.stderr
    control = run_pytest(root, env, "test")
    assert control.returncode == NO_ID_EXIT, control.stdout + control.stderr


@pytest.mark.parametrize("package", [True, False])
def test_the_option_wins_over_the_ini_and_turns_isolation_on(
    tmp_path: Path, resource_env: dict[str, str], package: bool
) -> None:
    """Outside a ROS package too: a request needs the plugin (without one it stays off)."""
    root = project(tmp_path / "pkg", package=package)
    # A bad ini value: never read when the option is given.
    (root / "pytest.ini").write_text("[pytest]\nros_isolated_test_resources = lidar\n")
    done = run_pytest(root, resource_env, "--ros-isolated-test-resources", "camera=1", "test")
    assert done.returncode == 0, done.stdout + done.stderr
    lines = header_lines(done.stdout)
    assert lines[1].startswith("ros-isolated-test: holding camera=1 of camera=1"), lines
    domain = recorded(tmp_path)["ROS_DOMAIN_ID"]
    assert domain is not None and lines[0].startswith(f"ros-isolated-test: ROS_DOMAIN_ID {domain},")


# --- decide itself: explicit, automatic or off ---------------------------------------------------

#: A plugin of the test's own: the plugin's options registered as the plugin registers them,
#: and what ``decide`` and ``resources`` make of the run written to $DECIDED (the plugin
#: itself is off: nothing is reserved).
PROBE = """\
import json, os
import pytest
from ros_isolated_test.pytest_plugin import options

def pytest_addoption(parser):
    options.add(parser)

@pytest.hookimpl(tryfirst=True)
def pytest_configure(config):
    record = {"decided": options.decide(config),
              "resources": list(options.resources(config))}
    with open(os.environ["DECIDED"], "w") as out:
        json.dump(record, out)
"""
#: The one test of every project here.
NOTHING_TEST = "def test_nothing():\n    pass\n"
RESOURCES_INI = "ini option ros_isolated_test_resources"


def decided(cwd: Path, env: dict[str, str], tmp_path: Path, *args: str) -> dict[str, object]:
    """pytest ``args`` in ``cwd`` with the probe instead of the plugin: what it recorded."""
    probe = tmp_path / "probe"
    probe.mkdir(exist_ok=True)
    (probe / "decide_probe.py").write_text(PROBE)
    record = tmp_path / "decided.json"
    path = os.pathsep.join(filter(None, (str(probe), env.get("PYTHONPATH"))))
    probe_env = {**env, "PYTHONPATH": path, "DECIDED": str(record)}
    done = run_pytest(cwd, probe_env, *OFF, "-p", "decide_probe", *args)
    assert done.returncode == 0, done.stdout + done.stderr
    found: dict[str, object] = json.loads(record.read_text())
    return found


def _rootdir(tmp_path: Path, where: str) -> Path:
    """A project (its own rootdir) in a ROS package, in a folder below one, or in none."""
    if where == "below a package":
        (tmp_path / "ws").mkdir()
        (tmp_path / "ws" / "package.xml").write_text(PACKAGE_XML)
        return project(tmp_path / "ws" / "sub", NOTHING_TEST, package=False)
    return project(tmp_path / "pkg", NOTHING_TEST, package=where == "package")


@pytest.mark.parametrize(
    ("where", "args", "expected"),
    [
        ("package", (), False),  # automatic: a package.xml in the rootdir ...
        ("below a package", (), False),  # ... or above it
        ("plain", (), None),  # the control: no package anywhere, nothing asked
        ("plain", ("--ros-isolation",), True),  # asked for: explicit, in a package or not
        ("package", ("--ros-isolation",), True),
        ("package", ("--no-ros-isolation",), None),
        ("plain", ("-o", "ros_isolation=true"), True),
        ("package", ("-o", "ros_isolation=off"), None),
        ("package", ("-o", "ros_isolation=auto"), False),
        ("plain", ("-o", "ros_isolation=auto"), None),
        # The option wins over the ini option, either way.
        ("plain", ("--ros-isolation", "-o", "ros_isolation=false"), True),
        ("package", ("--no-ros-isolation", "-o", "ros_isolation=true"), None),
        # A run of no test is never isolated, even when asked for.
        ("package", ("--collect-only", "--ros-isolation"), None),
    ],
)
def test_decide_tells_the_explicit_from_the_automatic_from_off(
    tmp_path: Path, env: dict[str, str], where: str, args: tuple[str, ...], expected: bool | None
) -> None:
    """True: asked for (a preset ID is then refused); False: on by itself; None: off."""
    root = _rootdir(tmp_path, where)
    assert decided(root, env, tmp_path, *args, "test")["decided"] is expected


@pytest.mark.parametrize(("target", "expected"), [("ros_pkg", False), ("plain_dir", None)])
def test_a_package_xml_above_a_test_path_counts_wherever_the_rootdir_is(
    tmp_path: Path, env: dict[str, str], target: str, expected: bool | None
) -> None:
    """colcon's case with the rootdir elsewhere: the path on the command line is in a package.

    The control: the same rootdir and a test path in no package.
    """
    root = project(tmp_path / "runner", NOTHING_TEST, package=False)
    project(tmp_path / "ros_pkg", NOTHING_TEST)
    project(tmp_path / "plain_dir", NOTHING_TEST, package=False)
    test_path = f"../{target}/test/test_it.py::test_nothing"
    found = decided(root, env, tmp_path, "--rootdir", str(root), test_path)
    assert found["decided"] is expected


@pytest.mark.parametrize(
    ("args", "ini", "expected", "asked"),
    [
        ((), "", None, ["", RESOURCES_INI]),  # the control: no request, no package: off
        ((), "lidar=1", True, ["lidar=1", RESOURCES_INI]),
        (("--ros-isolated-test-resources", "cpu=2"), "", True, ["cpu=2", RESOURCES_OPTION]),
        # The option wins over the ini option, even given empty; a blank one asks nothing.
        (("--ros-isolated-test-resources", "cpu=2"), "lidar=1", True, ["cpu=2", RESOURCES_OPTION]),
        (("--ros-isolated-test-resources=",), "lidar=1", None, ["", RESOURCES_OPTION]),
        (("--ros-isolated-test-resources", " "), "", None, [" ", RESOURCES_OPTION]),
        # Isolation turned off explicitly stays off, request or not.
        (("--no-ros-isolation", "--ros-isolated-test-resources", "cpu=2"), "", None,
         ["cpu=2", RESOURCES_OPTION]),
    ],
)  # fmt: skip
def test_a_resource_request_turns_isolation_on_outside_a_ros_package(
    tmp_path: Path,
    env: dict[str, str],
    args: tuple[str, ...],
    ini: str,
    expected: bool | None,
    asked: list[str],
) -> None:
    """The request and where it was given (its errors name it); held as --ros-isolation is."""
    root = project(tmp_path / "plain", NOTHING_TEST, package=False)
    if ini:
        (root / "pytest.ini").write_text(f"[pytest]\nros_isolated_test_resources = {ini}\n")
    found = decided(root, env, tmp_path, *args, "test")
    assert (found["decided"], found["resources"]) == (expected, asked)


def test_help_lists_the_options_and_ini_options_of_the_plugin(
    tmp_path: Path, env: dict[str, str]
) -> None:
    """``add`` registers them in a group of their own; the control: the plugin off, none."""
    root = project(tmp_path / "plain", NOTHING_TEST, package=False)
    words = (
        "ROS isolation (ros-isolated-test):",
        "--ros-isolation",
        "--no-ros-isolation",
        "--ros-isolated-test-resources=SPEC",
        "ros_isolation (string):",
        "ros_isolated_test_resources (string):",
    )
    shown = run_pytest(root, env, "--help")
    assert shown.returncode == 0, shown.stderr
    assert [word for word in words if word not in shown.stdout] == []
    off = run_pytest(root, env, *OFF, "--help")
    assert off.returncode == 0, off.stderr
    assert [word for word in words if word in off.stdout] == []

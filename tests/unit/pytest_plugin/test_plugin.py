"""``plugin``: the entry point pytest loads, which hands each hook to the module doing its work.

Real pytest processes (helpers/pytest_sessions.py): the ``pytest11`` entry point named
``ros_isolated_test`` loads this module, and ``-p no:ros_isolated_test`` keeps it out
(nothing imported, nothing reserved), with its control; loaded by every pytest run of the
environment, outside a ROS package it imports nothing of the runner, nor of the plugin
package beyond its options. What the session holds is test_holding*.py's, signals
test_interrupts.py's, launch files test_launch_testing_cases*.py's.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from helpers.pytest_sessions import OFF, project, run_pytest

#: A test that records the plugin's modules loaded, and the ID it ran with.
MODULES_TEST = """\
import json, os, sys

def test_modules():
    loaded = sorted(name for name in sys.modules if name.startswith("ros_isolated_test"))
    record = {"ROS_DOMAIN_ID": os.environ.get("ROS_DOMAIN_ID"), "loaded": loaded}
    with open(os.environ["PLUGIN_RECORD"], "w") as out:
        json.dump(record, out)
"""


def _seen(tmp_path: Path) -> dict[str, Any]:
    found: dict[str, Any] = json.loads((tmp_path / "record.json").read_text())
    return found


def test_the_entry_point_loads_the_plugin_and_no_ros_isolated_test_keeps_it_out(
    tmp_path: Path, plain_env: dict[str, str]
) -> None:
    root = project(tmp_path / "pkg", MODULES_TEST)
    done = run_pytest(root, plain_env, "test")
    assert done.returncode == 0, done.stdout + done.stderr
    seen = _seen(tmp_path)
    assert "ros_isolated_test.pytest_plugin.plugin" in seen["loaded"]
    domain = seen["ROS_DOMAIN_ID"]
    assert domain is not None and int(domain) > 0  # the control: a ROS package, isolated
    off = run_pytest(root, plain_env, *OFF, "test")
    assert off.returncode == 0, off.stdout + off.stderr
    seen = _seen(tmp_path)
    assert seen == {"ROS_DOMAIN_ID": None, "loaded": []}, seen
    assert "ros-isolated-test:" not in off.stdout + off.stderr


def test_inactive_plugin_imports_nothing_of_the_runner(tmp_path: Path, env: dict[str, str]) -> None:
    """Loaded by every pytest run: outside a ROS package it must cost nothing."""
    check = """\
import sys

def test_modules():
    heavy = ("lxml", "filelock", "ros_isolated_test.runner", "ros_isolated_test.domain_coordinator",
             "ros_isolated_test.pytest_plugin.holding")
    assert "ros_isolated_test.pytest_plugin.plugin" in sys.modules
    loaded = [name for name in sys.modules if name.startswith(heavy)]
    assert loaded == [], loaded
"""
    root = project(tmp_path / "plain", check, package=False)
    done = run_pytest(root, env, "test")
    assert done.returncode == 0, done.stdout + done.stderr
    active = run_pytest(project(tmp_path / "ros", check), env, "test")  # the control
    assert active.returncode == 1, active.stdout
    assert "ros_isolated_test.runner" in active.stdout

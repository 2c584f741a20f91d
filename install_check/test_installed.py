"""The installed package as a ROS user meets it: the command, the RUNNER, the pytest plugin."""

from __future__ import annotations

import shutil
import subprocess
import unittest
from importlib import metadata
from pathlib import Path


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    """``ros-isolated-test ARGS`` as found on PATH, as CMake and a shell find it."""
    command = shutil.which("ros-isolated-test")
    if command is None:
        raise AssertionError("ros-isolated-test is not on PATH: is the workspace sourced?")
    return subprocess.run([command, *args], capture_output=True, text=True, timeout=60, check=False)


class InstalledPackage(unittest.TestCase):
    """Found through the environment a sourced workspace gives, nothing else."""

    def test_the_command_runs_and_names_the_packages_version(self) -> None:
        done = _cli("--version")
        self.assertEqual(done.returncode, 0, done.stderr)
        self.assertIn(metadata.version("ros-isolated-test"), done.stdout)

    def test_the_runner_script_is_installed_beside_the_package(self) -> None:
        done = _cli("runner-path")
        self.assertEqual(done.returncode, 0, done.stderr)
        script = Path(done.stdout.strip())
        self.assertEqual(script.name, "run_test_isolated.py")
        self.assertTrue(script.is_file(), script)

    def test_pytest_finds_the_plugin_by_its_entry_point(self) -> None:
        found = {
            entry.name: entry.value
            for entry in metadata.entry_points(group="pytest11")
            if entry.name == "ros_isolated_test"
        }
        self.assertEqual(found, {"ros_isolated_test": "ros_isolated_test.pytest_plugin.plugin"})


if __name__ == "__main__":
    unittest.main()

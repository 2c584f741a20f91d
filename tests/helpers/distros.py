"""The ROS 2 distributions this suite tests on, each a virtualenv made by scripts/setup.sh.

Jazzy lives in ``.venv`` (the suite's own interpreter), Kilted in ``.venv-kilted``. A test
that runs something "on Kilted" starts that venv's Python, colcon or runner with
:meth:`Distro.env`, which gives what sourcing that distro's setup would: its ``bin`` on
PATH, its prefix on AMENT_PREFIX_PATH and CMAKE_PREFIX_PATH, its libraries on
LD_LIBRARY_PATH, ROS_DISTRO. It also takes out everything of the other distro's venv,
because the suite itself runs in Jazzy's venv and its environment leaks into children:
the wheels' start-up hook keeps LD_LIBRARY_PATH in a *set* (so the order of two venvs'
``lib`` is random) and skips itself when ``_ROS_WHEELS_BOOTSTRAP_COMPLETE`` is inherited,
so without this a Kilted process could load Jazzy's libraries.
"""

from __future__ import annotations

import functools
import os
import subprocess
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from helpers import commands
from helpers.commands import CLI

REPO = Path(__file__).resolve().parents[2]
#: Set by the ROS wheels' ``.pth`` hook once it has re-executed Python with the library
#: path of *its* venv; inherited, it stops the next venv's hook from doing the same.
BOOTSTRAP_GUARD = "_ROS_WHEELS_BOOTSTRAP_COMPLETE"
#: Path-list variables a sourced setup extends; entries of the other venvs are taken out.
_PATH_LISTS = ("PATH", "AMENT_PREFIX_PATH", "CMAKE_PREFIX_PATH", "LD_LIBRARY_PATH", "PYTHONPATH")


@dataclass(frozen=True)
class Distro:
    """One distribution's venv: where its tools are and the environment they need."""

    #: ROS_DISTRO's value: "jazzy", "kilted".
    name: str
    #: The venv (its ``sys.prefix``); the install prefix of every ROS package in it.
    prefix: Path

    @property
    def bin(self) -> Path:
        return self.prefix / "bin"

    @property
    def python(self) -> Path:
        """The venv's interpreter (not resolved: the symlink is what makes it the venv)."""
        return self.bin / "python"

    @property
    def cli(self) -> Path:
        """``ros-isolated-test`` as installed in this venv (editable: this checkout)."""
        return self.bin / "ros-isolated-test"

    @property
    def lib(self) -> Path:
        return self.prefix / "lib"

    @property
    def site_packages(self) -> Path:
        found = sorted(self.lib.glob("python3.*/site-packages"))
        return found[0] if found else self.lib / "python3" / "site-packages"

    @property
    def upstream_runner(self) -> Path:
        """ament_cmake_ros's ``run_test_isolated.py``, the RUNNER upstream ships."""
        return self.prefix / "share" / "ament_cmake_ros" / "cmake" / "run_test_isolated.py"

    @property
    def run_rmw_isolated(self) -> Path | None:
        """Kilted's C++ ID-holding wrapper that its upstream runner inserts; None before."""
        if self.name == "jazzy":
            return None
        return self.lib / "rmw_test_fixture_implementation" / "run_rmw_isolated"

    def _library_dirs(self) -> list[str]:
        """``lib`` and the wheels' vendored ``ros_*.libs``, as the start-up hook finds them."""
        dirs = [str(self.lib)]
        dirs += sorted(
            str(d.resolve()) for d in self.site_packages.glob("ros_*.libs") if d.is_dir()
        )
        return dirs

    def env(self, base: Mapping[str, str]) -> dict[str, str]:
        """``base`` as if this distro's setup had been sourced in it, and no other venv's.

        ROS_DOMAIN_ID and the runner's policy variables are the caller's business: they
        pass through unchanged.
        """
        others = [d for d in DISTROS if d.prefix != self.prefix]
        result = dict(base)
        result.pop(BOOTSTRAP_GUARD, None)
        for name in _PATH_LISTS:
            kept = [p for p in base.get(name, "").split(os.pathsep) if p]
            kept = [p for p in kept if not any(o.owns(p) for o in others) and not self.owns(p)]
            result[name] = os.pathsep.join(kept)
        own = {
            "PATH": [str(self.bin)],
            "AMENT_PREFIX_PATH": [str(self.prefix)],
            "CMAKE_PREFIX_PATH": [str(self.prefix)],
            "LD_LIBRARY_PATH": self._library_dirs(),
            "PYTHONPATH": [],
        }
        for name, first in own.items():
            joined = os.pathsep.join([*first, *filter(None, [result[name]])])
            if joined:
                result[name] = joined
            else:
                result.pop(name, None)
        result["ROS_DISTRO"] = self.name
        result["ROS_VERSION"] = "2"
        result["ROS_PYTHON_VERSION"] = "3"
        return result

    def owns(self, path: str) -> bool:
        """Whether ``path`` lies in this venv (as written, or with links resolved)."""
        candidate = Path(path)
        roots = {self.prefix, self.prefix.resolve()}
        paths = {candidate, Path(os.path.realpath(candidate))}
        return any(p == r or r in p.parents for p in paths for r in roots)

    @functools.cached_property
    def missing(self) -> str | None:
        """Why this distro cannot be used here (naming the fix), or None when it can."""
        setup = "run scripts/setup.sh"
        if not self.python.exists():
            return f"needs ROS 2 {self.name.title()} in {self.prefix.name}; {setup}"
        # Not through env(): a fault of this helper must fail the tests, not skip them. The
        # wheels' start-up hook sets the library path itself when nothing is inherited.
        inherited = (BOOTSTRAP_GUARD, "LD_LIBRARY_PATH", "PYTHONPATH")
        try:
            probe = subprocess.run(
                [str(self.python), "-c", "import rclpy, ros_isolated_test"],
                env={k: v for k, v in os.environ.items() if k not in inherited},
                capture_output=True,
                text=True,
                timeout=120,
                check=False,
            )
        except (OSError, subprocess.TimeoutExpired) as error:
            return f"{self.python} does not run ({error}); {setup}"
        if probe.returncode != 0:
            last = (probe.stderr.strip().splitlines() or ["no output"])[-1]
            return f"{self.prefix.name} cannot import rclpy and ros_isolated_test ({last}); {setup}"
        return None


JAZZY = Distro("jazzy", REPO / ".venv")
KILTED = Distro("kilted", REPO / ".venv-kilted")
DISTROS = (JAZZY, KILTED)


@dataclass(frozen=True)
class Tools:
    """How a test runs our CLI, our RUNNER and its test commands on one distro.

    On Jazzy these are the suite's own interpreter and environment, exactly as the tests
    always ran them; on another distro, that venv's interpreter and installed
    ``ros-isolated-test`` with the environment its sourced setup would give.
    """

    distro: Distro
    #: The interpreter that runs the RUNNER (as ctest would) and the test commands.
    python: str
    cli: str

    @classmethod
    def on(cls, distro: Distro) -> Tools:
        if distro == JAZZY:
            return cls(distro, sys.executable, CLI)
        return cls(distro, str(distro.python), str(distro.cli))

    def env(self, base: Mapping[str, str]) -> dict[str, str]:
        """``base`` for this distro (Jazzy: unchanged; it is the suite's own venv)."""
        return dict(base) if self.distro == JAZZY else self.distro.env(base)

    def runner_script(self) -> str:
        """The RUNNER as this venv's ``ros-isolated-test runner-path`` prints it."""
        done = self.run_cli(["runner-path"], self.env(os.environ))
        assert done.returncode == 0, done.stdout + done.stderr
        return done.stdout.strip()

    def run_cli(
        self, args: Sequence[str], env: Mapping[str, str], **kwargs: object
    ) -> subprocess.CompletedProcess[str]:
        """``ros-isolated-test ARGS`` from this venv (``env`` is taken as given)."""
        return commands.run_process([self.cli, *args], env, **kwargs)

    def run_runner(
        self, runner_script: str, args: Sequence[str], env: Mapping[str, str], **kwargs: object
    ) -> subprocess.CompletedProcess[str]:
        """The RUNNER as ctest calls it on this distro: ``<venv python> -u <script> ARGS``."""
        return commands.run_process([self.python, "-u", runner_script, *args], env, **kwargs)

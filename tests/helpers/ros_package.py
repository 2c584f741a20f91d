"""This repository as a ROS package: copied into a colcon workspace, built on Ubuntu's Python.

The distro venv (``.venv-distro``, made by scripts/setup.sh) is what a Jazzy user on Ubuntu
24.04 has: ROS 2 Jazzy (here its wheels), colcon, and the Python packages Ubuntu ships at the
versions it ships (scripts/ubuntu-24.04-constraints.txt). It does not hold this project: a
workspace gets it the ROS way, as a package in ``src/`` that colcon builds.
"""

from __future__ import annotations

import shlex
import shutil
import subprocess
from collections.abc import Mapping, Sequence
from pathlib import Path

from helpers.busy_machine import clean_environment
from helpers.commands import HUNG, REPO
from helpers.distros import Distro

#: Ubuntu 24.04's packages, ROS 2 Jazzy's wheels and colcon; never this project.
DISTRO_VENV = Distro("jazzy", REPO / ".venv-distro")
#: The versions Ubuntu 24.04 ships, as pip constraints (``name==version`` lines).
CONSTRAINTS = REPO / "scripts" / "ubuntu-24.04-constraints.txt"
#: The package's name in package.xml, colcon and the ament index.
PACKAGE = "ros_isolated_test"


def ubuntu_versions() -> dict[str, str]:
    """``{name: version}`` of every package the constraints file pins."""
    pins: dict[str, str] = {}
    for raw in CONSTRAINTS.read_text().splitlines():
        line = raw.split("#", 1)[0].strip()
        if line:
            name, _, version = line.partition("==")
            assert version, f"{CONSTRAINTS.name}: not a name==version pin: {raw!r}"
            pins[name.strip()] = version.strip()
    return pins


def distro_venv_problem() -> str | None:
    """Why the distro venv cannot be used here (naming the fix), or None when it can."""
    if not DISTRO_VENV.python.exists():
        name = DISTRO_VENV.prefix.name
        return f"needs {name} (Ubuntu 24.04's Python packages); run scripts/setup.sh"
    for tool in ("colcon", "pytest"):
        if not (DISTRO_VENV.bin / tool).exists():
            return f"{DISTRO_VENV.prefix.name} has no {tool}; run scripts/setup.sh"
    return None


def checkout_files() -> list[Path]:
    """The working tree as a clone would have it after the lead's commit: tracked and new
    files, ignored ones left out (the tree under test, not the last commit)."""
    listed = subprocess.run(
        ["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
        cwd=REPO,
        capture_output=True,
        check=True,
        timeout=HUNG,
    ).stdout.split(b"\0")
    files = {Path(name.decode()) for name in listed if name}
    # A tracked file deleted in the working tree is listed too; it is not in the tree.
    return sorted(path for path in files if (REPO / path).is_file())


def copy_checkout(destination: Path) -> Path:
    """The working tree's files copied to ``destination`` (modes kept); returns it."""
    for relative in checkout_files():
        target = destination / relative
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(REPO / relative, target)
    return destination


def distro_env() -> dict[str, str]:
    """A fresh login's shell with Jazzy's setup sourced: the distro venv first, none of this
    suite's venvs, no ROS or runner settings, no pytest variables of this session."""
    return DISTRO_VENV.env(clean_environment(DISTRO_VENV.bin))


def in_workspace(
    workspace: Path, command: Sequence[str], env: Mapping[str, str], cwd: Path | None = None
) -> subprocess.CompletedProcess[str]:
    """``command`` after ``source install/setup.bash``, as a user runs things in a workspace.

    colcon's scripts read unset variables, so they are sourced without ``set -u``.
    """
    script = f'source {shlex.quote(str(workspace / "install" / "setup.bash"))} && exec "$@"'
    return run(["bash", "-c", script, "bash", *command], env, cwd=cwd or workspace)


def run(
    command: Sequence[str], env: Mapping[str, str], cwd: Path
) -> subprocess.CompletedProcess[str]:
    """A tool of the workspace, output captured as text (stderr into stdout), hangs stopped."""
    return subprocess.run(
        list(command),
        env=dict(env),
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        timeout=HUNG * 3,
        check=False,
    )

"""The release artefacts built as a releaser builds them: the sdist and wheel, the .deb.

The sdist and wheel are built from a copy of the checkout as a clone would hold it
(helpers/ros_package.copy_checkout), the .deb by scripts/package_deb.sh from the same
files: the checkout itself is never written.
"""

from __future__ import annotations

import subprocess
import sys
import zipfile
from dataclasses import dataclass
from email.message import Message
from email.parser import Parser
from pathlib import Path

from helpers.commands import HUNG, REPO

#: Hang stopper for a build or an install (pip, dpkg-buildpackage) on a loaded machine.
BUILD_LIMIT_S = 900.0

PACKAGE_DEB = REPO / "scripts" / "package_deb.sh"
DEB_NAME = "ros-jazzy-ros-isolated-test"
#: Where a ROS package of Jazzy installs, and the folder apt's remove must leave as it was.
ROS_PREFIX = "/opt/ros/jazzy"


def _run(command: list[str], cwd: Path | None = None, what: str = "") -> str:
    done = subprocess.run(
        command, cwd=cwd, capture_output=True, text=True, timeout=BUILD_LIMIT_S, check=False
    )
    assert done.returncode == 0, f"{what or command[0]} failed:\n{done.stdout}\n{done.stderr}"
    return done.stdout


@dataclass(frozen=True)
class Dists:
    """``python -m build``'s two artefacts."""

    sdist: Path
    wheel: Path


def build_dists(source: Path, out: Path) -> Dists:
    """``python -m build`` of ``source`` into ``out``: the sdist, then the wheel from it."""
    _run([sys.executable, "-m", "build", "--outdir", str(out), str(source)], what="python -m build")
    (sdist,) = out.glob("ros_isolated_test-*.tar.gz")
    (wheel,) = out.glob("ros_isolated_test-*.whl")
    return Dists(sdist, wheel)


def wheel_from_sdist(sdist: Path, root: Path) -> Path:
    """The sdist unpacked alone, and a wheel built from that and nothing else."""
    (root / "unpacked").mkdir(parents=True)
    _run(["tar", "-xzf", str(sdist), "-C", str(root / "unpacked")])
    (source,) = (root / "unpacked").iterdir()
    out = root / "dist"
    _run([sys.executable, "-m", "build", "--wheel", "--outdir", str(out), str(source)])
    (wheel,) = out.glob("ros_isolated_test-*.whl")
    return wheel


def wheel_contents(wheel: Path) -> dict[str, bytes]:
    """Every file of a wheel by name (RECORD included: it holds every other file's hash)."""
    with zipfile.ZipFile(wheel) as archive:
        return {name: archive.read(name) for name in archive.namelist()}


def wheel_metadata(wheel: Path) -> Message:
    """The wheel's METADATA, parsed as the core-metadata (email header) format it is."""
    (name,) = [n for n in wheel_contents(wheel) if n.endswith(".dist-info/METADATA")]
    return Parser().parsestr(wheel_contents(wheel)[name].decode())


def fresh_venv(root: Path, *requirements: str) -> Path:
    """A new venv of the base Python (never this suite's), with ``requirements`` from pip."""
    base = getattr(sys, "_base_executable", sys.executable)
    _run([base, "-m", "venv", str(root)], what="python -m venv")
    pip = [str(root / "bin" / "python"), "-m", "pip", "install", "-q"]
    _run([*pip, "--disable-pip-version-check", *requirements], what="pip install")
    return root


def build_deb(out: Path) -> Path:
    """scripts/package_deb.sh into ``out``: the one .deb it leaves."""
    _run([str(PACKAGE_DEB), str(out)], what="scripts/package_deb.sh")
    (deb,) = out.glob(f"{DEB_NAME}_*.deb")
    return deb


def deb_control(deb: Path) -> Message:
    """The .deb's control file (``dpkg-deb -f``), parsed: its fields by name."""
    return Parser().parsestr(_run(["dpkg-deb", "-f", str(deb)]))


def deb_file(deb: Path, member: str) -> str:
    """One file of the .deb's data, as text."""
    extracted = subprocess.run(
        f"dpkg-deb --fsys-tarfile '{deb}' | tar -xO '.{member}'",
        shell=True, capture_output=True, text=True, timeout=HUNG, check=False,
    )  # fmt: skip
    assert extracted.returncode == 0, extracted.stderr
    return extracted.stdout


#: The stand-in for ros_workspace's setup.sh: what a sourced Jazzy gives this package.
WORKSPACE_SETUP_SH = f"""\
# A stand-in for ros-jazzy-ros-workspace's setup.sh (tests/helpers/release.py): the
# paths a sourced ROS 2 Jazzy adds for a package installed under {ROS_PREFIX}.
export ROS_DISTRO=jazzy
export AMENT_PREFIX_PATH={ROS_PREFIX}
export CMAKE_PREFIX_PATH={ROS_PREFIX}
export PATH={ROS_PREFIX}/bin:$PATH
for _site in {ROS_PREFIX}/lib/python3*/site-packages; do
  export PYTHONPATH="$_site${{PYTHONPATH:+:$PYTHONPATH}}"
done
unset _site
"""


def workspace_stub_deb(out: Path) -> Path:
    """``ros-jazzy-ros-workspace``, a stand-in: the package's Depends names it, and the
    Debian base has no ROS. It holds the setup.sh alone, as the real one owns it."""
    root = out / "ros-workspace"
    (root / "DEBIAN").mkdir(parents=True)
    (root / "DEBIAN" / "control").write_text(
        "Package: ros-jazzy-ros-workspace\nVersion: 0.0.0-stand-in\nArchitecture: all\n"
        "Maintainer: ros-isolated-test tests <tests@ros-isolated-test.org>\n"
        "Description: stand-in for ROS 2 Jazzy's ros_workspace (setup.sh only)\n"
    )
    setup = root / ROS_PREFIX.lstrip("/") / "setup.sh"
    setup.parent.mkdir(parents=True)
    setup.write_text(WORKSPACE_SETUP_SH)
    deb = out / "ros-jazzy-ros-workspace_0.0.0-stand-in_all.deb"
    _run(["dpkg-deb", "--root-owner-group", "--build", str(root), str(deb)])
    return deb

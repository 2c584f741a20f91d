"""The Debian package installed with apt, as a ROS user installs it, on a real Docker engine.

scripts/package_deb.sh's .deb goes into the Debian base the container tier already makes
with debootstrap (tests/helpers/docker_engine.py), with ``apt-get install ./...deb``: its
dependencies come from the Debian archive. The base has no ROS, so a stand-in
``ros-jazzy-ros-workspace`` (the package's Depends names it) brings a minimal
``/opt/ros/jazzy/setup.sh``, sourced as users source the real one. Then the command, a run
on a reserved ID, the RUNNER, the CMake include and the pytest plugin under
``python3 -m pytest``; ``apt-get remove`` must leave ``/opt/ros/jazzy`` as it found it.

colcon is not in the base, and the colcon extension does not exist yet: ``colcon
extensions`` is checked where colcon is present (it is not, here), and the check says so.
"""

from __future__ import annotations

import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
from helpers import capabilities, docker_engine, release
from helpers.docker_engine import LABEL, Engine
from helpers.domains import free_ids
from helpers.release import BUILD_LIMIT_S, DEB_NAME, ROS_PREFIX

import ros_isolated_test

pytestmark = [capabilities.DOCKER_ENGINE.mark, capabilities.DEB_BUILD.mark]

#: Runs in the container as root (the Debian base's only user), and says what it saw in /out.
CHECK_SCRIPT = f"""\
set -eux
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
# What the base gets before ours: python3 -m pytest, and the stand-in ros_workspace.
apt-get install -y -qq python3-pytest /debs/ros-jazzy-ros-workspace_*.deb >/dev/null
find {ROS_PREFIX} | sort >/out/before.txt
apt-get install -y /debs/{DEB_NAME}_*.deb >/out/install.log 2>&1
dpkg-query -W -f='${{Version}}\\n' {DEB_NAME} >/out/installed-version.txt
find {ROS_PREFIX} | sort >/out/installed.txt

set +u  # as users source it: ROS's setup.sh reads unset variables
. {ROS_PREFIX}/setup.sh
set -u
ros-isolated-test --version >/out/version.txt
ros-isolated-test run -- sh -c 'echo "on $ROS_DOMAIN_ID"' >/out/run.txt
ros-isolated-test runner-path >/out/runner-path.txt
test -f "$(cat /out/runner-path.txt)"
ros-isolated-test cmake-include >/out/cmake-include.txt
test -f "$(cat /out/cmake-include.txt)"
mkdir -p /tmp/t && cd /tmp/t
printf 'import os\\n\\ndef test_domain():\\n    print("domain", os.environ["ROS_DOMAIN_ID"])\\n' \\
  >test_domain.py
python3 -m pytest -p no:cacheprovider --ros-isolation -s test_domain.py >/out/pytest.txt
if command -v colcon >/dev/null; then colcon extensions >/out/colcon.txt; fi
cd /

apt-get remove -y {DEB_NAME} >/out/remove.log 2>&1
find {ROS_PREFIX} | sort >/out/after.txt
"""


@pytest.fixture(scope="module")
def engine() -> Iterator[Engine]:
    with docker_engine.running() as running:
        yield running


@pytest.fixture(scope="module")
def debs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Ours, built by scripts/package_deb.sh, and the stand-in ros_workspace beside it."""
    folder = tmp_path_factory.mktemp("debs")
    release.build_deb(folder)
    release.workspace_stub_deb(folder)
    return folder


def test_apt_installs_the_deb_with_debians_python_and_every_way_in_works(
    engine: Engine, debs: Path, tmp_path: Path
) -> None:
    base = docker_engine.base_image(engine)
    out = tmp_path / "out"
    out.mkdir()
    (tmp_path / "check.sh").write_text(CHECK_SCRIPT)
    (pool_id,) = free_ids(1)
    done = subprocess.run(
        ["docker", "run", "--rm", "--label", LABEL, "--network", "host",
         "-e", f"ROS_ISOLATED_TEST_DOMAINS={pool_id}",
         "-v", f"{debs}:/debs:ro", "-v", f"{out}:/out", "-v", f"{tmp_path}/check.sh:/check.sh:ro",
         base, "bash", "/check.sh"],
        env=engine.env(), capture_output=True, text=True, timeout=BUILD_LIMIT_S, check=False,
        stdin=subprocess.DEVNULL,
    )  # fmt: skip
    said = {path.name: path.read_text() for path in out.iterdir()}
    assert done.returncode == 0, f"{done.stderr[-4000:]}\n{said.get('install.log', '')[-3000:]}"

    version = ros_isolated_test.__version__
    assert said["installed-version.txt"].startswith(f"{version}-"), said
    install_log = said["install.log"]
    for dependency in ("python3-click", "python3-filelock", "python3-lxml"):
        assert dependency in install_log, install_log  # from the Debian archive, by apt
    site = f"{ROS_PREFIX}/lib/python3"
    lines = said["version.txt"].splitlines()
    assert lines[0] == f"ros-isolated-test {version}", lines
    assert lines[1].startswith(f"installed in {site}") and "site-packages" in lines[1], lines
    assert lines[2].startswith("Python 3.") and "(/usr/bin/python3" in lines[2], lines
    assert f"on {pool_id}" in said["run.txt"].splitlines(), said["run.txt"]
    assert said["runner-path.txt"].startswith(site), said["runner-path.txt"]
    assert said["cmake-include.txt"].startswith(ROS_PREFIX), said["cmake-include.txt"]
    assert f"ros-isolated-test: ROS_DOMAIN_ID {pool_id}" in said["pytest.txt"], said["pytest.txt"]
    assert f"domain {pool_id}" in said["pytest.txt"], said["pytest.txt"]
    assert "1 passed" in said["pytest.txt"], said["pytest.txt"]
    assert "colcon.txt" not in said  # no colcon in the base (and no extension yet)

    # Removed, it leaves /opt/ros/jazzy as it found it: nothing of ours, no bytecode.
    before, after = said["before.txt"].splitlines(), said["after.txt"].splitlines()
    assert after == before, sorted(set(after) - set(before))
    # The control: installed, the same listing shows ours (and the bytecode py3compile made).
    installed = set(said["installed.txt"].splitlines()) - set(before)
    assert f"{ROS_PREFIX}/bin/ros-isolated-test" in installed, sorted(installed)
    assert any(path.endswith(".pyc") for path in installed), sorted(installed)
    assert "not empty so not removed" not in said["remove.log"], said["remove.log"]

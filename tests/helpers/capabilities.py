"""Named capability markers: the only way a test of this suite may be skipped.

A test skips only when the machine lacks something it needs (root, ``unshare``, namespaces,
the outside tier beside the checkout), never because the product failed: a
product error fails the test. Each marker says what is missing and how to get it, so the
``-rs`` summary explains every skip. In strict mode (``ROS_ISOLATED_TEST_NO_SKIPS=1``,
which ``.ci/run`` sets, or ``pytest --no-skips``) any skip fails the run instead.

Use: ``@capabilities.ROOT`` on a test, or ``pytestmark = [capabilities.UNSHARE]``; for a
need found only at run time, ``capabilities.require(capabilities.ROOT)`` inside it.
"""

from __future__ import annotations

import functools
import importlib.util
import os
import shutil
import socket
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
#: The outside tier: facts and third-party sources beside the checkout, in CI only.
SHARED = REPO.parent / "shared"
JENKINS_JUNIT10_XSD = SHARED / "reference" / "xunit-schemas" / "junit-10.xsd"
LAUNCH_SOURCES = SHARED / "vendor" / "ros2-launch-jazzy"


class Capability:
    """Something a test needs from the machine: checked once, named in every skip."""

    def __init__(self, name: str, check: Callable[[], str | None]) -> None:
        self.name = name
        self._check = check

    @functools.cached_property
    def missing(self) -> str | None:
        """Why the machine lacks it (a sentence naming the fix), or None when it has it."""
        return self._check()

    @property
    def mark(self) -> pytest.MarkDecorator:
        """``skipif`` with the reason, for a test, a class or ``pytestmark``."""
        return pytest.mark.skipif(self.missing is not None, reason=f"[{self.name}] {self.missing}")

    def __call__(self, function: Callable[..., object]) -> Callable[..., object]:
        """Used bare as a decorator: ``@capabilities.ROOT``."""
        return self.mark(function)  # type: ignore[no-any-return]


def require(*needs: Capability) -> None:
    """Skip the running test for the first missing capability (for needs found late)."""
    for need in needs:
        if need.missing is not None:
            pytest.skip(f"[{need.name}] {need.missing}")


def _root() -> str | None:
    if os.geteuid() == 0:
        return None
    return "needs root (CI runs the suite as root; sudo ./scripts/test.sh does too)"


def _run_ok(command: list[str]) -> str | None:
    """None when ``command`` runs and exits 0, else what it said."""
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=30, check=False)
    except (OSError, subprocess.TimeoutExpired) as error:
        return str(error)
    if done.returncode != 0:
        return (done.stderr or done.stdout).strip() or f"exit code {done.returncode}"
    return None


def _unshare() -> str | None:
    if shutil.which("unshare") is None:
        return "needs unshare(1) from util-linux (scripts/setup.sh installs it)"
    failed = _run_ok(["unshare", "--pid", "--fork", "--mount-proc", "true"])
    if failed is not None:
        return f"`unshare --pid --fork --mount-proc` is not permitted here (needs root): {failed}"
    return None


def _mount_namespace() -> str | None:
    if (missing := _root()) is not None:
        return f"mounting a private file system {missing}"
    if shutil.which("unshare") is None:
        return "needs unshare(1) from util-linux (scripts/setup.sh installs it)"
    import tempfile

    # What the tests do in it: mount a tmpfs, which a container may forbid even to root.
    with tempfile.TemporaryDirectory() as where:
        command = ["unshare", "--mount", "--propagation", "private"]
        failed = _run_ok([*command, "mount", "-t", "tmpfs", "tmpfs", where])
    if failed is not None:
        return f"cannot mount a tmpfs in a private mount namespace here: {failed}"
    return None


def _network_namespaces() -> str | None:
    if (missing := _root()) is not None:
        return f"building hosts out of network namespaces {missing}"
    tools = [tool for tool in ("ip", "unshare") if shutil.which(tool) is None]
    if tools:
        return f"needs {' and '.join(tools)} (iproute2, util-linux) to build hosts"
    failed = _run_ok(["unshare", "--net", "ip", "link", "set", "lo", "up"])
    if failed is not None:
        return f"cannot make a network namespace here (CAP_SYS_ADMIN, CAP_NET_ADMIN): {failed}"
    return None


def _other_users() -> str | None:
    """Children run as nobody (65534) and daemon (1), with an interpreter they may run."""
    if (missing := _root()) is not None:
        return f"running runners as other users {missing}"
    import pwd

    try:
        pwd.getpwuid(65534)
        pwd.getpwuid(1)
    except KeyError:
        return "needs the users nobody (65534) and daemon (1)"
    try:
        subprocess.run(
            [sys.executable, "-c", "import ros_isolated_test"],
            check=True,
            capture_output=True,
            user=65534,
            group=65534,
            extra_groups=[],
            cwd="/",
            timeout=60,
        )
    except (OSError, subprocess.SubprocessError) as error:
        return (
            f"user nobody cannot run this suite's Python ({sys.executable}): {error}; make the "
            "venv from an interpreter every user can run (scripts/setup.sh prefers "
            "/usr/bin/python3.11) and keep the checkout's path traversable"
        )
    return None


def _setpriv() -> str | None:
    """setpriv(1) starts a runner as nobody with supplementary groups and an ambient capability."""
    if (missing := _other_users()) is not None:
        return missing
    if shutil.which("setpriv") is None:
        return "needs setpriv(1) from util-linux (scripts/setup.sh installs it)"
    ambient = ["--inh-caps=+setgid", "--ambient-caps=+setgid"]
    failed = _run_ok(["setpriv", "--reuid=65534", "--regid=65534", "--groups=20", *ambient, "true"])
    if failed is not None:
        return f"setpriv cannot start a process as nobody with an ambient capability: {failed}"
    return None


def _setuid_helper() -> str | None:
    """A setuid-root program built in the temp dir (a process other users may not signal)."""
    if (missing := _other_users()) is not None:
        return missing
    folder = os.environ.get("TMPDIR", "/tmp")
    if os.statvfs(folder).f_flag & os.ST_NOSUID:
        return f"{folder} is mounted nosuid: a setuid helper built there would not become root"
    if shutil.which("gcc") is None:
        return "needs gcc to build a setuid helper (Debian's gcc)"
    return None


def _ipv6() -> str | None:
    try:
        with socket.socket(socket.AF_INET6, socket.SOCK_STREAM) as probe:
            probe.bind(("::1", 0))
    except OSError as error:
        return f"needs IPv6 on loopback (::1): {error.strerror}"
    return None


def _sock_diag_bound() -> str | None:
    """sock_diag's dump shows a TCP socket bound without listen(), as coordinators hold it.

    Probed here by hand (a port of the coordinators' range, its socket's inode looked for
    in ``holding_sockets``), not by the product's own probe, which tests check against it.
    """
    from ros_isolated_test.domain_coordinator import port_guard

    for domain_id in range(232, -1, -1):
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
            try:
                probe.bind(("", port_guard.PORT_BASE + domain_id))
            except OSError:
                continue  # taken: try the next
            held = port_guard.holding_sockets(domain_id)
            if held is not None and os.fstat(probe.fileno()).st_ino in held:
                return None
            break
    else:
        return "no port 32768-33000 was free to probe sock_diag's bound-only sockets with"
    kernel = os.uname().release
    return (
        f"needs Linux 6.8 or later (here {kernel}): sock_diag shows no bound-only TCP socket, "
        "which tells colcon's domain-ID coordinator's port from anyone's"
    )


def _shared() -> str | None:
    if SHARED.is_dir():
        return None
    return (
        f"the outside tier needs {SHARED.name}/ beside the checkout (the real Jenkins "
        "junit-10.xsd and vendored launch sources), which only the team's CI has"
    )


def _module(name: str) -> Callable[[], str | None]:
    def check() -> str | None:
        if importlib.util.find_spec(name) is not None:
            return None
        return f"needs the Python module {name} (scripts/setup.sh installs it into .venv)"

    return check


def _colcon() -> str | None:
    """rclpy for the example's tests, colcon and ament_cmake beside this interpreter."""
    if (missing := _module("rclpy")()) is not None:
        return missing
    if shutil.which("colcon", path=str(Path(sys.executable).parent)) is None:
        return "needs colcon and ament_cmake from the ros extra (scripts/setup.sh installs them)"
    return None


def _gtest() -> str | None:
    """What building googletest binaries with cmake needs: the tools and Debian's gtest."""
    tools = [tool for tool in ("cmake", "make", "c++") if shutil.which(tool) is None]
    if tools:
        return f"building googletest binaries needs {', '.join(tools)} (apt install cmake g++)"
    if not any(Path(root, "GTest", "GTestConfig.cmake").is_file() for root in _CMAKE_ROOTS):
        return "needs googletest's CMake package (apt install libgtest-dev)"
    return None


def _gmock() -> str | None:
    """ament_cmake_gmock builds googlemock from Debian's sources under /usr/src/gmock."""
    if (missing := _gtest()) is not None:
        return missing
    if not Path("/usr/include/gmock/gmock.h").is_file() or not Path("/usr/src/gmock").is_dir():
        return "needs googlemock's headers and sources (apt install libgmock-dev google-mock)"
    return None


_CMAKE_ROOTS = ("/usr/lib/cmake", *map(str, Path("/usr/lib").glob("*-linux-gnu*/cmake")))


def bare_python() -> str | None:
    """A system python3.11 that cannot import ros_isolated_test (not this suite's venv), if any.

    Debian's python3-filelock and python3-lxml may be there (the .deb's build needs them):
    what matters is that the package itself is not, as for ctest's python3 on a machine
    where ros-isolated-test lives in a venv.
    """
    candidate = shutil.which("python3.11", path="/usr/bin:/bin:/usr/local/bin")
    if candidate is None:
        return None
    # An empty environment and a neutral folder: no PYTHONPATH or checkout may lend it ours.
    probe = subprocess.run(
        [candidate, "-c", "import ros_isolated_test"],
        capture_output=True,
        env={},
        check=False,
        cwd="/",
    )
    return None if probe.returncode == 0 else candidate


def _bare_python() -> str | None:
    if bare_python() is not None:
        return None
    return (
        "needs a system python3.11 that cannot import ros-isolated-test, to run the RUNNER "
        "as ctest does with such a Python (apt install python3.11)"
    )


def other_python(version: str) -> str | None:
    """A Python ``version`` (``3.10``): on PATH, else the newest pyenv has; as
    scripts/py310_smoke.sh finds it (pyenv installs versions it does not put on PATH)."""
    on_path = shutil.which(f"python{version}")
    if on_path is not None and _run_ok([on_path, "-c", ""]) is None:
        return on_path  # (a pyenv shim on PATH fails for a version pyenv has not selected)
    try:
        root = subprocess.run(
            ["pyenv", "root"], capture_output=True, text=True, timeout=30, check=True
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    found = sorted(
        Path(root).glob(f"versions/{version}.*/bin/python{version}"),
        key=lambda path: [int(part) for part in path.parents[1].name.split(".") if part.isdigit()],
    )
    return str(found[-1]) if found else None


def _python(version: str) -> Callable[[], str | None]:
    def check() -> str | None:
        if other_python(version) is not None:
            return None
        return f"needs Python {version} (pyenv install {version}, or python{version} on PATH)"

    return check


def _tomllib() -> str | None:
    if importlib.util.find_spec("tomllib") is not None:
        return None
    return f"reading pyproject.toml needs Python 3.11+ (tomllib); this is {sys.version.split()[0]}"


#: A multi-gigabyte (mostly sparse) result file: this much free disk under the temp dir.
FREE_DISK_BYTES = 4 << 30


def _free_disk() -> str | None:
    import tempfile

    where = tempfile.gettempdir()
    usage = shutil.disk_usage(where)
    if usage.free >= FREE_DISK_BYTES:
        return None
    return (
        f"needs {FREE_DISK_BYTES >> 30} GiB free under {where} for a 2.5 GiB result file "
        f"({usage.free >> 20} MiB free)"
    )


#: Upstream's RUNNER (ament_cmake_ros, from the ros extra), for the controls that run it.
UPSTREAM_RUNNER_PATH = (
    Path(sys.prefix) / "share" / "ament_cmake_ros" / "cmake" / "run_test_isolated.py"
)


def _upstream_runner() -> str | None:
    if UPSTREAM_RUNNER_PATH.is_file():
        return None
    return (
        f"needs upstream's run_test_isolated.py at {UPSTREAM_RUNNER_PATH} (ament_cmake_ros, "
        "from the ros extra: scripts/setup.sh installs it)"
    )


#: colcon's domain-ID coordinator, installed apart from the venv's site-packages (scripts/setup.sh):
#: a colcon loads it only when given this folder on PYTHONPATH.
COLCON_COORDINATOR_DIR = Path(sys.prefix) / "colcon-coordinator"


def _colcon_coordinator() -> str | None:
    if (COLCON_COORDINATOR_DIR / "colcon_ros_domain_id_coordinator").is_dir():
        return None
    return (
        f"needs colcon-ros-domain-id-coordinator in {COLCON_COORDINATOR_DIR} "
        "(scripts/setup.sh installs it there)"
    )


def _gcc() -> str | None:
    return None if shutil.which("gcc") is not None else "needs gcc (Debian's gcc)"


def _kilted() -> str | None:
    """ROS 2 Kilted in .venv-kilted, whose Python imports rclpy (see helpers/distros.py)."""
    from helpers.distros import KILTED

    return KILTED.missing


def _distro_venv() -> str | None:
    """Ubuntu 24.04's Python packages with ROS 2 Jazzy and colcon (helpers/ros_package.py)."""
    from helpers.ros_package import distro_venv_problem

    return distro_venv_problem()


def _ctest() -> str | None:
    tools = [tool for tool in ("cmake", "ctest") if shutil.which(tool) is None]
    if tools:
        return f"needs {' and '.join(tools)} (apt install cmake)"
    return None


#: Where Debian's ignition-transport-cli puts its tools (there is no ``ign`` wrapper).
IGN_TRANSPORT_DIRS = "/usr/libexec/ignition/transport*"


def ign_transport_topic() -> Path | None:
    """Gazebo's topic tool (Debian's ``ign-transport-topic``, newest release), if installed."""
    found = sorted(
        Path("/").glob(IGN_TRANSPORT_DIRS.lstrip("/") + "/ign-transport-topic"),
        key=lambda tool: int("0" + "".join(filter(str.isdigit, tool.parent.name))),
    )
    if found:
        return found[-1]
    on_path = shutil.which("ign-transport-topic")
    return None if on_path is None else Path(on_path)


def _ign_transport() -> str | None:
    if ign_transport_topic() is not None:
        return None
    return (
        "needs Gazebo's transport tools, ign-transport-topic (apt install "
        "ignition-transport-cli; scripts/setup.sh installs it)"
    )


def _docker_engine() -> str | None:
    """A Docker engine answers, or dockerd can run here (root, overlay mounts)."""
    from helpers import docker_engine

    return docker_engine.missing()


def _chromium() -> str | None:
    """Headless Chromium, to open the report page as a person would (helpers/chromium.py)."""
    from helpers.chromium import executable

    found = executable()
    if found is None:
        return "needs Chromium for the report page (apt install chromium; scripts/setup.sh does)"
    failed = _run_ok([found, "--headless", "--no-sandbox", "--disable-gpu", "--version"])
    return None if failed is None else f"{found} does not start: {failed}"


#: libseccomp, as Docker links it: a real seccomp filter for the namespace-refusal tests.
LIBSECCOMP = "libseccomp.so.2"


def _seccomp() -> str | None:
    """libseccomp loads (a test installs a real filter with it, as Docker's profile is one)."""
    import ctypes

    try:
        ctypes.CDLL(LIBSECCOMP)
    except OSError as error:
        return f"needs {LIBSECCOMP} (apt install libseccomp2): {error}"
    return None


def _release_tools() -> str | None:
    """python -m build and twine, beside this interpreter (the dev extra)."""
    for name in ("build", "twine"):
        if (missing := _module(name)()) is not None:
            return missing
    return None


def _deb_build() -> str | None:
    """What scripts/package_deb.sh runs: bloom and rosdep from .venv, Debian's build tools."""
    here = Path(sys.executable).parent
    tools = [tool for tool in ("bloom-generate", "rosdep") if not (here / tool).is_file()]
    if tools:
        names = " and ".join(tools)
        return f"needs {names} beside {sys.executable} (scripts/setup.sh installs them)"
    tools = [t for t in ("dpkg-buildpackage", "dh_python3", "fakeroot") if shutil.which(t) is None]
    if tools:
        return (
            f"needs {', '.join(tools)} (apt install debhelper dh-python fakeroot; "
            "scripts/setup.sh does)"
        )
    probe = "import click, filelock, lxml"
    if _run_ok(["/usr/bin/python3", "-c", probe]) is not None:
        return (
            "the Debian build tests the package with Debian's python3, which needs "
            "python3-click, python3-filelock and python3-lxml (scripts/setup.sh installs them)"
        )
    return None


ROOT = Capability("root", _root)
UNSHARE = Capability("unshare", _unshare)
MOUNT_NAMESPACE = Capability("mount-namespace", _mount_namespace)
NETWORK_NAMESPACES = Capability("network-namespaces", _network_namespaces)
OTHER_USERS = Capability("other-users", _other_users)
#: Runners as nobody with supplementary groups (and an ambient CAP_SETGID), via setpriv(1).
SETPRIV = Capability("setpriv", _setpriv)
SETUID_HELPER = Capability("setuid-helper", _setuid_helper)
IPV6 = Capability("ipv6", _ipv6)
#: sock_diag's dump of bound-only sockets (Linux 6.8+): colcon's coordinator told apart.
SOCK_DIAG_BOUND = Capability("sock-diag-bound", _sock_diag_bound)
#: The outside tier: tests that read ``../shared`` (present in CI, absent in a fresh clone).
OUTSIDE = Capability("outside-tier", _shared)
RCLPY = Capability("rclpy", _module("rclpy"))
#: Building and testing the example ament_cmake package (rclpy, colcon, ament_cmake).
COLCON = Capability("colcon", _colcon)
#: A C++ compiler, cmake, make and googletest, to build real gtest binaries.
GTEST = Capability("gtest", _gtest)
#: googlemock's headers and sources too, for ament_add_gmock.
GMOCK = Capability("gmock", _gmock)
#: A system python3.11 that cannot import the package (see :func:`bare_python`).
BARE_PYTHON = Capability("bare-python3.11", _bare_python)
TOMLLIB = Capability("tomllib", _tomllib)
#: Other Pythons the product supports (3.10, the oldest; 3.12, Ubuntu 24.04's), run bare.
PYTHON310 = Capability("python3.10", _python("3.10"))
PYTHON312 = Capability("python3.12", _python("3.12"))
FREE_DISK = Capability("free-disk", _free_disk)
UPSTREAM_RUNNER = Capability("upstream-runner", _upstream_runner)
#: The distro venv (.venv-distro, made by scripts/setup.sh): Ubuntu 24.04's Python packages.
DISTRO_VENV = Capability("ubuntu-24.04-venv", _distro_venv)
#: cmake and ctest, to run a registered test under ctest's TIMEOUT.
CTEST = Capability("ctest", _ctest)
#: A C compiler, for a shared library a test builds (a stand-in RMW fixture).
GCC = Capability("gcc", _gcc)
#: colcon's domain-ID coordinator, for the tests that run colcon with it active.
COLCON_COORDINATOR = Capability("colcon-coordinator", _colcon_coordinator)
#: ROS 2 Kilted's venv (.venv-kilted, made by scripts/setup.sh), for the Kilted tier.
KILTED = Capability("kilted", _kilted)
#: Gazebo's transport CLI (Debian's ignition-transport-cli), for the simulation isolation tests.
IGN_TRANSPORT = Capability("ign-transport", _ign_transport)
#: A real Docker engine, started by the tier when needed, and what builds the stand-in base.
DOCKER_ENGINE = Capability("docker-engine", _docker_engine)
#: Headless Chromium (Debian's chromium), for the report page's tests.
CHROMIUM = Capability("chromium", _chromium)
#: libseccomp, to put a process under a real seccomp filter (as Docker's default profile).
SECCOMP = Capability("seccomp", _seccomp)
#: python -m build and twine, for the release artefacts (tests/e2e/test_release.py).
RELEASE_TOOLS = Capability("release-tools", _release_tools)
#: bloom, rosdep and Debian's package build tools, for scripts/package_deb.sh.
DEB_BUILD = Capability("deb-build", _deb_build)

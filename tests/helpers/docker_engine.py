"""A real Docker engine for the container tier: dockerd when needed, the images built once.

The tier (tests/e2e/test_docker_engine.py) runs the project's image as users run it. No image
registry is reachable from the test machines, so everything comes from here:

- The engine: one that answers at ``DOCKER_HOST`` (or the CLI's default socket) is used
  as it is. Otherwise, as root, a dockerd of the tier's own is started (Debian's
  docker.io, overlay2, no bridge: containers use the host's network or none), its images
  kept under the cache folder between runs. Test sessions running at once share it, each
  holding a shared lock on it; the last one to end stops it.
- The base: ``ros:jazzy-ros-base`` cannot be pulled, so a stand-in is built from
  tests/data/docker: a Debian 12 root file system made by debootstrap from the archive
  apt already uses, with ROS 2 Jazzy from PyPI wheels fetched on the host by pip (the
  build containers never need the package index, nor its certificates).
- Each image is built once per content: the root file system is tagged by its recipe,
  the wheelhouse is kept by its requirements, the rest is Docker's build cache. A second
  run rebuilds nothing that did not change.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import importlib
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from helpers.commands import HUNG, REPO

#: Where the engine's images, the wheelhouse and the build logs are kept between runs.
CACHE_ENV = "ROS_ISOLATED_TEST_DOCKER_CACHE"
DATA = REPO / "tests" / "data" / "docker"
STANDIN_DOCKERFILE = DATA / "standin.Dockerfile"
STANDIN_ENTRYPOINT = DATA / "ros_entrypoint.sh"
#: Debian 12, whose python3 is 3.11: the Python the ROS 2 Jazzy wheels are built for.
SUITE = "bookworm"
WHEEL_PYTHON = (3, 11)
#: Beside Debian's minimal base: what the stand-in needs to make its ROS venv, and ps.
ROOTFS_PACKAGES = ("python3", "python3-venv", "procps")
#: The stand-in's ROS, as its Dockerfile installs it: what ros:jazzy-ros-base gives a test.
ROS_REQUIREMENTS = ("ros-jazzy-rclpy[fastrtps]", "ros-jazzy-std-msgs", "pytest<9")
#: On every image and container of the tier: cleaning up never touches anyone else's.
LABEL = "org.ros-isolated-test.tier=docker-engine"
ROOTFS_REPO = "ros-isolated-test-rootfs"
STANDIN_REPO = "ros-isolated-test-standin"
PROJECT_TAG = "ros-isolated-test:engine-tests"
#: The lock directory inside the image (the runner's default there).
IMAGE_LOCK_DIR = "/tmp/ros-isolated-test-domains"
#: What containers share with the host to talk ROS to each other (README, "Docker").
HOST_NAMESPACES = ("--network", "host", "--ipc", "host", "--pid", "host")
#: Hang stoppers only: how long dockerd may take to answer, or to stop.
START_LIMIT_S = 120.0
STOP_LIMIT_S = 60.0
#: Hang stopper for a build step (debootstrap, pip, docker build) on a loaded machine.
BUILD_LIMIT_S = 900.0


def cache_dir() -> Path:
    """``$ROS_ISOLATED_TEST_DOCKER_CACHE``, else ``ros-isolated-test/docker`` in the user cache."""
    configured = os.environ.get(CACHE_ENV)
    if configured:
        return Path(configured)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "ros-isolated-test" / "docker"


def _digest(*parts: str | bytes) -> str:
    hasher = hashlib.sha256()
    for part in parts:
        data = part.encode() if isinstance(part, str) else part
        hasher.update(len(data).to_bytes(8, "big") + data)
    return hasher.hexdigest()[:12]


def _tail(path: Path, lines: int = 30) -> str:
    with contextlib.suppress(OSError):
        return "\n".join(path.read_text(errors="replace").splitlines()[-lines:])
    return "(no log)"


@contextlib.contextmanager
def _flocked(path: Path) -> Iterator[None]:
    """An exclusive lock on ``path`` (made if missing) for the block."""
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o600)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


# -- the engine -----------------------------------------------------------------------------


@dataclass(frozen=True)
class Engine:
    """A Docker engine the CLI reaches at ``host`` (``""``: the CLI's own default)."""

    host: str

    def env(self) -> dict[str, str]:
        env = dict(os.environ)
        if self.host:
            env["DOCKER_HOST"] = self.host
            env.pop("DOCKER_CONTEXT", None)
        return env

    def docker(
        self, *args: str, check: bool = True, timeout: float = HUNG
    ) -> subprocess.CompletedProcess[str]:
        """``docker ARGS``, output captured; a failure fails the test unless ``check=False``."""
        done = subprocess.run(
            ["docker", *args],
            env=self.env(),
            capture_output=True,
            text=True,
            timeout=timeout,
            check=False,
            stdin=subprocess.DEVNULL,
        )
        if check and done.returncode != 0:
            pytest.fail(f"docker {' '.join(args)} failed ({done.returncode}):\n{done.stderr}")
        return done

    def answers(self) -> bool:
        try:
            done = self.docker("info", "--format", "{{.ServerVersion}}", check=False, timeout=30)
        except (OSError, subprocess.TimeoutExpired):
            return False
        return done.returncode == 0


#: dockerd processes this session started, kept so they are waited for when stopped.
_STARTED: list[subprocess.Popen[bytes]] = []


class OwnDaemon:
    """The tier's own dockerd: data under the cache folder, socket and state in /tmp.

    ``users.lock`` is held shared by every session using it; ``state.lock`` makes the
    start and the stop one step each, so a session never uses a daemon being stopped.
    """

    def __init__(self, root: Path) -> None:
        self.root = root
        # A short path of its own: unix socket paths are limited to about 100 bytes.
        self.run_dir = Path(tempfile.gettempdir()) / f"rit-dockerd-{_digest(str(root))}"
        self.socket = self.run_dir / "docker.sock"
        self.pidfile = self.run_dir / "dockerd.pid"
        self.log = root / "dockerd.log"
        self.engine = Engine(f"unix://{self.socket}")

    @contextlib.contextmanager
    def used(self) -> Iterator[Engine]:
        self.root.mkdir(parents=True, exist_ok=True)
        users = os.open(self.root / "users.lock", os.O_RDWR | os.O_CREAT, 0o600)
        try:
            with _flocked(self.root / "state.lock"):
                fcntl.flock(users, fcntl.LOCK_SH)
                if not self.engine.answers():
                    self._start()
            yield self.engine
        finally:
            with _flocked(self.root / "state.lock"):
                fcntl.flock(users, fcntl.LOCK_UN)
                try:
                    fcntl.flock(users, fcntl.LOCK_EX | fcntl.LOCK_NB)
                except BlockingIOError:
                    pass  # another session still uses it: the last one stops it
                else:
                    self._stop()
            os.close(users)

    def _start(self) -> None:
        dockerd = shutil.which("dockerd")
        assert dockerd is not None, "the docker-engine capability checks for dockerd"
        self.run_dir.mkdir(mode=0o700, exist_ok=True)
        self._stop()  # one that no longer answers (a session killed mid-way) goes first
        config = self.root / "daemon.json"
        config.write_text("{}\n")  # not the machine's /etc/docker/daemon.json
        with self.log.open("ab") as out:
            process = subprocess.Popen(
                [
                    dockerd,
                    f"--config-file={config}",
                    f"--data-root={self.root / 'data'}",
                    f"--exec-root={self.run_dir / 'exec'}",
                    f"--pidfile={self.pidfile}",
                    f"--host={self.engine.host}",
                    "--storage-driver=overlay2",
                    # No bridge, no firewall rules: the host's network is left as it is.
                    "--bridge=none",
                    "--iptables=false",
                    "--ip-masq=false",
                ],
                stdin=subprocess.DEVNULL,
                stdout=out,
                stderr=out,
                start_new_session=True,  # not ended by a Ctrl-C meant for pytest
            )
        _STARTED.append(process)
        deadline = time.monotonic() + START_LIMIT_S
        while not self.engine.answers():
            if process.poll() is not None or time.monotonic() > deadline:
                self._stop()
                pytest.fail(f"dockerd did not start; the end of {self.log}:\n{_tail(self.log)}")
            time.sleep(0.2)

    def _stop(self) -> None:
        try:
            pid = int(self.pidfile.read_text().strip())
            # A pidfile outliving its dockerd (a reboot) may name someone else's process.
            is_dockerd = Path(f"/proc/{pid}/comm").read_text().strip() == "dockerd"
        except (OSError, ValueError):
            is_dockerd = False
        if not is_dockerd:
            with contextlib.suppress(FileNotFoundError):
                self.pidfile.unlink()
            self._unmount_leftovers()
            return
        ours = [process for process in _STARTED if process.pid == pid]
        for signum in (signal.SIGTERM, signal.SIGKILL):  # SIGKILL only if SIGTERM hangs
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signum)
            deadline = time.monotonic() + STOP_LIMIT_S
            while _alive(pid, ours) and time.monotonic() < deadline:
                time.sleep(0.1)
            if not _alive(pid, ours):
                break
        with contextlib.suppress(FileNotFoundError):
            self.pidfile.unlink()
        self._unmount_leftovers()

    def _unmount_leftovers(self) -> None:
        """What a stopped dockerd leaves mounted in its exec root (its netns handle)."""
        inside = f"{self.run_dir}/"
        with open("/proc/self/mounts", encoding="utf-8") as mounts:
            points = [line.split()[1] for line in mounts if line.split()[1].startswith(inside)]
        for point in sorted(points, reverse=True):
            subprocess.run(["umount", "--lazy", point], capture_output=True, check=False)


def _alive(pid: int, ours: Sequence[subprocess.Popen[bytes]]) -> bool:
    """Whether dockerd ``pid`` still runs: our own child is reaped, another's looked up."""
    if ours:
        return ours[0].poll() is None
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    status = Path(f"/proc/{pid}/stat")
    with contextlib.suppress(OSError):
        data = status.read_bytes()
        return data[data.rfind(b")") + 2 :].split()[0] != b"Z"
    return False


@contextlib.contextmanager
def running() -> Iterator[Engine]:
    """An engine for the session: one already answering, else the tier's own dockerd."""
    existing = Engine(os.environ.get("DOCKER_HOST", ""))
    if existing.answers():
        yield existing
        return
    with OwnDaemon(cache_dir() / "engine").used() as engine:
        yield engine


# -- what the machine needs -----------------------------------------------------------------


def debian_archive() -> str | None:
    """The Debian archive apt uses for SUITE, as apt names it (debootstrap's mirror)."""
    try:
        done = subprocess.run(
            ["apt-get", "indextargets", "--format", "$(REPO_URI) $(RELEASE) $(COMPONENT)"],
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
    except (OSError, subprocess.TimeoutExpired):
        return None
    for line in done.stdout.splitlines():
        words = line.split()
        if len(words) == 3 and words[1:] == [SUITE, "main"]:
            return words[0]
    return None


def _overlay_mounts() -> str | None:
    """None when an overlay file system mounts here (what overlay2 needs), else why not."""
    if shutil.which("unshare") is None:
        return "needs unshare(1) from util-linux to check for overlay mounts"
    with tempfile.TemporaryDirectory() as where:
        folders = [Path(where, name) for name in ("lower", "upper", "work", "merged")]
        for folder in folders:
            folder.mkdir()
        lower, upper, work, merged = folders
        options = f"lowerdir={lower},upperdir={upper},workdir={work}"
        command = ["unshare", "--mount", "--propagation", "private"]
        command += ["mount", "-t", "overlay", "overlay", "-o", options, str(merged)]
        done = subprocess.run(command, capture_output=True, text=True, timeout=30, check=False)
    if done.returncode != 0:
        return (done.stderr or done.stdout).strip() or f"exit code {done.returncode}"
    return None


def missing() -> str | None:
    """Why a Docker engine cannot run the tier here (naming the fix), or None."""
    if shutil.which("docker") is None:
        return "needs the docker CLI and dockerd (apt install docker.io; scripts/setup.sh does)"
    if sys.version_info[:2] != WHEEL_PYTHON:
        wanted = ".".join(map(str, WHEEL_PYTHON))
        return f"fetches the stand-in's ROS 2 wheels with this Python, which must be {wanted}"
    if os.geteuid() != 0:
        return "needs root to make the stand-in base with debootstrap (CI runs as root)"
    if shutil.which("debootstrap") is None:
        return "needs debootstrap for the stand-in base (apt install debootstrap; setup.sh does)"
    if debian_archive() is None:
        return f"needs apt configured with a Debian {SUITE} archive, which debootstrap uses"
    if Engine(os.environ.get("DOCKER_HOST", "")).answers():
        return None
    if shutil.which("dockerd") is None:
        return "no Docker engine answers and dockerd is missing (apt install docker.io)"
    failed = _overlay_mounts()
    if failed is not None:
        return f"dockerd's overlay2 storage needs overlay mounts, which fail here: {failed}"
    return None


# -- the images -----------------------------------------------------------------------------


@dataclass
class Images:
    """The project's image on the stand-in base, by image ID, and how long each step took."""

    project: str
    standin: str
    steps: list[str] = field(default_factory=list)


def _timed(steps: list[str], what: str, started: float) -> None:
    steps.append(f"{what} {time.monotonic() - started:.1f} s")


def _run_logged(command: Sequence[str], log: Path, what: str, env: dict[str, str]) -> None:
    with log.open("w") as out:
        done = subprocess.run(
            list(command),
            stdout=out,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            env=env,
            timeout=BUILD_LIMIT_S,
            check=False,
        )
    if done.returncode != 0:
        pytest.fail(f"{what} failed ({done.returncode}); the end of {log}:\n{_tail(log)}")


def _tags(engine: Engine, repository: str) -> list[str]:
    listed = engine.docker("image", "ls", repository, "--format", "{{.Repository}}:{{.Tag}}")
    return [line for line in listed.stdout.split() if not line.endswith(":<none>")]


def _drop_other_tags(engine: Engine, repository: str, keep: str) -> None:
    """Older builds of a recipe: nothing uses them any more (a container keeps its own)."""
    for tag in _tags(engine, repository):
        if tag != keep:
            engine.docker("image", "rm", tag, check=False)


def _rootfs(engine: Engine, cache: Path, steps: list[str]) -> str:
    """A minimal Debian root file system as an image, tagged by its recipe."""
    packages = ",".join(ROOTFS_PACKAGES)
    recipe = ["debootstrap", "--variant=minbase", f"--include={packages}", SUITE]
    # apt's caches stay out: the Dockerfiles run apt-get update themselves.
    excluded = ["./var/cache/apt/archives/*.deb", "./var/lib/apt/lists/*"]
    tag = f"{ROOTFS_REPO}:{SUITE}-{_digest(*recipe, *excluded)}"
    if tag in _tags(engine, ROOTFS_REPO):
        steps.append("root file system cached")
        return tag
    started = time.monotonic()
    mirror = debian_archive()
    assert mirror is not None, "the docker-engine capability checks for the archive"
    where = Path(tempfile.mkdtemp(prefix="rootfs-", dir=cache))
    try:
        root = where / "root"
        log = cache / "debootstrap.log"
        _run_logged([*recipe, str(root), mirror], log, "debootstrap", {**os.environ, "LC_ALL": "C"})
        tar = ["tar", "-C", str(root), *(f"--exclude={path}" for path in excluded), "-c", "."]
        with subprocess.Popen(tar, stdout=subprocess.PIPE) as packer:
            imported = subprocess.run(
                ["docker", "import", "--change", f"LABEL {LABEL}", "-", tag],
                stdin=packer.stdout,
                env=engine.env(),
                capture_output=True,
                text=True,
                timeout=BUILD_LIMIT_S,
                check=False,
            )
        if imported.returncode != 0 or packer.returncode != 0:
            pytest.fail(f"docker import of the root file system failed:\n{imported.stderr}")
    finally:
        shutil.rmtree(where, ignore_errors=True)
    _drop_other_tags(engine, ROOTFS_REPO, tag)
    _timed(steps, "root file system (debootstrap)", started)
    return tag


def _wheel_requirements() -> list[str]:
    """The stand-in's ROS, the runner's dependencies and its build backend (pyproject)."""
    tomllib = importlib.import_module("tomllib")  # WHEEL_PYTHON has it
    pyproject = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))
    project: list[str] = pyproject["project"]["dependencies"]
    build: list[str] = pyproject["build-system"]["requires"]
    return [*ROS_REQUIREMENTS, *project, *build]


def _wheelhouse(cache: Path, steps: list[str]) -> Path:
    """Every wheel the images install, fetched here by pip, kept by its requirement list."""
    requirements = _wheel_requirements()
    key = _digest(json.dumps(requirements), sys.version)
    houses = cache / "wheels"
    folder = houses / key
    if (folder / ".complete").is_file():
        steps.append("wheelhouse cached")
        return folder
    started = time.monotonic()
    shutil.rmtree(houses, ignore_errors=True)  # the old requirement lists' wheels go
    partial = houses / f"{key}.partial"
    partial.mkdir(parents=True)
    command = [sys.executable, "-m", "pip", "wheel", "--quiet", "--wheel-dir", str(partial)]
    _run_logged([*command, *requirements], cache / "pip-wheel.log", "pip wheel", dict(os.environ))
    (partial / ".complete").touch()
    partial.rename(folder)
    _timed(steps, "wheelhouse (pip)", started)
    return folder


def _build(
    engine: Engine,
    context: Path,
    dockerfile: Path,
    tag: str,
    build_args: dict[str, str],
    log: Path,
) -> str:
    """``docker build`` (Docker's cache makes an unchanged one quick); the image ID."""
    iidfile = log.with_suffix(".iid")
    iidfile.unlink(missing_ok=True)
    command = ["docker", "build", "--network", "host", "--label", LABEL, "--iidfile", str(iidfile)]
    for name, value in build_args.items():
        command += ["--build-arg", f"{name}={value}"]
    command += ["-t", tag, "-f", str(dockerfile), str(context)]
    _run_logged(command, log, f"docker build of {tag}", engine.env())
    return iidfile.read_text().strip()


def base_image(engine: Engine) -> str:
    """The Debian root file system alone (debootstrap's, cached as build_images caches it)."""
    cache = cache_dir()
    cache.mkdir(parents=True, exist_ok=True)
    with _flocked(cache / "build.lock"):
        return _rootfs(engine, cache, [])


def build_images(engine: Engine) -> Images:
    """The stand-in base and the project's image on it, each built at most once per content.

    Serialised between sessions (``build.lock``): two sessions never debootstrap at once.
    """
    cache = cache_dir()
    cache.mkdir(parents=True, exist_ok=True)
    steps: list[str] = []
    with _flocked(cache / "build.lock"):
        # The tier's images that lost their tag to a newer build (never anyone else's).
        engine.docker("image", "prune", "--force", "--filter", f"label={LABEL}", check=False)
        rootfs = _rootfs(engine, cache, steps)
        wheels = _wheelhouse(cache, steps)
        started = time.monotonic()
        recipe = _digest(
            STANDIN_DOCKERFILE.read_bytes(), STANDIN_ENTRYPOINT.read_bytes(), rootfs, wheels.name
        )
        standin_tag = f"{STANDIN_REPO}:jazzy-{recipe}"
        context = Path(tempfile.mkdtemp(prefix="standin-", dir=cache))
        try:
            shutil.copy2(STANDIN_ENTRYPOINT, context / STANDIN_ENTRYPOINT.name)
            shutil.copytree(wheels, context / "wheels", ignore=shutil.ignore_patterns(".*"))
            standin = _build(
                engine,
                context,
                STANDIN_DOCKERFILE,
                standin_tag,
                {"ROOTFS": rootfs},
                cache / "standin-build.log",
            )
        finally:
            shutil.rmtree(context, ignore_errors=True)
        _drop_other_tags(engine, STANDIN_REPO, standin_tag)
        _timed(steps, "stand-in base (docker build)", started)
        started = time.monotonic()
        project = _build(
            engine,
            REPO,
            REPO / "Dockerfile",
            PROJECT_TAG,
            {"BASE": standin_tag},
            cache / "project-build.log",
        )
        _timed(steps, "project image (docker build)", started)
    return Images(project=project, standin=standin, steps=steps)


# -- containers -----------------------------------------------------------------------------


class Containers:
    """The containers one test runs from ``image``, each named; all removed at its end."""

    def __init__(self, engine: Engine, image: str) -> None:
        self.engine = engine
        self.image = image
        self.names: list[str] = []
        self.processes: list[subprocess.Popen[str]] = []

    def command(self, options: Sequence[str], args: Sequence[str]) -> tuple[str, list[str]]:
        """A name and ``docker run --rm --name NAME OPTIONS IMAGE ARGS``."""
        name = f"rit-{uuid.uuid4().hex[:12]}"
        self.names.append(name)
        run = ["docker", "run", "--rm", "--name", name, "--label", LABEL, *options]
        return name, [*run, self.image, *args]

    def run(self, options: Sequence[str], args: Sequence[str]) -> subprocess.CompletedProcess[str]:
        """A container to its end: its exit code is ``docker run``'s."""
        _, command = self.command(options, args)
        return subprocess.run(
            command,
            env=self.engine.env(),
            capture_output=True,
            text=True,
            timeout=HUNG,
            check=False,
            stdin=subprocess.DEVNULL,
        )

    def start(
        self, options: Sequence[str], args: Sequence[str], log: Path
    ) -> tuple[str, subprocess.Popen[str]]:
        """A container in the background, attached (its output into ``log``)."""
        name, command = self.command(options, args)
        with log.open("w") as out:
            process = subprocess.Popen(
                command,
                env=self.engine.env(),
                stdin=subprocess.DEVNULL,
                stdout=out,
                stderr=subprocess.STDOUT,
                text=True,
            )
        self.processes.append(process)
        return name, process

    def remove_all(self) -> None:
        if self.names:
            self.engine.docker("rm", "--force", *self.names, check=False)
        for process in self.processes:
            try:
                process.wait(timeout=HUNG)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()

"""The scene of a machine running other ROS work, held by real processes for a session.

Tests must pass on a machine where other runners hold IDs in the default lock directory,
a shell exported ``ROS_DOMAIN_ID=7``, upstream's ``domain_coordinator`` binds its port and
a ROS node runs on an ID its code chose: the coordinator's port guard and participant
check are machine-wide, as they must be. So the
suite runs with such a scene in place, on the lowest IDs, which tests are most likely to
assume free.

Every process of the scene waits on a pipe only this process writes: when the suite ends,
however it ends (even SIGKILL), the pipe closes and the scene goes away by itself.
"""

from __future__ import annotations

import contextlib
import importlib.util
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterable
from pathlib import Path

from ros_isolated_test.domain_coordinator import participants, squatters
from ros_isolated_test.domain_coordinator.lock_dir import lock_dir_from_env
from ros_isolated_test.domain_coordinator.lock_files import probe_lock
from ros_isolated_test.domain_coordinator.pool import DEFAULT_SPEC, parse_pool
from ros_isolated_test.domain_coordinator.port_guard import port_is_taken

#: Set to 1 to run the suite on a quiet machine (debugging only; CI keeps the scene).
QUIET_ENV = "ROS_ISOLATED_TEST_QUIET_MACHINE"
#: The ID a user's shell exported, the classic squatter.
SQUATTED_ID = 7
RUNNERS = 2
#: Generous: each start is one runner or interpreter on a loaded machine.
START_DEADLINE_S = 120.0
STOP_DEADLINE_S = 30.0
#: upstream's domain_coordinator, holding the first ID whose port is free until stdin closes.
UPSTREAM_SCRIPT = """
import sys
import domain_coordinator
with domain_coordinator.domain_id() as domain_id:
    print(domain_id, flush=True)
    sys.stdin.read()
"""

#: A ROS node on the domain its code chose (argv[1]), no ROS_DOMAIN_ID in its environment.
PARTICIPANT_SCRIPT = """
import sys
import rclpy
from rclpy.context import Context
from rclpy.signals import SignalHandlerOptions
context = Context()
rclpy.init(args=[], context=context, domain_id=int(sys.argv[1]),
           signal_handler_options=SignalHandlerOptions.NO)
node = rclpy.create_node("busy_machine_participant", context=context)
print(sys.argv[1], flush=True)
sys.stdin.read()
"""


def clean_environment(bin_dir: Path) -> dict[str, str]:
    """What a fresh login would have: no ROS_* or ros-isolated-test settings at all."""
    keep = ("HOME", "LANG", "LC_ALL", "USER", "LOGNAME", "TERM")
    environ = {name: os.environ[name] for name in keep if name in os.environ}
    environ["PATH"] = f"{bin_dir}{os.pathsep}{os.environ.get('PATH', '/usr/bin:/bin')}"
    return environ


def in_use(domain_ids: Iterable[int]) -> set[int]:
    """The IDs that a runner using the default lock directory would find taken now."""
    wanted = set(domain_ids)
    lock_dir = lock_dir_from_env({})
    taken = set(squatters.scan(wanted)) | (set(participants.bound_domains()) & wanted)
    for domain_id in wanted - taken:
        if port_is_taken(domain_id) or (lock_dir.is_dir() and probe_lock(lock_dir, domain_id)):
            taken.add(domain_id)
    return taken


class Held:
    """One process of the scene, the ID it holds and how ``status`` sees it (``via``)."""

    def __init__(
        self, what: str, via: str, domain_id: int, process: subprocess.Popen[bytes]
    ) -> None:
        self.what = what
        self.via = via
        self.domain_id = domain_id
        self.process = process

    def __str__(self) -> str:
        return f"ID {self.domain_id}: {self.what} (pid {self.process.pid})"


class Scene:
    """The processes holding IDs for the session; :meth:`stop` ends every one."""

    def __init__(self, bin_dir: Path, workdir: Path) -> None:
        self.bin_dir = bin_dir
        self.workdir = workdir
        self.held: list[Held] = []
        self._starting: list[subprocess.Popen[bytes]] = []

    def describe(self) -> str:
        """One line per holder, for the terminal and for every failing test's report."""
        if not self.held:
            return "busy machine: nothing held"
        lines = [f"busy machine (set {QUIET_ENV}=1 to turn it off):"]
        lines += [f"  {item}" for item in self.held]
        return "\n".join(lines)

    def _start(self, name: str, args: list[str], env: dict[str, str]) -> subprocess.Popen[bytes]:
        """A process of the scene: its own session (killed as a group), waiting on stdin."""
        log = self.workdir / f"{name}.log"
        with log.open("wb") as output:
            process = subprocess.Popen(
                args,
                stdin=subprocess.PIPE,
                stdout=output,
                stderr=subprocess.STDOUT,
                env=env,
                cwd=self.workdir,
                start_new_session=True,
            )
        self._starting.append(process)
        return process

    def _first_line(self, name: str, process: subprocess.Popen[bytes]) -> str:
        """The first line the process printed; raises with its output if it never came."""
        log = self.workdir / f"{name}.log"
        deadline = time.monotonic() + START_DEADLINE_S
        while time.monotonic() < deadline:
            text = log.read_text(errors="replace")
            if "\n" in text:
                return text.split("\n", 1)[0]
            if process.poll() is not None:
                break
            time.sleep(0.05)
        raise RuntimeError(f"busy machine: {name} did not start: {log.read_text()!r}")

    def start_runner(self, index: int, domain_id: int) -> bool:
        """``ros-isolated-test run`` holding ``domain_id`` in the default lock directory.

        The pool is that one ID: the runner would pick any least recently used ID, and
        the lowest ones are what tests most likely assume free. False if it was taken.
        """
        name = f"runner-{index}-on-{domain_id}"
        env = clean_environment(self.bin_dir)
        env["ROS_ISOLATED_TEST_DOMAINS"] = str(domain_id)
        cli = str(self.bin_dir / "ros-isolated-test")
        process = self._start(
            name,
            [cli, "run", "--wait-timeout", "0", "--", "sh", "-c", "read -r stop", f"scene-{name}"],
            env,
        )
        line = self._first_line(name, process)
        if not line.startswith(f"Running with ROS_DOMAIN_ID {domain_id} "):
            self._stop(process)
            return False
        self.held.append(
            Held(f"ros-isolated-test run, default lock dir ({name})", "lock", domain_id, process)
        )
        return True

    def start_squatter(self, domain_id: int) -> None:
        """A process with ``ROS_DOMAIN_ID`` in its environment and no reservation."""
        env = clean_environment(self.bin_dir)
        env["ROS_DOMAIN_ID"] = str(domain_id)
        process = self._start("squatter", ["sh", "-c", "read -r stop", "scene-squatter"], env)
        # Seen by the squatter scan only once exec'd: wait for its environment to show.
        deadline = time.monotonic() + START_DEADLINE_S
        while process.pid not in {seen.pid for seen in squatters.scan().get(domain_id, [])}:
            if time.monotonic() > deadline or process.poll() is not None:
                raise RuntimeError("busy machine: the squatter did not start")
            time.sleep(0.05)
        self.held.append(
            Held(
                f"squatter, ROS_DOMAIN_ID={domain_id} in its environment",
                "environment",
                domain_id,
                process,
            )
        )

    def start_upstream(self) -> None:
        """upstream's ``domain_coordinator`` (the ros extra) binding port 32768+ID."""
        env = clean_environment(self.bin_dir)
        process = self._start("upstream", [sys.executable, "-c", UPSTREAM_SCRIPT], env)
        domain_id = int(self._first_line("upstream", process))
        self.held.append(
            Held(
                f"upstream domain_coordinator, port {32768 + domain_id}", "port", domain_id, process
            )
        )

    def start_participant(self, domain_id: int) -> None:
        """A real rclpy node on ``domain_id``, chosen in its code: only its UDP ports show it."""
        env = clean_environment(self.bin_dir)
        process = self._start(
            "participant", [sys.executable, "-c", PARTICIPANT_SCRIPT, str(domain_id)], env
        )
        self._first_line("participant", process)
        self.held.append(
            Held(f"rclpy node, its code chose {domain_id}", "participant", domain_id, process)
        )

    def _stop(self, process: subprocess.Popen[bytes]) -> None:
        """Close its pipe (it exits by itself), else SIGTERM, then SIGKILL, its group.

        A group is signalled only while its leader is unreaped, so its ID cannot have
        been reused by anyone else's processes.
        """
        with contextlib.suppress(OSError):
            if process.stdin is not None:
                process.stdin.close()
        for signum in (None, signal.SIGTERM, signal.SIGKILL):
            if signum is not None:
                with contextlib.suppress(OSError):
                    os.killpg(process.pid, signum)
            try:
                process.wait(timeout=STOP_DEADLINE_S)
                return
            except subprocess.TimeoutExpired:
                continue

    def check(self) -> None:
        """Raise unless every ID of the scene is in use as ``status`` sees it, machine-wide.

        ``status`` names one holder per ID, the strongest: another session's upstream
        coordinator may bind the port of the ID the scene's node chose meanwhile, and
        the ID is then listed as "port", in use all the same.
        """
        from ros_isolated_test.domain_coordinator import domain_uses

        lock_dir = lock_dir_from_env({})
        seen = {item.domain_id for item in domain_uses(lock_dir, parse_pool("1-232"))}
        missing = {(held.domain_id, held.via) for held in self.held if held.domain_id not in seen}
        if missing:
            raise RuntimeError(f"busy machine: not in use as it should be: {missing}")

    def stop(self) -> None:
        """End every process of the scene, the ones still starting too."""
        for process in self._starting:
            self._stop(process)
        self._starting.clear()
        self.held.clear()


def build(bin_dir: Path, workdir: Path) -> Scene:
    """Start the scene: runners on the lowest free IDs, upstream, a squatter on 7, a node.

    On any failure, or an interrupt, whatever was started is stopped before raising.
    """
    scene = Scene(bin_dir, workdir)
    try:
        pool = parse_pool(DEFAULT_SPEC)
        started = 0
        for domain_id in pool:
            if started == RUNNERS:
                break
            if domain_id not in in_use([domain_id]) and scene.start_runner(started, domain_id):
                started += 1
        if started < RUNNERS:
            raise RuntimeError(
                f"busy machine: only {started} of {RUNNERS} runners could hold an ID"
            )
        scene.start_upstream()
        if SQUATTED_ID not in in_use([SQUATTED_ID]):
            scene.start_squatter(SQUATTED_ID)
        if importlib.util.find_spec("rclpy") is not None:
            taken = {held.domain_id for held in scene.held} | {SQUATTED_ID}
            free = [i for i in pool if i not in taken and i not in in_use([i])]
            scene.start_participant(free[0])
        scene.check()
    except BaseException:
        scene.stop()
        raise
    return scene

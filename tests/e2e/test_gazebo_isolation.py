"""Simulation tests run at once stay apart on Gazebo's real transport, as on DDS.

Three probes (helpers/gz_probe.py) start together, each listening on one Gazebo topic
and publishing its own token with the real ``ign-transport-topic``, all of them
publishing only once every listener is live. Through ``run`` and through the RUNNER,
each hears its own token only. The controls are the same three with isolation disabled
(``DISABLE_ROS_ISOLATION=1``, through ``run``) and with the partition switched off
(``ROS_ISOLATED_TEST_GZ_PARTITION=off`` in the RUNNER's ``--env``, IDs still held):
they hear each other, and the test fails if they stop hearing each other, since the
isolated case would then prove nothing.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from helpers import capabilities, gz_probe
from helpers.commands import CLI, HUNG, ament_args
from helpers.results import load_result

from ros_isolated_test.runner import partition

# Two groups at most (see Probes.run), each stopped after HUNG * 2 if it hangs.
pytestmark = [capabilities.IGN_TRANSPORT.mark, pytest.mark.timeout(HUNG * 5)]

PROBE = Path(__file__).resolve().parents[1] / "helpers" / "gz_probe.py"
PROBES = 3


class Probes:
    """Three probes started at once through ``run`` or the RUNNER, and what each heard."""

    def __init__(self, tmp_path: Path, mode: str, env: dict[str, str], runner_script: str) -> None:
        self.base = tmp_path / mode
        self.mode = mode
        self.env = env
        self.runner_script = runner_script
        self.processes: list[subprocess.Popen[bytes]] = []
        self._fresh(1)

    def _fresh(self, attempt: int) -> None:
        self.folder = self.base / f"attempt-{attempt}"
        self.rendezvous = self.folder / "rendezvous"
        self.rendezvous.mkdir(parents=True)
        # Unique to this run: another run of these tests elsewhere is never mistaken for one.
        self.tokens = [f"t{index}_{os.getpid()}_{os.urandom(3).hex()}" for index in range(PROBES)]
        self.processes = []

    def result(self, token: str) -> Path:
        return self.folder / "out" / "pkg" / f"{token}.xml"

    def log(self, token: str) -> Path:
        return self.folder / f"{token}.log"

    def run(self, options: tuple[str, ...] = ()) -> None:
        """All three started at once and ended, each passed (heard itself, met the others).

        Once only, a group is started afresh when a probe never heard itself: Gazebo's
        transport tool failed, which says nothing of isolation (what each heard is never
        retried). The first group's evidence is kept as a warning.
        """
        for attempt in (1, 2):
            if attempt > 1:
                self._fresh(attempt)
            self._start(options)
            codes = self._finish()
            if codes == [0] * PROBES:
                return
            if attempt == 1 and self._transport_failed():
                warnings.warn(f"Gazebo's transport failed once:\n{self.evidence()}", stacklevel=2)
                continue
            pytest.fail(f"probes ended with {codes}:\n{self.evidence()}")

    def _start(self, options: tuple[str, ...]) -> None:
        tool = capabilities.ign_transport_topic()
        assert tool is not None  # the module's mark
        for token in self.tokens:
            command = [sys.executable, str(PROBE), str(tool), str(self.rendezvous), token]
            command.append(str(PROBES))
            if self.mode == "shell":
                assert not options
                argv = [CLI, "run", "--junit-xml", str(self.result(token)), "--", *command]
            else:
                args = ament_args(
                    self.result(token), command, "--generate-result-on-success", *options
                )
                argv = [sys.executable, "-u", self.runner_script, *args]
            with self.log(token).open("wb") as out:
                self.processes.append(
                    subprocess.Popen(
                        argv, env=self.env, stdin=subprocess.DEVNULL, stdout=out, stderr=out
                    )
                )

    def _finish(self) -> list[int | None]:
        """Every probe's exit code (None: hung, and ended).

        A probe that fails makes its peers stop at once (``gz_probe``), so the wait ends
        with the reason; the deadline, inside pytest's timeout, only stops a hang.
        """
        deadline = time.monotonic() + HUNG * 2
        for process in self.processes:
            try:
                process.wait(max(deadline - time.monotonic(), 1))
            except subprocess.TimeoutExpired:
                self.stop()
                return [None] * PROBES
        return [process.returncode for process in self.processes]

    def _transport_failed(self) -> bool:
        """Whether every probe that failed first (not for a peer) never heard itself."""
        reasons = [path.read_text() for path in self.rendezvous.glob("failed-*")]
        first = [reason for reason in reasons if not reason.startswith(gz_probe.PEER_FAILED)]
        return bool(first) and all(reason.startswith(gz_probe.NEVER_HEARD) for reason in first)

    def evidence(self) -> str:
        """Every probe's runner log and every rendezvous file: why a group failed."""
        parts = [
            f"--- {path.name}\n{path.read_text(errors='replace')}"
            for path in (
                *(self.log(token) for token in self.tokens),
                *sorted(self.rendezvous.iterdir()),
            )
        ]
        return "\n".join(parts)

    def heard(self, token: str) -> set[str]:
        return set((self.rendezvous / f"heard-{token}").read_text().split())

    def partition_of(self, token: str) -> dict[str, str]:
        lines = (self.rendezvous / f"partition-{token}").read_text().split()
        return dict(line.split("=", 1) for line in lines)

    def stop(self) -> None:
        for process in self.processes:
            if process.poll() is None:
                process.terminate()
        for process in self.processes:
            try:
                process.wait(HUNG)
            except subprocess.TimeoutExpired:
                process.kill()


MakeProbes = Callable[[str, dict[str, str]], Probes]


@pytest.fixture
def probes(tmp_path: Path, env: dict[str, str], runner_script: str) -> Iterator[MakeProbes]:
    """Makes a group of probes (mode, extra environment); whatever still runs is ended."""
    made: list[Probes] = []

    def make(mode: str, extra_env: dict[str, str]) -> Probes:
        made.append(Probes(tmp_path, mode, {**env, **extra_env}, runner_script))
        return made[-1]

    yield make
    for item in made:
        item.stop()


@pytest.mark.parametrize("mode", ["shell", "runner"])
def test_three_simulations_at_once_each_hear_only_their_own_token(
    probes: MakeProbes, mode: str
) -> None:
    group = probes(mode, {})
    group.run()
    names = set()
    for token in group.tokens:
        assert group.heard(token) == {token}, (token, group.heard(token))
        seen = group.partition_of(token)
        assert seen["GZ_PARTITION"] == seen["IGN_PARTITION"], seen
        name = seen["GZ_PARTITION"]
        assert name.startswith("rit_"), seen
        names.add(name)
        assert load_result(group.result(token)).properties["gz_partition"] == name
        assert f"Gazebo transport partition {name} " in group.log(token).read_text()
    assert len(names) == PROBES, names


@pytest.mark.parametrize(
    ("mode", "extra_env", "options"),
    [
        ("shell", {"DISABLE_ROS_ISOLATION": "1"}, ()),
        ("runner", {}, ("--env", f"{partition.OPT_OUT_ENV}=off")),
    ],
    ids=["run-isolation-disabled", "runner-partition-off"],
)
def test_control_without_partitions_the_same_three_hear_each_other(
    probes: MakeProbes, mode: str, extra_env: dict[str, str], options: tuple[str, ...]
) -> None:
    group = probes(mode, extra_env)
    group.run(options)
    for token in group.tokens:
        assert group.partition_of(token) == {"GZ_PARTITION": "-", "IGN_PARTITION": "-"}
        # Every other probe's token: the crosstalk a partition per test prevents.
        assert set(group.tokens) <= group.heard(token), (token, group.heard(token))

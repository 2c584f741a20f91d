"""What keeps a test's runner cheap, checked by what it loads and does, never by a clock.

Every ctest test pays the RUNNER's start-up (benches/ measures it). The heavy modules
(HEAVY: lxml, filelock, subprocess, json, locale, ...) stay unloaded on the common
path; they load only where they are needed: lxml when the test wrote its own result
file, filelock when a runner has to queue for an ID, locale to show a failure. Also
here: the test is started as ``subprocess`` would start it (its PATH, default SIGPIPE,
no inherited descriptors), and a ``filelock`` lock and our reservation exclude each other.
"""

from __future__ import annotations

import functools
import io
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import filelock
import pytest
from helpers.commands import ament, run_cli, run_runner
from helpers.domains import free_ids

from ros_isolated_test.domain_coordinator import DomainCoordinator
from ros_isolated_test.domain_coordinator.lock_files import lock_path
from ros_isolated_test.process import spawn, supervisor
from ros_isolated_test.process.capture import OutputCapture

#: Modules the common path must not load: each costs more than a millisecond.
HEAVY = (
    "lxml",
    "filelock",
    "subprocess",
    "dataclasses",
    "typing",
    "json",
    "argparse",
    "tempfile",
    "socket",
    "threading",
    "inspect",
    "click",
    # Only to decode the output tail, which a passing test's result never shows.
    "locale",
    # The C functions are bound through _ctypes (ros_isolated_test.libc); shell quoting
    # is ros_isolated_test.text's.
    "ctypes",
    "shlex",
)
#: What each feature loads, and how a test asks for it: a test that does not ask loads none.
FEATURES = {
    "split": ({"ROS_ISOLATED_TEST_SHARD": "1/1"}, "ros_isolated_test.shard.record"),
    "reruns": ({"ROS_ISOLATED_TEST_RERUNS": "1"}, "ros_isolated_test.runner.reruns"),
    "resources": (
        {"ROS_ISOLATED_TEST_RESOURCES": "cpu=1"},
        "ros_isolated_test.domain_coordinator.resource_holds",
    ),
    # A rerun that passed: the result keeps the failed attempt.
    "attempts": ({"ROS_ISOLATED_TEST_RERUNS": "1"}, "ros_isolated_test.xunit.attempts"),
}
#: Fails the first time, passes the second: the flaky test the "attempts" feature needs.
_FLAKY = "test -e ran-once || { : > ran-once; exit 1; }"


def _imported(argv: list[str], env: dict[str, str], cwd: Path | None = None) -> set[str]:
    """The modules ``python -X importtime ARGV`` imported, by their full names."""
    proc = subprocess.run(
        [sys.executable, "-X", "importtime", *argv],
        env=env,
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    names = {
        line.rsplit("|", 1)[1].strip()
        for line in proc.stderr.splitlines()
        if line.startswith("import time:") and "|" in line
    }
    assert names, proc.stderr
    return names


def _loaded_by(runner_script: str, args: list[str], env: dict[str, str], cwd: Path) -> set[str]:
    return _imported(["-u", runner_script, *args], env, cwd)


def _baseline(env: dict[str, str]) -> set[str]:
    return _imported(["-c", "pass"], env)


def _heavy(names: set[str], baseline: set[str]) -> list[str]:
    return sorted(name for name in names - baseline if name.split(".")[0] in HEAVY)


def test_a_passing_test_without_own_result_file_loads_nothing_heavy(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    args = [str(result), "--package-name", "pkg", "--generate-result-on-success"]
    names = _loaded_by(runner_script, [*args, "--command", "true"], env, tmp_path)
    assert _heavy(names, _baseline(env)) == []
    assert "ros_isolated_test.runner.session" in names, "the check must see the real run"
    assert result.is_file()


@pytest.mark.parametrize("feature", sorted(FEATURES))
def test_a_feature_a_test_does_not_use_costs_it_nothing(
    runner_script: str, env: dict[str, str], tmp_path: Path, feature: str
) -> None:
    """The module of each feature loads only when it is asked for: the control asks."""
    extra, module = FEATURES[feature]
    loaded: dict[bool, set[str]] = {}
    for asked in (False, True):
        command = ["sh", "-c", _FLAKY if asked and feature == "attempts" else "true"]
        (tmp_path / "ran-once").unlink(missing_ok=True)
        result = tmp_path / str(asked) / "pkg" / "t.xml"
        args = [str(result), "--package-name", "pkg", "--generate-result-on-success"]
        given = {**env, **extra} if asked else env
        loaded[asked] = _loaded_by(runner_script, [*args, "--command", *command], given, tmp_path)
    assert module not in loaded[False]
    assert module in loaded[True], "the control: asked for, the feature loads its module"


@pytest.mark.parametrize("share", ["1/2", "2/2"])
def test_a_split_by_count_loads_nothing_heavy_on_either_share(
    runner_script: str, env: dict[str, str], tmp_path: Path, share: str
) -> None:
    """Every machine of a split starts every test's RUNNER: the share that skips the test
    and the one that runs it both stay lean (the hash needs no OpenSSL, the record no json)."""
    result = tmp_path / "pkg" / "t.xml"
    args = [str(result), "--package-name", "pkg", "--generate-result-on-success"]
    given = {**env, "ROS_ISOLATED_TEST_SHARD": share}
    proc = subprocess.run(
        [sys.executable, "-X", "importtime", "-u", runner_script, *args, "--command", "true"],
        env=given, cwd=tmp_path, capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert proc.returncode in (0, 77), proc.stdout + proc.stderr  # this share's, or another's
    names = {
        line.rsplit("|", 1)[1].strip()
        for line in proc.stderr.splitlines()
        if line.startswith("import time:") and "|" in line
    }
    assert _heavy(names, _baseline(env)) == []
    assert "ros_isolated_test.shard.plan" in names, "the check must see the split decided"
    assert (tmp_path / "pkg" / f"ros_isolated_test_shard-{share[0]}-of-2.json").is_file()


def test_a_test_with_its_own_result_file_loads_lxml_to_read_and_validate_it(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    own = '<testsuite name="s" tests="1"><testcase classname="C" name="a"/></testsuite>'
    command = ["sh", "-c", f"printf '%s' '{own}' > {result}"]
    names = _loaded_by(
        runner_script, [str(result), "--package-name", "pkg", "--command", *command], env, tmp_path
    )
    assert "lxml.etree" in names
    assert "filelock" not in names


@pytest.mark.parametrize(
    "tools",
    [
        [("tools", "#!/bin/sh\necho ran\n")],
        # As execvp (and Popen) do: ENOENT from one match on PATH means try the next.
        [("broken", "#!/no/such/interpreter\n"), ("working", "#!/bin/sh\necho ran\n")],
    ],
    ids=["only-on-the-test-path", "missing-interpreter-then-a-working-match"],
)
def test_the_command_is_found_on_the_tests_own_path(
    runner_script: str, env: dict[str, str], tmp_path: Path, tools: list[tuple[str, str]]
) -> None:
    """The runner's PATH has none of these folders: only the test's PATH finds ``tool``."""
    for name, body in tools:
        (tmp_path / name).mkdir()
        (tmp_path / name / "tool").write_text(body)
        (tmp_path / name / "tool").chmod(0o755)
    path = ":".join([*(str(tmp_path / name) for name, _ in tools), "/usr/bin", "/bin"])
    result = tmp_path / "pkg" / "t.xml"
    options = ("--generate-result-on-success", "--env", f"PATH={path}")
    proc = ament(runner_script, result, ["tool"], env, *options, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "ran\n" in proc.stdout


def test_a_runner_started_with_sigchld_ignored_still_sees_the_exit_code(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    """An ignored SIGCHLD is inherited across exec; the kernel would then reap the test."""
    result = tmp_path / "pkg" / "t.xml"
    args = [str(result), "--command", "sh", "-c", "exit 3"]
    ignore = functools.partial(signal.signal, signal.SIGCHLD, signal.SIG_IGN)
    proc = run_runner(runner_script, args, env, preexec_fn=ignore)
    assert proc.returncode == 3, proc.stdout + proc.stderr
    assert "exited with code 3" in proc.stdout


def test_a_status_reaped_elsewhere_is_a_failure_never_a_pass() -> None:
    """Off the main thread SIGCHLD cannot be reset: an ignored one loses the status."""
    console = io.BytesIO()
    outcomes: list[supervisor.Outcome] = []

    def run() -> None:
        outcomes.append(supervisor.run(["true"], dict(os.environ), OutputCapture(console)))

    previous = signal.signal(signal.SIGCHLD, signal.SIG_IGN)
    try:
        thread = threading.Thread(target=run)
        thread.start()
        thread.join(60)
    finally:
        signal.signal(signal.SIGCHLD, previous)
    assert outcomes, "the supervisor did not return"
    assert outcomes[0].returncode == spawn.STATUS_LOST
    assert b"exit status was lost" in console.getvalue()


def test_a_file_that_is_not_executable_is_reported_as_such(
    env: dict[str, str], tmp_path: Path
) -> None:
    script = tmp_path / "not-executable"
    script.write_text("#!/bin/sh\ntrue\n")
    script.chmod(0o644)
    proc = run_cli(["run", "--", str(script)], env, cwd=tmp_path)
    assert proc.returncode == 126, proc.stdout + proc.stderr
    assert "Permission denied" in proc.stdout + proc.stderr


def test_the_test_gets_the_default_sigpipe(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    """Python ignores SIGPIPE; a test must not inherit that (``yes | head`` would complain)."""
    result = tmp_path / "pkg" / "t.xml"
    command = ["sh", "-c", "yes | head -n 1; echo done"]
    # The control: started with SIGPIPE ignored, the same command does complain.
    control = subprocess.run(
        command, capture_output=True, text=True, timeout=60, check=False, restore_signals=False
    )
    assert "Broken pipe" in control.stderr, control.stderr
    args = [str(result), "--generate-result-on-success", "--command", *command]
    proc = run_runner(runner_script, args, env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "Broken pipe" not in proc.stdout + proc.stderr
    assert "y\ndone\n" in proc.stdout


def test_descriptors_the_runner_inherited_do_not_reach_the_test(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    read_fd, write_fd = os.pipe()
    try:
        command = ["sh", "-c", f"ls /proc/$$/fd; [ ! -e /proc/$$/fd/{write_fd} ]"]
        # The control: a process handed the descriptor does see it.
        assert subprocess.run(command, pass_fds=(write_fd,), check=False).returncode != 0
        args = [str(result), "--generate-result-on-success", "--command", *command]
        proc = run_runner(runner_script, args, env, pass_fds=(write_fd,))
    finally:
        os.close(read_fd)
        os.close(write_fd)
    assert proc.returncode == 0, f"fd {write_fd} reached the test:\n{proc.stdout}{proc.stderr}"


def test_a_filelock_on_an_ids_lock_file_keeps_the_coordinator_off_it(lock_dir: Path) -> None:
    """Our lock is filelock's: whoever holds a FileLock on domain-N.lock holds N."""
    first, second = free_ids(2)
    coordinator = DomainCoordinator(lock_dir, (first, second))
    with filelock.FileLock(str(lock_path(lock_dir, first)), timeout=0):
        reservation = coordinator.try_reserve(["test"])
        assert reservation is not None
        try:
            assert reservation.domain_id == second
        finally:
            reservation.release()


def test_a_held_reservation_keeps_a_filelock_out(lock_dir: Path) -> None:
    (domain_id,) = free_ids(1)
    reservation = DomainCoordinator(lock_dir, (domain_id,)).try_reserve(["test"])
    assert reservation is not None
    try:
        with pytest.raises(filelock.Timeout):
            filelock.FileLock(str(lock_path(lock_dir, domain_id)), timeout=0).acquire()
    finally:
        reservation.release()
    with filelock.FileLock(str(lock_path(lock_dir, domain_id)), timeout=0):
        pass  # released: filelock gets it at once

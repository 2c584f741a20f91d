"""``cli``: result paths that are not regular files, through ``run``, the RUNNER and ``normalise``.

A rename replaces whatever is at the path: as root, `--junit-xml /dev/null` once replaced
the machine's /dev/null. The null device discards the result; any other device node, FIFO
or socket (or a symlink to one) is refused before anything runs, and checked again when
the result is written; ``normalise -o`` keeps the same rule. The control: a regular file
at the path is replaced atomically. Real FIFOs and (as root) real device nodes.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import MODES, run_cli, the_error_line, through
from helpers.results import load_result


def _special_at(kind: str, folder: Path) -> Path:
    """A FIFO at ``folder/r.xml``, or a symlink there to one."""
    fifo = folder / ("r.xml" if kind == "fifo" else "fifo")
    os.mkfifo(fifo)
    if kind == "fifo":
        return fifo
    link = folder / "r.xml"
    link.symlink_to(fifo)
    return link


@pytest.mark.parametrize("kind", ["fifo", "symlink to a fifo"])
@pytest.mark.parametrize("mode", MODES)
def test_a_fifo_result_path_is_refused_before_anything_runs(
    runner_script: str, env: dict[str, str], lock_dir: Path, tmp_path: Path, mode: str, kind: str
) -> None:
    result = _special_at(kind, tmp_path)
    before = os.lstat(result)
    proc = through(mode, runner_script, env, tmp_path, ["touch", "ran"], result)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    line = the_error_line(proc)
    said = "a symlink to a FIFO" if kind.startswith("symlink") else "a FIFO"
    assert str(result) in line and f"it is {said}" in line, line
    assert "name a regular file" in line, line
    assert not (tmp_path / "ran").exists(), "the test ran"
    assert list(lock_dir.iterdir()) == [], "something was reserved"
    after = os.lstat(result)
    assert (after.st_ino, after.st_mode) == (before.st_ino, before.st_mode)


@pytest.mark.parametrize("mode", MODES)
def test_control_a_regular_result_path_is_replaced_atomically(
    runner_script: str, env: dict[str, str], tmp_path: Path, mode: str
) -> None:
    result = tmp_path / "pkg" / "r.xml"
    result.parent.mkdir()
    result.write_text("a stale result of an earlier run\n")
    before = os.lstat(result)
    proc = through(mode, runner_script, env, tmp_path, ["touch", "ran"], result)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (tmp_path / "ran").exists()
    assert os.lstat(result).st_ino != before.st_ino
    assert load_result(result).only.outcome == "passed"


@pytest.mark.parametrize("mode", MODES)
def test_a_symlink_to_dev_null_as_the_result_path_discards_the_result(
    runner_script: str, env: dict[str, str], tmp_path: Path, mode: str
) -> None:
    """As ``pytest --junit-xml=/dev/null``: the test runs, nothing is written, the link stays."""
    link = tmp_path / "r.xml"
    link.symlink_to(os.devnull)
    proc = through(mode, runner_script, env, tmp_path, ["touch", "ran"], link)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (tmp_path / "ran").exists()
    assert link.is_symlink() and os.readlink(link) == os.devnull
    assert sorted(item.name for item in tmp_path.iterdir()) == ["r.xml", "ran"]


@capabilities.ROOT
@pytest.mark.parametrize("mode", MODES)
def test_a_null_device_node_as_the_result_path_is_kept_and_the_output_file_still_works(
    runner_script: str, env: dict[str, str], tmp_path: Path, mode: str
) -> None:
    """The issue's reproduction: ``mknod $D/null c 1 3; run --junit-xml $D/null -- true``.

    The output goes to a second such node, as --output-file to a device always could.
    """
    null, output = tmp_path / "null", tmp_path / "output"
    for node in (null, output):
        os.mknod(node, 0o666 | stat.S_IFCHR, os.makedev(1, 3))
    if mode == "shell":
        args = ["--junit-xml", str(null), "--output-file", str(output), "--", "touch", "ran"]
        proc = run_cli(["run", *args], env, cwd=tmp_path)
    else:
        options = ["--output-file", str(output)]
        proc = through(mode, runner_script, env, tmp_path, ["touch", "ran"], null, options)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (tmp_path / "ran").exists()
    for node in (null, output):
        found = os.lstat(node)
        assert stat.S_ISCHR(found.st_mode) and found.st_rdev == os.makedev(1, 3), node
    assert sorted(item.name for item in tmp_path.iterdir()) == ["null", "output", "ran"]


@pytest.mark.parametrize("left", ["fifo", "regular file"])
def test_a_fifo_the_test_leaves_at_the_result_path_is_not_replaced_at_write_time(
    runner_script: str, env: dict[str, str], tmp_path: Path, left: str
) -> None:
    """Checked again when the result is written: the path became a FIFO while the test ran.

    --generate-result-on-success writes over the test's own file (run_test.py's rule), so
    nothing is kept aside: the FIFO stays, and the run fails saying why. The control: a
    regular file the test leaves there is replaced by the passed result. The test finds
    the path itself (no argument names it), so it writes there, not beside.
    """
    result = tmp_path / "pkg" / "r.xml"
    make = 'mkfifo "$1/r.xml"' if left == "fifo" else 'echo left > "$1/r.xml"'
    command = ["sh", "-c", f'rm -f "$1/r.xml"; {make}', "t", str(result.parent)]
    proc = through("runner", runner_script, env, tmp_path, command, result)
    if left == "fifo":
        assert proc.returncode == 1, proc.stdout + proc.stderr
        assert f"cannot write result file {result}: it is a FIFO" in proc.stderr, proc.stderr
        assert stat.S_ISFIFO(os.lstat(result).st_mode)
    else:
        assert proc.returncode == 0, proc.stdout + proc.stderr
        assert load_result(result).only.outcome == "passed"


SOURCE = '<testsuite name="s" tests="1"><testcase classname="c" name="t"/></testsuite>'


@pytest.mark.parametrize("output", ["fifo", "symlink to /dev/null", "regular file"])
def test_normalise_never_replaces_a_fifo_and_discards_into_dev_null(
    env: dict[str, str], tmp_path: Path, output: str
) -> None:
    source = tmp_path / "in.xml"
    source.write_text(SOURCE)
    target = tmp_path / "out.xml"
    if output == "fifo":
        os.mkfifo(target)
    elif output == "regular file":
        target.write_text("stale\n")
    else:
        target.symlink_to(os.devnull)
    before = os.lstat(target)
    proc = run_cli(["normalise", "--package-name", "p", str(source), "-o", str(target)], env)
    if output == "fifo":
        assert proc.returncode == 2, proc.stdout + proc.stderr
        line = the_error_line(proc)
        assert str(target) in line and "it is a FIFO" in line, line
        assert stat.S_ISFIFO(os.lstat(target).st_mode)
    elif output == "regular file":
        assert proc.returncode == 0, proc.stdout + proc.stderr
        assert os.lstat(target).st_ino != before.st_ino
        assert load_result(target).only.outcome == "passed"
    else:
        assert (proc.returncode, proc.stdout, proc.stderr) == (0, "", "")
        assert target.is_symlink() and os.readlink(target) == os.devnull

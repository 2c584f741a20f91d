"""``xunit.result_file``: one test's result file through its life, never lost and never lying.

Stale files of an earlier run go first; then the placeholder (what a killed runner
leaves); then the final word: the runner's own result, or the test's own file made
canonical with the original kept beside it as ``.orig`` (linked there before the
canonical file replaces it in one rename, so a kill at any instant leaves a file at
the path). When the final write fails, the test's own file is kept (beside as ``.orig``,
or, written in place, left there), and the run exits 1 with the error on stderr;
directories a test leaves where its result or our ``.orig`` go still give a result saying
so. The stand-in that overwrites the placeholder is ``test_placeholder``'s. In a rerun
series the file on disk never shows an attempt without the failures before it, and the
test's own file of each attempt is kept.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import CLI
from helpers.tiny_disk import fill, run_on_tiny_disk
from helpers.xunit import (
    NO_SPACE,
    OWN,
    argv_for,
    only_error,
    properties_of,
    valid_result,
)
from lxml import etree

from ros_isolated_test.atomic_file import NotReplaceableError
from ros_isolated_test.xunit.model import Outcome
from ros_isolated_test.xunit.placeholder import NOT_WRITTEN
from ros_isolated_test.xunit.result_file import ResultFile


def _result_file(path: Path | None) -> ResultFile:
    return ResultFile(path, ["talker", "--fast"], "pkg", "t")


# --- the steps, on their own -------------------------------------------------------------------


def test_prepare_clears_what_an_earlier_run_left_and_makes_the_folder(tmp_path: Path) -> None:
    path = tmp_path / "results" / "t.xml"
    path.parent.mkdir()
    stale = [path, path.with_name("t.xml.orig")]
    stale += [path.with_name(f"t.xml.attempt{number}.orig") for number in (1, 2)]
    for leftover in stale:
        leftover.write_text("stale")
    other = path.with_name("t.xml.attempt4.orig")  # after a gap: not of the same series
    other.write_text("not ours")
    _result_file(path).prepare()
    assert [leftover.exists() for leftover in stale] == [False] * 4
    assert other.exists()
    fresh = tmp_path / "new" / "deeper" / "t.xml"
    _result_file(fresh).prepare()
    assert fresh.parent.is_dir() and not fresh.exists()


def test_prepare_refuses_what_a_write_would_replace_and_discards_for_the_null_device(
    tmp_path: Path,
) -> None:
    fifo = tmp_path / "fifo.xml"
    os.mkfifo(fifo)
    with pytest.raises(NotReplaceableError):
        _result_file(fifo).prepare()
    assert fifo.exists()
    folder = tmp_path / "folder.xml"
    folder.mkdir()
    with pytest.raises(IsADirectoryError):
        _result_file(folder).prepare()
    discarded = _result_file(Path(os.devnull))
    discarded.prepare()
    assert discarded.path is None
    assert discarded.write([discarded.case(Outcome.PASSED)]) is None
    assert Path(os.devnull).is_char_device()


def test_without_a_path_every_step_is_a_no_op() -> None:
    nothing = _result_file(None)
    nothing.prepare()
    assert nothing.write_placeholder() and nothing.untouched()
    assert nothing.write([nothing.case(Outcome.FAILURE, "m")]) is None
    assert nothing.original is None


def test_the_placeholder_then_the_final_word_of_the_runner(tmp_path: Path) -> None:
    path = tmp_path / "t.xml"
    result = _result_file(path)
    result.prepare()
    assert result.write_placeholder()
    assert result.untouched()
    assert "most likely timed out" in only_error(valid_result(path))
    rendered = result.write([result.case(Outcome.PASSED, duration=1.5)], 1.5)
    assert rendered is not None and not rendered.failed
    root = valid_result(path)
    [case] = root.iter("testcase")
    assert (case.get("classname"), case.get("name"), case.get("time")) == ("pkg.t", "t", "1.500")
    assert properties_of(root)["command"] == "talker --fast"
    assert result.untouched() is False  # the final word is not the placeholder


def test_the_tests_own_file_is_adopted_and_kept_beside_the_canonical_one(tmp_path: Path) -> None:
    path = tmp_path / "t.xml"
    result = _result_file(path)
    result.prepare()
    result.write_placeholder()
    path.write_bytes(OWN)  # what the test wrote
    assert not result.untouched()
    cases = result.adopt()
    assert result.original is not None
    assert result.original.read_bytes() == OWN
    assert path.read_bytes() == OWN, "until the canonical file replaces it, the test's stays"
    rendered = result.write(cases, checked=True)
    assert rendered is not None and not rendered.failed
    root = valid_result(path)
    assert [node.get("name") for node in root.iter("testcase")] == ["its_case"]
    assert properties_of(root)["original_result_file"] == "t.xml.orig"
    assert result.original.read_bytes() == OWN


# --- the disk fills up while the test runs ---------------------------------------------------


@capabilities.MOUNT_NAMESPACE
@pytest.mark.parametrize("where", ["beside", "in place"])
def test_the_tests_own_result_file_stays_when_its_normalised_form_cannot_be_written(
    runner_script: str, env: dict[str, str], tmp_path: Path, where: str
) -> None:
    """A failed write must not lose the test's own file, nor leave a pass it did not make.

    Written beside (its argument names the result path), the file is kept as ``.orig``
    and the placeholder gives way to the stand-in naming it. Written in place (the test
    finds the path itself), the test's own file is left there, as it wrote it.
    """
    disk = tmp_path / "disk"
    result = disk / "pkg" / "t.xml"
    kept = tmp_path / "kept.xml"
    original = tmp_path / "kept.orig"
    source = tmp_path / "own.xml"
    source.write_bytes(OWN)
    target = '"$0"' if where == "beside" else '"$0/t.xml"'
    script = f"cp {source} {target}; {fill(disk)}"
    named = result if where == "beside" else result.parent
    argv = argv_for("runner", runner_script, result, "sh", "-c", script, str(named))
    copy = f"cp {result} {kept}; cp {result}.orig {original} || true"

    done = run_on_tiny_disk(disk, argv, env, then=copy)

    stderr = done.stderr.decode()
    assert done.returncode == 1, stderr
    assert f"cannot write result file {result}: {NO_SPACE}" in stderr
    if where == "in place":
        assert kept.read_bytes() == OWN, "the test's own result file is gone"
        return
    assert original.read_bytes() == OWN, "the test's own result file is gone"
    root = valid_result(kept)
    assert NOT_WRITTEN in only_error(root)
    assert properties_of(root)["original_result_file"] == "t.xml.orig"


@capabilities.MOUNT_NAMESPACE
def test_a_result_path_on_a_disk_full_before_the_run_is_a_one_line_error_naming_the_fix(
    env: dict[str, str], tmp_path: Path
) -> None:
    """Nothing runs when not even the placeholder fits: no result could say what happened."""
    disk = tmp_path / "disk"
    result = disk / "t.xml"
    ran = tmp_path / "ran"
    argv = ["sh", "-c", f'{fill(disk)}; exec "$@"', "sh"]
    argv += [CLI, "run", "--junit-xml", str(result), "--", "touch", str(ran)]

    done = run_on_tiny_disk(disk, argv, env)

    assert done.returncode == 2, done.stderr
    assert not ran.exists(), "the test ran although its result could not be recorded"
    errors = [line for line in done.stderr.decode().splitlines() if "error:" in line]
    assert len(errors) == 1, done.stderr
    assert str(result) in errors[0]
    assert NO_SPACE in errors[0]
    assert "free space" in errors[0]


# --- the test leaves directories where its result or our .orig go ---------------------------


@pytest.mark.parametrize(
    "left",
    ["result dir, .orig dir", "result dir", "result file, .orig dir", "result file, .orig file"],
)
def test_directories_left_at_the_result_path_or_orig_still_give_a_result_saying_so(
    runner_script: str, env: dict[str, str], tmp_path: Path, left: str
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    original = result.with_name("t.xml.orig")
    own = tmp_path / "own.xml"
    own.write_bytes(OWN)
    steps = []
    if left.startswith("result dir"):
        steps.append(f"mkdir -p {result}/inside")
    else:
        steps.append(f"cp {own} {result}")
    if left.endswith(".orig dir"):
        steps.append(f"mkdir -p {original}/inside")
    elif left.endswith(".orig file"):
        steps.append(f"echo planted > {original}")
    script = f"rm -f {result}; " + "; ".join(steps)
    argv = argv_for("runner", runner_script, result, "sh", "-c", script)

    done = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=120, check=False)

    assert "Traceback" not in done.stderr, done.stderr
    root = valid_result(result)
    props = properties_of(root)
    assert props["original_result_file"] == "t.xml.orig"
    if left.startswith("result dir"):
        assert done.returncode == 1, done.stdout + done.stderr
        assert "directory" in only_error(root)
        assert (original / "inside").is_dir(), "the test's directory was kept as .orig"
    else:
        assert done.returncode == 0, done.stdout + done.stderr
        names = [case.get("name") for case in root.iter("testcase")]
        assert names == ["its_case"]
        assert original.read_bytes() == OWN


# --- no instant without a file at the result path ---------------------------------------------


_BIG = """
import sys
with open(sys.argv[1], "w") as out:
    out.write('<?xml version="1.0"?>\\n<testsuite name="big" tests="100000">\\n')
    for index in range(100000):
        out.write('<testcase classname="c" name="t%d"/>\\n' % index)
    out.write("</testsuite>\\n")
"""


def test_a_runner_killed_while_adopting_the_tests_file_leaves_a_file_at_the_path(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    """SIGKILL (nothing can be done then) as soon as the original is kept aside."""
    result = tmp_path / "pkg" / "big.xml"
    original = result.with_name("big.xml.orig")
    script = tmp_path / "big.py"
    script.write_text(_BIG)
    argv = argv_for("runner", runner_script, result, sys.executable, str(script), str(result))
    runner = subprocess.Popen(argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        while not os.path.lexists(original):
            assert runner.poll() is None, "the runner ended before it adopted the result"
            time.sleep(0.001)
        runner.kill()
        runner.wait(timeout=120)
    finally:
        if runner.poll() is None:
            runner.kill()
            runner.wait()
    assert runner.returncode == -signal.SIGKILL, "it ended before the kill"
    assert result.is_file(), "the result path was left empty"
    kept = result.read_bytes()
    assert kept == original.read_bytes() or b"<testsuites" in kept[:200]


# --- a rerun series, driven as the rerun loop drives it --------------------------------------


def test_a_rerun_result_is_never_on_disk_without_the_earlier_attempts(tmp_path: Path) -> None:
    """The rerun's own result is written merged: a kill before the final merge loses nothing.

    The runner's result file driven as the rerun loop drives it, on a real file: after
    attempt 2 is written (the last write a kill before the final merge leaves), attempt
    1's failure is on disk beside it, while its own word (passed) still sets the exit code.
    """
    path = tmp_path / "pkg" / "t.xml"
    result = ResultFile(path, ("t",), "pkg", "t")
    result.prepare()
    assert result.write_placeholder()
    result.write([result.case(Outcome.FAILURE, "attempt one failed")])
    assert result.last_suite is not None
    result.end_attempt()
    assert result.next_attempt(1, {})
    assert "attempt one failed" in path.read_text()  # the placeholder holds it (the control)
    rendered = result.write([result.case(Outcome.PASSED)])
    assert rendered is not None and not rendered.failed  # attempt 2's own word: it passed
    root = valid_result(path)
    (case,) = root.iter("testcase")
    (flaky,) = case.findall("flakyFailure")
    assert flaky.get("message") == "attempt one failed", etree.tostring(root)
    assert properties_of(root)["attempts"] == "2"
    assert result.last_suite is not None and len(result.last_suite.cases) == 1


def test_an_attempts_file_that_cannot_be_kept_is_one_line_naming_the_fix(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Something in the way of ``.attempt1.orig`` (a folder the test made): say what to do."""
    path = tmp_path / "t.xml"

    def attempt_one(result: ResultFile) -> None:
        result.prepare()
        assert result.write_placeholder()
        path.write_text(
            '<testsuite name="s" tests="1"><testcase classname="s" name="c">'
            '<failure message="own failure"/></testcase></testsuite>'
        )
        result.write(result.adopt(), checked=True)

    # The control: nothing in the way, attempt 1's own file is kept, nothing said.
    kept = ResultFile(path, ("t",), "pkg", "t")
    attempt_one(kept)
    capsys.readouterr()
    kept.end_attempt()
    assert kept.next_attempt(1, {})
    assert b"own failure" in path.with_name("t.xml.attempt1.orig").read_bytes()
    assert capsys.readouterr().err == ""
    blocked = ResultFile(path, ("t",), "pkg", "t")
    attempt_one(blocked)
    (path.with_name("t.xml.attempt1.orig") / "made by the test").mkdir(parents=True)
    capsys.readouterr()
    blocked.end_attempt()
    assert blocked.next_attempt(1, {})
    (line,) = capsys.readouterr().err.splitlines()
    assert "t.xml.attempt1.orig" in line and "remove what is in the way" in line, line

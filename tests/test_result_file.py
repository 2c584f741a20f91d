"""The result file never lies when the disk fills up: it says the result could not be written.

The placeholder says "the test most likely timed out" (what ctest leaves when it kills
the runner). When the final write fails, that placeholder is overwritten in place by a
valid result saying the write failed, why, and how the test ended; the test's own file,
moved aside to be normalised, goes back; and the run exits 1 with the error on stderr.
Real full file systems: a tmpfs in a private mount namespace, or a file size limit
(RLIMIT_FSIZE), which needs no root.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import CLI
from helpers.tiny_disk import fill, run_on_tiny_disk
from lxml import etree

from ros_isolated_test.xunit import validate
from ros_isolated_test.xunit.result_file import NOT_WRITTEN

TIMED_OUT = "timed out"
NO_SPACE = "No space left on device"


def valid_result(path: Path) -> etree._Element:
    """The parsed result file, failing the test unless it matches schemas/junit.xsd."""
    assert path.is_file(), f"no result file at {path}"
    root = etree.parse(str(path), etree.XMLParser(resolve_entities=False)).getroot()
    assert validate.problems(root) == [], f"{path} does not match schemas/junit.xsd"
    assert root.tag == "testsuites"
    return root


def only_error(root: etree._Element) -> str:
    """The message and text of the one case's <error>, which it must have."""
    cases = root.findall("testsuite/testcase")
    assert len(cases) == 1
    error = cases[0].find("error")
    assert error is not None, etree.tostring(cases[0]).decode()
    return f"{error.get('message')}\n{error.text}"


def properties(root: etree._Element) -> dict[str, str]:
    return {p.get("name", ""): p.get("value", "") for p in root.iter("property")}


def argv_for(mode: str, runner_script: str, result: Path, *command: str) -> list[str]:
    if mode == "shell":
        return [CLI, "run", "--junit-xml", str(result), "--", *command]
    return [sys.executable, "-u", runner_script, str(result), "--command", *command]


# --- the disk fills up while the test runs ---------------------------------------------------


@capabilities.MOUNT_NAMESPACE
@pytest.mark.parametrize("mode", ["shell", "runner"])
def test_a_final_write_that_fails_leaves_a_result_saying_so_not_the_placeholder(
    mode: str, runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    disk = tmp_path / "disk"
    result = disk / "pkg" / "t.xml"
    kept = tmp_path / "kept.xml"
    argv = argv_for(mode, runner_script, result, "sh", "-c", fill(disk))
    if mode == "runner":
        argv.insert(argv.index("--command"), "--generate-result-on-success")

    done = run_on_tiny_disk(disk, argv, env, then=f"cp {result} {kept}")

    stderr = done.stderr.decode()
    assert done.returncode == 1, stderr
    assert f"cannot write result file {result}: {NO_SPACE}" in stderr
    root = valid_result(kept)
    said = only_error(root)
    assert TIMED_OUT not in kept.read_text(), "the placeholder was left saying timed out"
    assert NOT_WRITTEN in said
    assert NO_SPACE in said
    assert "The test exited with code 0." in said
    assert properties(root)["exit_code"] == "0"
    assert NO_SPACE in properties(root)["result_write_error"]


@capabilities.MOUNT_NAMESPACE
def test_the_tests_own_result_file_stays_when_its_normalised_form_cannot_be_written(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    """It is moved aside to be normalised: a failed write must not leave nothing behind."""
    disk = tmp_path / "disk"
    result = disk / "pkg" / "t.xml"
    kept = tmp_path / "kept.xml"
    own = (
        b'<?xml version="1.0"?>\n<testsuite name="own" tests="1" failures="0">'
        b'<testcase classname="own" name="its_case"/></testsuite>\n'
    )
    source = tmp_path / "own.xml"
    source.write_bytes(own)
    script = f'cp {source} "$0"; {fill(disk)}'
    argv = argv_for("runner", runner_script, result, "sh", "-c", script, str(result))

    done = run_on_tiny_disk(disk, argv, env, then=f"cp {result} {kept}")

    stderr = done.stderr.decode()
    assert done.returncode == 1, stderr
    assert f"cannot write result file {result}: {NO_SPACE}" in stderr
    assert kept.read_bytes() == own, "the test's own result file is gone"


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


@capabilities.MOUNT_NAMESPACE
def test_control_with_room_to_spare_the_final_result_is_written(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    """The same run on a disk with room: the stand-in appears only when the write fails."""
    disk = tmp_path / "disk"
    result = disk / "pkg" / "t.xml"
    kept = tmp_path / "kept.xml"
    argv = argv_for("runner", runner_script, result, "true")
    argv.insert(argv.index("--command"), "--generate-result-on-success")

    done = run_on_tiny_disk(disk, argv, env, then=f"cp {result} {kept}")

    assert done.returncode == 0, done.stderr.decode()
    text = kept.read_text()
    valid_result(kept)
    assert NOT_WRITTEN not in text
    assert 'tests="1" failures="0" errors="0"' in text


# --- the stand-in always fits the placeholder (a file size limit: no root needed) ------------

_LIMITED = textwrap.dedent(
    """
    import resource, signal, sys
    from pathlib import Path
    from ros_isolated_test.xunit.model import Outcome
    from ros_isolated_test.xunit.result_file import ResultFile, test_name_of

    path, long = Path(sys.argv[1]), int(sys.argv[2])
    name = "n" * long
    command = ("x" * long, "&<>" * long)
    result = ResultFile(path, command, path.parent.name, test_name_of(path))
    result.prepare()
    result.write_placeholder()
    assert result.placeholder is not None and result.write_error is None
    # Beyond this size every write fails (EFBIG), as on a disk that filled up.
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (len(result.placeholder), resource.RLIM_INFINITY))
    result.properties["exit"] = "exited with code 3 " + "&" * long
    result.properties["exit_code"] = "3"
    message = "<&'\\"> assertion failed " * long
    cases = [result.case(Outcome.FAILURE, message, 1.5)]
    cases[0].name = name
    result.write(cases, 1.5, output="o" * 100_000)
    print(result.write_error)
    """
)


@pytest.mark.parametrize("long", [1, 300, 5000], ids=["short", "long", "huge"])
def test_the_stand_in_fits_the_placeholder_whatever_the_names_and_messages(
    long: int, env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    done = subprocess.run(
        [sys.executable, "-c", _LIMITED, str(result), str(long)],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert "File too large" in done.stdout, "the final write did not fail"
    root = valid_result(result)
    said = only_error(root)
    assert TIMED_OUT not in result.read_text()
    assert NOT_WRITTEN in said
    assert "File too large" in said
    assert "cannot write result file" in done.stderr


# --- the test leaves directories where its result or our .orig go ---------------------------

OWN = (
    b'<?xml version="1.0"?>\n<testsuite name="own" tests="1" failures="0">'
    b'<testcase classname="own" name="its_case"/></testsuite>\n'
)


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
    props = properties(root)
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

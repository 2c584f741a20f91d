"""The RUNNER script when no Python can import ros-isolated-test: a result file all the same.

ctest runs the script with the Python CMake found. When neither that one nor the one of
the ``ros-isolated-test`` command on PATH can import the package, nothing of the package
can write the result file, so ``without_package.py`` beside the script writes it, importing
nothing: one
error case saying why and how to fix it, valid against schemas/junit.xsd, stamped in
local time, beside the one-line error and exit code 2. Run for real with the system
python3.11, which has not got the package, from an environment without the venv.
(What the script hands its arguments to, ``args``, is tested in test_args.py.)
"""

from __future__ import annotations

import datetime
import importlib.util
import os
import shlex
import subprocess
from pathlib import Path
from types import ModuleType

import pytest
from helpers import capabilities
from helpers.canonical import check_canonical
from helpers.commands import REPO, ament
from lxml import etree

SCHEMA = REPO / "ros_isolated_test" / "schemas" / "junit.xsd"


def _bare_python() -> str:
    python = capabilities.bare_python()
    assert python is not None
    return python


def _bare_run(
    python: str,
    runner_script: str,
    args: list[str],
    path: Path,
    lock_dir: Path,
    cwd: Path,
    *settings: str,
) -> subprocess.CompletedProcess[str]:
    """The script as ctest runs it, with ``python``, only ``path`` on PATH and ``settings``."""
    return subprocess.run(
        [
            "/usr/bin/env",
            "-i",
            f"PATH={path}",
            f"ROS_ISOLATED_TEST_LOCK_DIR={lock_dir}",
            *settings,
            python,
            "-u",
            runner_script,
            *args,
        ],
        capture_output=True,
        check=False,
        text=True,
        timeout=60,
        cwd=cwd,
    )


def _valid_against_the_schema(path: Path) -> etree._Element:
    root = etree.parse(str(path), etree.XMLParser(resolve_entities=False)).getroot()
    schema = etree.XMLSchema(etree.parse(str(SCHEMA)))
    assert schema.validate(root), schema.error_log
    return root


def _cli_of(python: str, folder: Path) -> Path:
    """A ``ros-isolated-test`` command whose Python (a wrapper that leaves a mark) is ``python``.

    The script re-executes itself with it; that Python cannot import the package either.
    """
    folder.mkdir()
    wrapper = folder / "python-of-the-cli"
    mark = folder / "re-executed"
    wrapper.write_text(
        f'#!/bin/sh\n: > {shlex.quote(str(mark))}\nexec {shlex.quote(python)} "$@"\n'
    )
    wrapper.chmod(0o755)
    cli = folder / "ros-isolated-test"
    cli.write_text(f"#!{wrapper}\nraise SystemExit('never run: only its first line is read')\n")
    cli.chmod(0o755)
    return mark


@capabilities.BARE_PYTHON
@pytest.mark.parametrize("cli", ["no-cli-on-path", "cli-that-cannot-import-it-either"])
def test_without_the_package_the_result_file_says_why_and_how_to_fix_it(
    runner_script: str, lock_dir: Path, tmp_path: Path, cli: str
) -> None:
    # An odd name for the Python: its path is in the message, so the markup is escaped.
    python = tmp_path / 'py <&"odd">'
    python.symlink_to(_bare_python())
    path = tmp_path / "bin"
    mark = _cli_of(str(python), path) if cli != "no-cli-on-path" else None
    path.mkdir(exist_ok=True)
    result = tmp_path / "build" / "test_results" / "pkg" / "t.xml"
    args = [str(result), "--package-name", "pkg", "--command", "touch", "ran"]
    proc = _bare_run(str(python), runner_script, args, path, lock_dir, tmp_path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert not (tmp_path / "ran").exists()
    lines = proc.stderr.splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("run_test_isolated.py: error: cannot import ros-isolated-test")
    assert "Python3_EXECUTABLE" in lines[0] and str(python) in lines[0]
    if mark is not None:
        assert mark.exists(), "the script did not try the Python of the command on PATH"
    _valid_against_the_schema(result)
    canonical = check_canonical(result, "pkg", "t")
    case = canonical.summary.only
    assert (case.classname, case.name, case.outcome) == ("pkg.t", "t", "error")
    assert case.message == lines[0].removeprefix("run_test_isolated.py: error: ")
    assert case.text == case.message
    assert canonical.properties["exit"] == "not run"
    assert canonical.properties["command"] == "touch ran"
    assert not [item for item in result.parent.iterdir() if item != result]  # no temp file


def test_control_with_a_python_that_imports_it_the_test_runs(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    """The same invocation with this suite's Python runs the test and writes its result."""
    result = tmp_path / "build" / "test_results" / "pkg" / "t.xml"
    proc = ament(
        runner_script,
        result,
        ("touch", "ran"),
        env,
        "--generate-result-on-success",
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (tmp_path / "ran").exists()
    assert check_canonical(result, "pkg", "t").summary.only.outcome == "passed"


@capabilities.BARE_PYTHON
def test_a_result_path_that_cannot_be_written_leaves_the_error_line(
    runner_script: str, lock_dir: Path, tmp_path: Path
) -> None:
    result = tmp_path / "t.xml"
    (result / "inside").mkdir(parents=True)  # a folder with something in it: no replace
    empty = tmp_path / "bin"
    empty.mkdir()
    args = [str(result), "--command", "touch", "ran"]
    proc = _bare_run(_bare_python(), runner_script, args, empty, lock_dir, tmp_path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stderr
    assert len(proc.stderr.splitlines()) == 1, proc.stderr
    assert sorted(item.name for item in tmp_path.iterdir()) == ["bin", "t.xml"]


@capabilities.BARE_PYTHON
@pytest.mark.parametrize("kind", ["fifo", "symlink to a fifo", "symlink to /dev/null"])
def test_a_fifo_or_dev_null_at_the_result_path_is_never_replaced(
    runner_script: str, lock_dir: Path, tmp_path: Path, kind: str
) -> None:
    """Without the package too: the error line only, and the path left as it was.

    The control is the test above: a regular path gets the result saying why.
    """
    result = tmp_path / "t.xml"
    if kind == "symlink to /dev/null":
        result.symlink_to(os.devnull)
    elif kind == "fifo":
        os.mkfifo(result)
    else:
        os.mkfifo(tmp_path / "fifo")
        result.symlink_to(tmp_path / "fifo")
    before = os.lstat(result)
    empty = tmp_path / "bin"
    empty.mkdir()
    args = [str(result), "--command", "touch", "ran"]
    proc = _bare_run(_bare_python(), runner_script, args, empty, lock_dir, tmp_path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert len(proc.stderr.splitlines()) == 1, proc.stderr
    after = os.lstat(result)
    assert (after.st_ino, after.st_mode) == (before.st_ino, before.st_mode)
    names = sorted(item.name for item in tmp_path.iterdir())
    assert names == sorted(["bin", "t.xml", *(["fifo"] if kind == "symlink to a fifo" else [])])


def _imported(python: str, argv: list[str], cwd: Path) -> set[str]:
    """The modules ``python -X importtime ARGV`` imported, in an empty environment."""
    proc = subprocess.run(
        ["/usr/bin/env", "-i", "PATH=/nonexistent", python, "-X", "importtime", *argv],
        capture_output=True,
        check=False,
        text=True,
        timeout=60,
        cwd=cwd,
    )
    return {
        line.rsplit("|", 1)[1].strip()
        for line in proc.stderr.splitlines()
        if line.startswith("import time:") and "|" in line
    }


@capabilities.BARE_PYTHON
def test_writing_that_result_imports_nothing(runner_script: str, tmp_path: Path) -> None:
    """The same modules load whether the script writes the result or has no path to write.

    (``-X importtime`` lists the failed import of the package too: compared, not listed.)
    """
    python = _bare_python()
    result = tmp_path / "t.xml"
    loaded = _imported(python, ["-u", runner_script, str(result), "--command", "true"], tmp_path)
    assert result.is_file()
    without = _imported(python, ["-u", runner_script], tmp_path)
    assert "shutil" in without  # control: the measurement sees what finding the CLI loads
    assert loaded - without == set()


# --- the document itself: escaped, stamped, valid whatever the names hold -------------------


def _script(runner_script: str) -> ModuleType:
    """The fallback beside the RUNNER script, as a module: its writer, with odd names."""
    fallback = Path(runner_script).with_name("without_package.py")
    spec = importlib.util.spec_from_file_location("runner_fallback_under_test", fallback)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize(
    ("given", "shown"),
    [
        (("pkg.t", "t", "plain"), ("pkg.t", "t", "plain")),
        (
            ("a&b<c>\"d'", "\x01\x1b[31m", "tab\there\nline \udce9 bytes \ufffe"),
            ("a&b<c>\"d'", "\\x01\\x1b[31m", "tab\\x09here\\x0aline \\udce9 bytes \\ufffe"),
        ),
        (("  ", "\x00", " \t "), ("test", "\\x00", "")),
    ],
)
def test_the_document_is_valid_whatever_the_names_hold(
    runner_script: str,
    tmp_path: Path,
    given: tuple[str, str, str],
    shown: tuple[str, str, str],
) -> None:
    """Markup escaped, what XML forbids shown as ``\\xNN``, blank names made ``test``."""
    path = tmp_path / "t.xml"
    command = ["echo", "<&>", "\udcff"]
    suite, test, message = given
    stamp = "2026-01-02T03:04:05"
    document = _script(runner_script)._not_run_document(suite, test, command, message, stamp)
    path.write_bytes(document)
    root = _valid_against_the_schema(path)
    case = root.find("testsuite/testcase")
    assert case is not None
    error = case.find("error")
    assert error is not None
    assert (case.get("classname"), case.get("name"), error.get("message")) == shown
    assert (error.text or "") == shown[2]
    assert root.findall("testsuite/properties/property")[0].get("value") == "echo <&> \\udcff"


#: A zone 14 hours east of UTC (POSIX TZ, no zone database needed): no machine's own.
FAR_EAST = "XYZ-14"


def _far_east_now() -> str:
    zone = datetime.timezone(datetime.timedelta(hours=14))
    return datetime.datetime.now(zone).strftime("%Y-%m-%dT%H:%M:%S")


@capabilities.BARE_PYTHON
def test_the_stamp_is_local_time_as_in_every_other_result(
    runner_script: str, lock_dir: Path, tmp_path: Path
) -> None:
    result = tmp_path / "t.xml"
    empty = tmp_path / "bin"
    empty.mkdir()
    args = [str(result), "--command", "true"]
    before = _far_east_now()
    proc = _bare_run(
        _bare_python(), runner_script, args, empty, lock_dir, tmp_path, f"TZ={FAR_EAST}"
    )
    after = _far_east_now()
    assert proc.returncode == 2, proc.stdout + proc.stderr
    suite = _valid_against_the_schema(result).find("testsuite")
    assert suite is not None
    stamp = suite.get("timestamp", "")
    # The control: UTC now lies 14 hours outside that window, so the zone was used.
    utc = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%S")
    assert not before <= utc <= after
    assert before <= stamp <= after, (before, stamp, after)

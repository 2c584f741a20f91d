"""``private_shm``: which of a test's paths its private /dev/shm would hide from it.

On real folders in the host's /dev/shm (made per test, removed after), each beside its
control: a working directory there (or /dev/shm itself) and not; a command, an argument
(whole, after ``=`` or ``:``, through a symlink) in a folder there, and a new name in
/dev/shm itself (the test's own to make); an environment entry there, one that does not
exist, /dev/shm itself (``TMPDIR``) and the shell's ``PWD``; the result file when the
command names it and when it does not. What the runner does with the answer is in
test_environment.py and, end to end, tests/e2e/test_namespace_boundary.py.
"""

from __future__ import annotations

import shutil
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

from ros_isolated_test.runner.private_shm import cause, hidden

SHM = Path("/dev/shm")


@pytest.fixture
def folder() -> Iterator[Path]:
    """A folder in the host's /dev/shm holding ``data.txt``, removed after."""
    made = SHM / f"rit-unit-{uuid.uuid4().hex[:12]}"
    made.mkdir()
    (made / "data.txt").write_text("data")
    try:
        yield made
    finally:
        shutil.rmtree(made, ignore_errors=True)


def test_a_working_directory_in_the_hosts_dev_shm_is_named(folder: Path, tmp_path: Path) -> None:
    assert hidden(["true"], {}, cwd=str(folder)) == [f"its working directory {folder}"]
    assert hidden(["true"], {}, cwd=str(SHM)) == [f"its working directory {SHM}"]
    assert hidden(["true"], {}, cwd=str(tmp_path)) == []  # the control


def test_a_command_or_argument_that_exists_there_is_named(folder: Path, tmp_path: Path) -> None:
    data = folder / "data.txt"
    (tmp_path / "link").symlink_to(data)
    found = hidden(
        [str(data), f"{data}", f"--data={data}", f"xml:{data}", "link", "-q"],
        {},
        cwd=str(tmp_path),
    )
    assert found == [
        f"its command {data}",
        f"its argument {data}",
        f"its argument {data}",  # after "="
        f"its argument {data}",  # after ":"
        "its argument link",  # a symlink into it
    ]


def test_a_new_name_in_a_folder_there_is_named(folder: Path) -> None:
    """The test would make it in a folder its /dev/shm lacks: ``--out=`` an output file."""
    found = hidden(["sh", "-c", "echo > $0", f"--out={folder}/new/out.txt"], {}, cwd="/")
    assert found == [f"its argument {folder}/new/out.txt"]


def test_control_a_new_name_in_dev_shm_itself_is_the_tests_own_to_make() -> None:
    """A shared-memory segment the test creates: found nowhere, refused nowhere."""
    name = str(SHM / f"rit-unit-segment-{uuid.uuid4().hex}")
    assert hidden(["sh", "-c", "echo > $0", name, f"--segment={name}"], {}, cwd="/") == []


def test_an_environment_entry_there_is_named_but_not_dev_shm_itself_nor_pwd(
    folder: Path,
) -> None:
    env = {
        "PYTHONPATH": f"/usr/lib/python3/dist-packages:{folder}",
        "TMPDIR": "/dev/shm/",
        "PWD": str(folder),
        "OLDPWD": str(folder),
        "GONE": f"{folder}/not-there",
    }
    assert hidden(["true"], env, cwd="/") == [f"the entry {folder} of PYTHONPATH"]
    assert hidden(["true"], {"TMPDIR": "/dev/shm"}, cwd="/") == []  # the control


def test_the_result_file_is_named_only_when_the_command_names_it(folder: Path) -> None:
    """The test writes it there (not seen outside); the runner's own writes are outside."""
    result = folder / "results" / "t.xml"
    result.parent.mkdir()
    named = hidden(["pytest", f"--junit-xml={result}"], {}, result_file=result, cwd="/")
    assert named == [f"its result file {result} (the test writes it)"]
    assert hidden(["pytest"], {}, result_file=result, cwd="/") == []  # the runner writes it


def test_no_dev_shm_on_the_host_hides_nothing(folder: Path) -> None:
    """Where there is no /dev/shm, namespace mode mounts none either."""
    assert hidden([str(folder / "data.txt")], {}, cwd=str(folder), shm="/nonexistent/shm") == []


def test_the_cause_names_three_and_counts_the_rest() -> None:
    assert cause(["a"]) == "a is in the host's /dev/shm, out of its reach"
    assert cause(["a", "b"]) == "a and b are in the host's /dev/shm, out of its reach"
    assert cause(["a", "b", "c", "d", "e"]).startswith("a, b, c and 2 more are in the host's")

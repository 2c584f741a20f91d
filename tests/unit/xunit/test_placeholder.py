"""``xunit.placeholder``: the placeholder never stays behind saying the test timed out.

The placeholder says "the test most likely timed out" (what ctest leaves when it kills
the runner). When the final write fails (a disk that filled up while the test ran),
the placeholder is overwritten where it lies, in blocks it already holds, by a short
valid result saying the write failed, why, and how the test ended: the placeholder is
written with room for it, and the stand-in is cut to fit whatever the names and
messages. Only our own placeholder is ever overwritten. Real full file systems: a tmpfs
in a private mount namespace, or a file size limit (RLIMIT_FSIZE), which needs no root.
"""

from __future__ import annotations

import errno
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import CLI
from helpers.tiny_disk import fill, run_on_tiny_disk
from helpers.xunit import (
    NO_SPACE,
    TIMED_OUT,
    argv_for,
    failed,
    only_error,
    parse,
    passed,
    properties_of,
    suite_of,
    valid_result,
)
from lxml import etree

from ros_isolated_test.xunit import serialise, validate
from ros_isolated_test.xunit.model import Case, Outcome
from ros_isolated_test.xunit.placeholder import (
    NOT_WRITTEN,
    RESERVE_BYTES,
    StandIn,
    holds_exactly,
    overwrite_in_place,
    with_room,
)

ENDED = {"exit": "exited with code 3", "exit_code": "3", "command": "talker --fast"}


def _placeholder() -> bytes:
    runner = Case.saying("pkg.test", "test", Outcome.ERROR, "the test most likely timed out")
    return with_room(serialise.serialize(suite_of([runner])))


def _stand_in(properties: dict[str, str] = ENDED) -> StandIn:
    """The stand-in of a test that ended as ``properties`` say, one of its two cases failed."""
    case = Case.saying("pkg.test", "test", Outcome.ERROR, "")
    reason = f"cannot write result file t.xml: {NO_SPACE}"
    return StandIn(suite_of([case]), NO_SPACE, reason, properties, [passed("b"), failed()])


# --- the placeholder and the stand-in, on their own -----------------------------------------


def test_the_placeholder_is_valid_xml_with_room_to_spare() -> None:
    content = serialise.serialize(suite_of([passed()]))
    placeholder = with_room(content)
    assert placeholder.startswith(content) and placeholder.endswith(b" -->\n")
    assert len(placeholder) >= len(content) + RESERVE_BYTES
    assert validate.problems(parse(placeholder)) == []


def test_the_stand_in_says_the_write_failed_why_and_how_the_test_ended() -> None:
    data = _stand_in().render(len(_placeholder()))
    root = parse(data)
    assert validate.problems(root) == []
    said = only_error(root)
    assert said.startswith(f"{NOT_WRITTEN} ({NO_SPACE}): this short one stands in.")
    assert "The test exited with code 3." in said
    assert "2 test case(s), 1 failed; the first: a: boom" in said
    properties = properties_of(root)
    assert (properties["exit"], properties["exit_code"]) == ("exited with code 3", "3")
    assert NO_SPACE in properties["result_write_error"]
    assert "command" not in properties  # only how the test ended, to keep it short
    unknown = only_error(parse(_stand_in({}).render(len(_placeholder()))))
    assert "How the test ended is not known." in unknown


def test_a_smaller_room_drops_the_properties_then_cuts_the_message_then_refuses() -> None:
    stand_in = _stand_in()
    full = stand_in.render(100_000)
    room = len(full)
    smallest = full
    while True:
        room -= 40
        try:
            data = stand_in.render(room)
        except OSError as error:
            assert error.errno == errno.ENOSPC
            break
        assert len(data) <= room
        assert validate.problems(parse(data)) == []
        assert only_error(parse(data)).startswith(f"{NOT_WRITTEN} ({NO_SPACE})")
        smallest = data
    assert len(smallest) < len(full)
    assert "exit_code" not in properties_of(parse(smallest))
    assert len(only_error(parse(smallest))) < len(only_error(parse(full)))


def test_only_our_own_placeholder_is_told_apart_and_overwritten(tmp_path: Path) -> None:
    placeholder = _placeholder()
    path = tmp_path / "t.xml"
    path.write_bytes(placeholder)
    assert holds_exactly(path, placeholder)
    inode = path.stat().st_ino
    assert overwrite_in_place(path, placeholder, _stand_in())
    assert path.stat().st_ino == inode, "not in place: a new file needs new blocks"
    assert NOT_WRITTEN in only_error(valid_result(path))
    assert TIMED_OUT not in path.read_text()
    assert not holds_exactly(path, placeholder)
    # The test's own file, of the same length or not, is never ours to overwrite.
    for own in (placeholder.replace(b"timed out", b"timed-out"), placeholder + b"\n"):
        path.write_bytes(own)
        assert not holds_exactly(path, placeholder)
        assert not overwrite_in_place(path, placeholder, _stand_in())
        assert path.read_bytes() == own


def test_a_fifo_or_a_link_at_the_path_is_never_opened_as_ours(tmp_path: Path) -> None:
    """A FIFO without a writer would hang an ordinary read; a link would lead elsewhere."""
    placeholder = _placeholder()
    fifo = tmp_path / "fifo.xml"
    os.mkfifo(fifo)
    assert not holds_exactly(fifo, placeholder)
    assert not overwrite_in_place(fifo, placeholder, _stand_in())
    target = tmp_path / "target.xml"
    target.write_bytes(placeholder)
    link = tmp_path / "link.xml"
    link.symlink_to(target)
    assert not overwrite_in_place(link, placeholder, _stand_in())
    assert target.read_bytes() == placeholder
    assert not holds_exactly(tmp_path / "missing.xml", placeholder)


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
    assert properties_of(root)["exit_code"] == "0"
    assert NO_SPACE in properties_of(root)["result_write_error"]


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
    from ros_isolated_test.xunit.canonical import test_name_of
    from ros_isolated_test.xunit.result_file import ResultFile

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


# --- a rerun series: the stand-in keeps the earlier attempts' failures ------------------------


_LIMITED_SERIES = textwrap.dedent(
    """
    import resource, signal, sys
    from pathlib import Path
    from ros_isolated_test.xunit.model import Case, Outcome
    from ros_isolated_test.xunit.result_file import ResultFile

    path, long = Path(sys.argv[1]), int(sys.argv[2])
    result = ResultFile(path, ("x" * long,), "pkg", "t")
    result.prepare()
    assert result.write_placeholder()
    result.properties.update({"exit": "exited with code 1", "noise": "&" * long})
    own = Case.saying("pkg.cases", "n" * long, Outcome.FAILURE, "<&> attempt 1 failed " * long)
    assert result.write([result.case(Outcome.FAILURE, "exited 1"), own], 1.0, "o" * 100_000)
    result.end_attempt()
    assert result.next_attempt(1, {"command": "x" * long})
    # Beyond the placeholder's size every write fails (EFBIG), as on a disk that filled up.
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (len(result.placeholder), resource.RLIM_INFINITY))
    result.properties["exit"] = "exited with code 0"
    result.write([result.case(Outcome.PASSED, duration=1.0)], 1.0, output="o" * 100_000)
    print(result.write_error)
    """
)


@pytest.mark.parametrize("long", [1, 5000], ids=["short", "huge"])
def test_in_a_rerun_series_the_stand_in_keeps_the_earlier_attempts_failures(
    long: int, env: dict[str, str], tmp_path: Path
) -> None:
    """Attempt 2's final write fails: the stand-in keeps attempt 1's failures, and fits."""
    result = tmp_path / "pkg" / "t.xml"
    done = subprocess.run(
        [sys.executable, "-c", _LIMITED_SERIES, str(result), str(long)],
        env=env, capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "File too large" in done.stdout, "the final write did not fail"
    root = valid_result(result)
    _keeps_the_earlier_failure(root, "attempt 1 failed")
    # Attempt 1's own case, which attempt 2 did not report: failed, then not run.
    (other,) = [case for case in root.iter("testcase") if case.get("name") != "t"]
    assert other.get("name", "").startswith("n") and other.find("failure") is not None


def _keeps_the_earlier_failure(root: etree._Element, failure: str) -> None:
    """The stand-in's case (an error) carries attempt 1's failure; the file counts 2 attempts."""
    (stand_in,) = [case for case in root.iter("testcase") if case.get("name") == "t"]
    error = stand_in.find("error")
    assert error is not None and NOT_WRITTEN in (error.get("message") or "")
    earlier = etree.tostring(root, encoding="unicode")
    assert stand_in.find("rerunFailure") is not None, etree.tostring(stand_in)
    assert failure in earlier, earlier
    assert properties_of(root)["attempts"] == "2"
    assert TIMED_OUT not in earlier


@capabilities.MOUNT_NAMESPACE
def test_a_rerun_whose_final_write_fails_on_a_full_disk_keeps_attempt_1_in_the_result_path(
    one_id: dict[str, str], tmp_path: Path
) -> None:
    """Attempt 1 fails; attempt 2 fills the disk and passes: its word cannot be written."""
    disk = tmp_path / "disk"
    result = disk / "pkg" / "t.xml"
    kept = tmp_path / "kept.xml"
    script = (
        f'if [ -e "$1" ]; then {fill(disk)}; exit 0; fi; '
        ': > "$1"; echo "failed on $ROS_DOMAIN_ID"; exit 1'
    )
    argv = [CLI, "run", "--rerun-failures", "1", "--junit-xml", str(result),
            "--", "sh", "-c", script, "t", str(tmp_path / "state")]  # fmt: skip

    done = run_on_tiny_disk(disk, argv, one_id, then=f"cp {result} {kept}")

    assert done.returncode == 1, done.stderr.decode()
    _keeps_the_earlier_failure(valid_result(kept), "failed on ")


# --- how long a killed test ran at least ------------------------------------------------------


def _left(folder: Path, written: float, own: float | None, attempts: int = 1) -> dict[str, str]:
    """A placeholder left at ``folder/t.xml`` at ``written``, the test's own file at ``own``."""
    from ros_isolated_test.xunit.kept_files import attempt_original_of
    from ros_isolated_test.xunit.placeholder import stamped

    path = folder / "t.xml"
    path.write_bytes(_placeholder())
    os.utime(path, (written, written))
    if own is not None:
        mine = attempt_original_of(path, attempts)
        mine.write_text("<testsuite/>")
        os.utime(mine, (own, own))
    properties = stamped({"command": "t"}, written)
    if attempts > 1:
        properties["attempts"] = str(attempts)
    return properties


def test_a_killed_test_ran_at_least_until_it_wrote_its_own_file(tmp_path: Path) -> None:
    from ros_isolated_test.xunit.placeholder import WRITTEN_AT, killed_seconds

    written = 1_800_000_000.25
    properties = _left(tmp_path, written, written + 42.5)
    assert WRITTEN_AT in properties
    assert killed_seconds(tmp_path / "t.xml", properties) == pytest.approx(42.5, abs=1e-3)
    # The attempt of a rerun series that was killed: its own file, not the first's.
    series = tmp_path / "series"
    series.mkdir()
    properties = _left(series, written, written + 7.0, attempts=2)
    assert killed_seconds(series / "t.xml", properties) == pytest.approx(7.0, abs=1e-3)


@pytest.mark.parametrize("why", ["no own file", "times not kept", "no stamp", "own file first"])
def test_a_killed_test_of_no_evidence_measured_nothing_not_zero(tmp_path: Path, why: str) -> None:
    from ros_isolated_test.xunit.placeholder import WRITTEN_AT, killed_seconds

    written = 1_800_000_000.25
    properties = _left(tmp_path, written, None if why == "no own file" else written + 42.5)
    if why == "times not kept":  # a copy: every file the time it was copied
        for path in tmp_path.iterdir():
            os.utime(path, (written + 3600, written + 3600))
    elif why == "no stamp":
        del properties[WRITTEN_AT]
    elif why == "own file first":  # a stale file of an earlier run
        os.utime(tmp_path / "t.xml.attempt1.orig", (written - 5, written - 5))
    assert killed_seconds(tmp_path / "t.xml", properties) is None

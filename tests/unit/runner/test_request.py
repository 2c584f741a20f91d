"""``request``: the one request every entry point builds, and what it derives from its words.

The test's name is the result file's stem as ament names the test (``t.gtest.xml`` is
``t``), else the command's name; the package is ``--package-name``, else the result
file's folder, as run_test.py does. In a rerun series each attempt's command is pointed
at a result file of its own: every argument that names the result path (itself, or after
``=`` or ``:`` as ``--junit-xml=`` and ``--gtest_output=xml:`` do), compared made
absolute, and nothing else.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from ros_isolated_test.runner import settings
from ros_isolated_test.runner.request import EnvAssignment, Mode, RunRequest


def _request(command: tuple[str, ...], result_file: Path | None, **given: object) -> RunRequest:
    return RunRequest(
        command,
        Mode.AMENT,
        settings.defaults(),
        result_file=result_file,
        **given,  # type: ignore[arg-type]
    )


@pytest.mark.parametrize(
    ("result_file", "name"),
    [
        ("build/test_results/pkg/test_talker.gtest.xml", "test_talker"),
        ("r/test_node.xunit.xml", "test_node"),
        ("r/t.xml", "t"),
        ("r/.xml", ".xml"),  # nothing left without the suffix: the name as it is
        ("r/results.txt", "results.txt"),
    ],
)
def test_the_tests_name_is_the_result_files_stem_as_ament_names_it(
    result_file: str, name: str
) -> None:
    assert _request(("/opt/bin/talker",), Path(result_file)).test_name == name


def test_without_a_result_file_the_name_is_the_commands_and_the_package_a_default() -> None:
    assert _request(("/opt/bin/talker", "--x"), None).test_name == "talker"
    assert _request((), None).test_name == "test"
    assert _request(("t",), None).package == "ros_isolated_test"
    # The control: a result file's folder names the package, --package-name wins over it.
    assert _request(("t",), Path("test_results/pkg_a/t.xml")).package == "pkg_a"
    named = _request(("t",), Path("test_results/pkg_a/t.xml"), package_name="pkg_b")
    assert named.package == "pkg_b"


def test_every_argument_naming_the_result_path_is_pointed_at_the_attempts_own(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    own = tmp_path / "r.xml.attempt2.orig"
    command = (
        "test",
        "r.xml",
        "./r.xml",
        f"--junit-xml={tmp_path / 'r.xml'}",
        "--gtest_output=xml:r.xml",
        "other/r.xml",  # ends in the name, names another file: left as it is
        "--flag=r.xml.bak",
    )
    pointed = _request(command, Path("r.xml")).command_writing_to(Path("r.xml.attempt2.orig"))
    assert pointed == (
        "test",
        str(own),
        str(own),
        f"--junit-xml={own}",
        f"--gtest_output=xml:{own}",
        "other/r.xml",
        "--flag=r.xml.bak",
    )
    # The control: without a result file, nothing is pointed anywhere.
    assert _request(command, None).command_writing_to(own) == command


def test_env_assignments_compare_by_value() -> None:
    assert EnvAssignment("A", "1") == EnvAssignment("A", "1", append=False)
    assert EnvAssignment("A", "1") != EnvAssignment("A", "1", append=True)
    assert len({EnvAssignment("A", "1"), EnvAssignment("A", "1")}) == 1
    assert repr(EnvAssignment("P", "/x", True)) == "EnvAssignment('P', '/x', append=True)"

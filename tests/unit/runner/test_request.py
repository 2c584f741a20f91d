"""``request``: the one request every entry point builds, and what it derives from its words.

The test's name is the result file's stem as ament names the test (``t.gtest.xml`` is
``t``), else the command's name; the package is ``--package-name``, else the result
file's folder, as run_test.py does. In a rerun series each attempt's command is pointed
at a result file of its own: every argument that names the result path (itself, or after
``=`` or ``:`` as ``--junit-xml=`` and ``--gtest_output=xml:`` do), compared made
absolute, and nothing else.
"""

from __future__ import annotations

import subprocess
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


def test_a_split_refuses_a_package_name_no_identity_can_hold() -> None:
    """A ``/`` in the package under a split: a usage error when the request is made."""
    from ros_isolated_test.shard.identity import PackageNameError
    from ros_isolated_test.shard.selection import select
    from ros_isolated_test.shard.spec import SHARD_ENV, ShardSettingError

    split = select({SHARD_ENV: "1/2"})
    with pytest.raises(PackageNameError, match=r"^--package-name 'a/b' cannot name a test"):
        _request(("true",), Path("r/t.xml"), package_name="a/b", shard=split)
    assert issubclass(PackageNameError, ShardSettingError)  # what every entry point reports
    # The controls: a valid name under the split, and the same name without one.
    assert _request(("true",), Path("r/t.xml"), package_name="a_b", shard=split).package == "a_b"
    assert _request(("true",), Path("r/t.xml"), package_name="a/b").package == "a/b"


@pytest.mark.parametrize("mode", ["shell", "runner"])
def test_a_slash_in_the_package_of_a_split_is_a_usage_error_with_a_result_file(
    tmp_path: Path, env: dict[str, str], runner_script: str, mode: str
) -> None:
    """Issue 41 item 5: no traceback; one line, exit 2, and the RUNNER's result file."""
    from helpers.commands import ament, run_cli
    from helpers.results import load_result

    from ros_isolated_test.shard.spec import SHARD_ENV

    result = tmp_path / "r" / "t.xml"
    marker = tmp_path / "ran"

    def started(package: str) -> subprocess.CompletedProcess[str]:
        if mode == "shell":
            return run_cli(
                ["run", "--shard", "1/1", "--package-name", package, "--junit-xml", str(result),
                 "--", "touch", str(marker)], env, cwd=tmp_path,
            )  # fmt: skip
        return ament(
            runner_script, result, ["touch", str(marker)], {**env, SHARD_ENV: "1/1"},
            "--generate-result-on-success", cwd=tmp_path, package=package,
        )  # fmt: skip

    proc = started("a/b")
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stderr
    (line,) = proc.stderr.splitlines()
    said = "ros-isolated-test: error: --package-name 'a/b' cannot name a test"
    assert line.startswith(said), line
    assert "package.xml" in line  # the fix
    assert not marker.exists()
    case = load_result(result).only
    assert case.outcome == "error" and "--package-name 'a/b'" in case.message
    # The control: a valid package name runs the test (the only share of 1/1).
    fine = started("a_b")
    assert fine.returncode == 0, fine.stdout + fine.stderr
    assert marker.exists()
    assert load_result(result).properties["shard"] == "1/1"

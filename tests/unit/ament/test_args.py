"""run_test.py's arguments, parsed without argparse: the words argparse would accept, read alike.

What the ctest RUNNER script hands over (``args.parse``, ``args.main``): the full ament
argument set, the resources a test's ENV asks for, and usage errors that name the problem
and keep the result file, so a run that cannot start still leaves one. Only what the user
can fix is called a usage error: a bug of ours while parsing shows as the bug it is.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers.commands import ament
from helpers.results import load_result

from ros_isolated_test.ament import args
from ros_isolated_test.ament.args import UsageError, help_text, parse
from ros_isolated_test.runner import settings


def _env(argv: list[str]) -> list[tuple[str, str, bool]]:
    return [(item.name, item.value, item.append) for item in parse(argv).env]


def test_the_full_ament_argument_set() -> None:
    request = parse(
        [
            "build/pkg/test_results/pkg/t.xunit.xml",
            "--package-name",
            "pkg",
            "--output-file",
            "build/pkg/ament_cmake_pytest/t.txt",
            "--env",
            "A=1",
            "B=x=y",
            "--append-env",
            "PATH=/opt/bin",
            "--generate-result-on-success",
            "--skip-return-code",
            "77",
            "--command",
            "pytest",
            "--env",
            "-x",
        ]
    )
    assert request.result_file == Path("build/pkg/test_results/pkg/t.xunit.xml")
    assert request.package_name == "pkg"
    assert request.output_file == Path("build/pkg/ament_cmake_pytest/t.txt")
    assert [(e.name, e.value, e.append) for e in request.env] == [
        ("A", "1", False),
        ("B", "x=y", False),
        ("PATH", "/opt/bin", True),
    ]
    assert request.generate_result_on_success
    assert not request.skip_test
    assert request.skip_return_code == 77
    assert request.command == ("pytest", "--env", "-x")


def test_values_that_look_like_negative_numbers_or_hold_spaces_are_values() -> None:
    """CMake splits ``A=1;-5`` into two words; argparse keeps ``-5`` as a value."""
    assert _env(["r.xml", "--env", "A=1", "-5", "--command", "x"]) == [("A", "1;-5", False)]
    assert _env(["r.xml", "--env", "A=1", "-x y", "--command", "x"]) == [("A", "1;-x y", False)]
    assert parse(["r.xml", "--output-file", "-", "--command", "x"]).output_file == Path("-")


def test_repeated_env_options_accumulate() -> None:
    argv = ["r.xml", "--env", "A=1", "--env", "B=2", "--append-env", "P=/x", "--command", "x"]
    assert _env(argv) == [("A", "1", False), ("B", "2", False), ("P", "/x", True)]


def test_a_continuation_never_crosses_into_another_env_option() -> None:
    """CMake's ``;`` splits are rejoined within one ``--env`` only, as run_test.py does."""
    with pytest.raises(UsageError, match="contains no '='"):
        parse(["r.xml", "--env", "A=x", "--env", "junk", "--command", "x"])


def test_an_option_with_an_inline_value_holding_a_space() -> None:
    request = parse(["r.xml", "--output-file=/tmp/my dir/o.txt", "--env=A=a b", "--command", "x"])
    assert request.output_file == Path("/tmp/my dir/o.txt")
    assert _env(["r.xml", "--env=A=a b", "--command", "x"]) == [("A", "a b", False)]


def test_option_equals_value_and_unique_prefixes() -> None:
    request = parse(["r.xml", "--pack=p", "--gen", "--env=A=1", "--command", "x"])
    assert request.package_name == "p"
    assert request.generate_result_on_success
    assert _env(["r.xml", "--env=A=1", "--command", "x"]) == [("A", "1", False)]


def test_double_dash_ends_the_options() -> None:
    assert parse(["--", "r.xml", "--command", "x"]).result_file == Path("r.xml")


@pytest.mark.parametrize(
    ("argv", "says", "result_file"),
    [
        (["--command", "x"], "required: result_file", None),
        (["r.xml", "extra", "--command", "x"], "unrecognized arguments: extra", "r.xml"),
        (["r.xml", "-q", "--command", "x"], "unrecognized arguments: -q", "r.xml"),
        (["r.xml", "--nope", "--command", "x"], "unrecognized arguments: --nope", "r.xml"),
        (["r.xml", "--skip", "--command", "x"], "ambiguous option: --skip", "r.xml"),
        (["r.xml", "--package-name", "--command", "x"], "expected one argument", "r.xml"),
        (["r.xml", "--env", "--command", "x"], "expected at least one argument", "r.xml"),
        (["r.xml", "--skip-test=yes", "--command", "x"], "ignored explicit argument", "r.xml"),
        (["r.xml", "--skip-return-code", "256", "--command", "x"], "0 to 255", "r.xml"),
        (["r.xml", "--skip-return-code", "x", "--command", "x"], "0 to 255", "r.xml"),
        (["r.xml", "--env", "=1", "--command", "x"], "no variable name", "r.xml"),
        (["r.xml", "--env", "novalue", "--command", "x"], "contains no '='", "r.xml"),
        (["r.xml", "--package-name", "p"], "no test command", "r.xml"),
        (["r.xml", "--command"], "no test command", "r.xml"),
    ],
)
def test_usage_errors_name_the_problem_and_keep_the_result_file(
    argv: list[str], says: str, result_file: str | None
) -> None:
    with pytest.raises(UsageError) as raised:
        parse(argv)
    assert says in str(raised.value)
    assert raised.value.result_file == (Path(result_file) if result_file else None)


def test_help_lists_every_option() -> None:
    text = help_text()
    assert text.startswith("usage: run_test_isolated.py result_file")
    for option in (
        "--package-name NAME",
        "--env K=V [K=V ...]",
        "--append-env K=V [K=V ...]",
        "--output-file PATH",
        "--generate-result-on-success",
        "--skip-test",
        "--skip-return-code N",
        "--command CMD ...",
        "DISABLE_ROS_ISOLATION",
    ):
        assert option in text


#: The variable ament_add_test's ENV (the CMake macros' RESOURCES) passes as --env.
RESOURCES = "ROS_ISOLATED_TEST_RESOURCES"
CAPACITY = "ROS_ISOLATED_TEST_CAPACITY"


@pytest.fixture
def no_resource_variables(monkeypatch: pytest.MonkeyPatch) -> None:
    """parse() reads the runner's own environment: nothing of this machine's may leak in."""
    monkeypatch.delenv(RESOURCES, raising=False)
    monkeypatch.delenv(CAPACITY, raising=False)


def _resources(*options: str) -> dict[str, int]:
    return parse(["r.xml", *options, "--command", "x"]).settings.resources


@pytest.mark.usefixtures("no_resource_variables")
def test_resources_come_from_the_tests_env() -> None:
    assert _resources() == {}
    assert _resources("--env", f"{RESOURCES}=gpu=1,mem=1K") == {"gpu": 1, "mem": 1024}
    # The last --env of it wins, as for reruns (ENV of ros_isolated_test_all(), then the call's).
    last = ("--env", f"{RESOURCES}=gpu=1", "--env", "A=1", f"{RESOURCES}=lidar=1")
    assert _resources(*last) == {"lidar": 1}
    # An --append-env of it is no request (path-like variables only).
    assert _resources("--append-env", f"{RESOURCES}=gpu=1") == {}


def test_the_tests_env_wins_over_the_runners_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(CAPACITY, raising=False)
    monkeypatch.setenv(RESOURCES, "gpu=1")
    assert _resources() == {"gpu": 1}  # the control: the runner's own variable is read
    assert _resources("--env", f"{RESOURCES}=lidar=1") == {"lidar": 1}
    assert _resources("--env", f"{RESOURCES}=") == {}  # an empty value asks for nothing
    # A bad value in the runner's environment is not even read when --env sets it.
    monkeypatch.setenv(RESOURCES, "gpu")
    assert _resources("--env", f"{RESOURCES}=lidar=1") == {"lidar": 1}


@pytest.mark.usefixtures("no_resource_variables")
@pytest.mark.parametrize(
    ("value", "says"),
    [
        ("gpu", "'gpu' is not name=amount"),
        ("GPU=1", "'GPU' is not a resource name"),
        ("gpu=0", "gpu='0' is zero"),
        ("gpu=1,gpu=1", "gpu is given twice"),
        ("mem=4X", "mem='4X' is not a whole amount"),
        ("gpu=2", "more than this machine's capacity of gpu, 1 (by default)"),
    ],
)
def test_a_bad_request_is_a_usage_error_naming_the_env(value: str, says: str) -> None:
    with pytest.raises(UsageError) as raised:
        parse(["r.xml", "--env", f"{RESOURCES}={value}", "--command", "x"])
    message = str(raised.value)
    assert message.startswith(f"--env {RESOURCES}: ") and says in message, message
    assert "\n" not in message
    assert raised.value.result_file == Path("r.xml")


def test_the_capacity_comes_from_the_runners_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    """Above the default capacity of 1 is refused; the same request fits a capacity set higher."""
    monkeypatch.delenv(RESOURCES, raising=False)
    monkeypatch.setenv(CAPACITY, "gpu=2")
    request = parse(["r.xml", "--env", f"{RESOURCES}=gpu=2", "--command", "x"])
    assert (request.settings.resources, request.settings.capacity) == ({"gpu": 2}, {"gpu": 2})
    with pytest.raises(UsageError, match=rf"gpu, 2 \(as set in {CAPACITY}\)"):
        parse(["r.xml", "--env", f"{RESOURCES}=gpu=3", "--command", "x"])


def test_help_names_the_resource_variables() -> None:
    text = help_text()
    assert f"{RESOURCES}=cpu=2,mem=4G,gpu=1 (also in --env / ENV, which wins)" in text
    assert CAPACITY in text


def test_a_bad_request_through_the_runner_runs_nothing_and_leaves_a_result(
    env: dict[str, str], runner_script: str, tmp_path: Path
) -> None:
    """A real RUNNER: exit 2, one line, a result file saying why; a good request runs (control)."""
    for name in (RESOURCES, CAPACITY):
        env.pop(name, None)
    result = tmp_path / "r.xml"
    options = ("--generate-result-on-success", "--env")
    bad = ament(
        runner_script, result, ["touch", "ran"], env, *options, f"{RESOURCES}=gpu", cwd=tmp_path
    )
    assert bad.returncode == 2, bad.stdout + bad.stderr
    (line,) = bad.stderr.strip().splitlines()
    assert f"--env {RESOURCES}: 'gpu' is not name=amount" in line, line
    assert not (tmp_path / "ran").exists()
    case = load_result(result).only
    assert case.outcome == "error" and f"--env {RESOURCES}" in case.message, case
    good = ament(
        runner_script, result, ["touch", "ran"], env, *options, f"{RESOURCES}=gpu=1", cwd=tmp_path
    )
    assert good.returncode == 0, good.stdout + good.stderr
    assert (tmp_path / "ran").exists()
    summary = load_result(result)
    assert summary.only.outcome == "passed", summary
    assert summary.properties.get("resources") == "gpu=1", summary.properties


# --- arguments: only what the user can fix is a usage error ----------------------------------


def test_a_bad_setting_is_a_usage_error_naming_the_result_file(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    result = tmp_path / "t.xml"
    monkeypatch.setenv(settings.WAIT_TIMEOUT_ENV, "ten")
    with pytest.raises(args.UsageError) as raised:
        args.parse([str(result), "--command", "true"])
    assert raised.value.result_file == result
    assert f"{settings.WAIT_TIMEOUT_ENV}='ten' is not a number of seconds" in str(raised.value)


def test_a_bug_while_parsing_shows_as_a_bug_never_as_a_usage_error(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """A fault planted where settings are read: a ValueError of ours is no user's mistake."""

    def broken(*_args: object, **_kwargs: object) -> settings.Settings:
        raise ValueError("a bug of the runner")

    monkeypatch.setattr(settings, "read", broken)
    with pytest.raises(ValueError, match="a bug of the runner") as raised:
        args.parse([str(tmp_path / "t.xml"), "--command", "true"])
    assert type(raised.value) is ValueError

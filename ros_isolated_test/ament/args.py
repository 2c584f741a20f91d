"""ctest RUNNER mode: run_test.py's argument set, parsed into a :class:`RunRequest`.

ament_cmake calls ``python3 -u <RUNNER> RESULT_FILE --package-name P [...] --command CMD...``;
everything after ``--command`` is the test's command line, options included.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path

from ros_isolated_test import not_run
from ros_isolated_test.runner import exit_codes, session, settings
from ros_isolated_test.runner.request import EnvAssignment, Mode, RunRequest

PROG = "run_test_isolated.py"
DESCRIPTION = (
    "ctest RUNNER for ament_add_test / add_launch_test: reserves a free ROS_DOMAIN_ID on "
    "this machine, runs the test with it and makes sure a result file is left. Accepts "
    "the arguments of ament_cmake_test's run_test.py."
)
EPILOG = (
    "Set DISABLE_ROS_ISOLATION=1 (in the environment, or with --env / ament_add_test's ENV) "
    "to run without a reserved domain ID. Also read: ROS_ISOLATED_TEST_DOMAINS, "
    "ROS_ISOLATED_TEST_LOCK_DIR, ROS_ISOLATED_TEST_WAIT_TIMEOUT, "
    "ROS_ISOLATED_TEST_DISCOVERY_RANGE (see ros-isolated-test run --help); "
    "ROS_ISOLATED_TEST_RERUNS=N (also in --env / ENV, which wins): run a failed test again "
    "up to N times (N from 0 to 100), keeping every attempt in the result file; "
    "ROS_ISOLATED_TEST_RESOURCES=cpu=2,mem=4G,gpu=1 (also in --env / ENV, which wins): "
    "machine resources the test holds with its ID, waiting until they are free; "
    "ROS_ISOLATED_TEST_CAPACITY: how much of each the machine has (default: its CPUs, its "
    "memory, 1 of any other name); "
    "ROS_ISOLATED_TEST_SHARD=I/N: run only share I of N of the tests (a test of another "
    "share is not run and exits with its skip code, else 77), balanced by "
    "ROS_ISOLATED_TEST_DURATIONS=FILE (absolute; else by count); "
    "ROS_ISOLATED_TEST_ISOLATION=domain|namespace|auto (also in --env / ENV, which wins): "
    "namespace runs the test in a network, /dev/shm and IPC of its own too, never waiting "
    "for an ID."
)

#: run_test.py's options: (name, metavar or None for a flag, repeats, help). No argparse:
#: it is imported by every test's runner, and this fixed set needs none of it.
OPTIONS: tuple[tuple[str, str | None, bool, str], ...] = (
    ("--package-name", "NAME", False, "prefix for gtest classnames, suite names"),
    ("--env", "K=V", True, "variables to set (repeatable)"),
    (
        "--append-env",
        "K=V",
        True,
        "values to append to path-like variables, set when unset (repeatable)",
    ),
    ("--output-file", "PATH", False, "also write all output to this file"),
    (
        "--generate-result-on-success",
        None,
        False,
        "write a passed result when the command returns 0 and wrote none",
    ),
    ("--skip-test", None, False, "do not run; report skipped"),
    (
        "--skip-return-code",
        "N",
        False,
        "report the test skipped when it returns N and wrote no result file",
    ),
)


class UsageError(not_run.NotRun):
    """The arguments cannot be understood; ``result_file`` is set if it could be found."""

    def __init__(self, message: str, result_file: Path | None = None) -> None:
        super().__init__(message)
        self.result_file = result_file


def help_text() -> str:
    """What ``--help`` prints: every option, in the words ament's users know."""
    rows = [("result_file", "the xUnit result file of the test"), ("-h, --help", "show this")]
    for name, metavar, repeats, text in OPTIONS:
        shown = f"{name} {metavar} [{metavar} ...]" if repeats else f"{name} {metavar or ''}"
        rows.append((shown.strip(), text))
    rows.append(("--command CMD ...", "the test command and all its arguments; must come last"))
    width = max(len(left) for left, _ in rows) + 2
    lines = [f"usage: {PROG} result_file [options] --command CMD ...", "", DESCRIPTION, ""]
    lines += [f"  {left.ljust(width)}{text}" for left, text in rows]
    return "\n".join([*lines, "", EPILOG, ""])


def _option(word: str) -> tuple[str, str | None, bool]:
    """The option ``word`` names (unique prefixes allowed, as run_test.py's argparse does)."""
    matches = [item for item in OPTIONS if item[0] == word]
    matches = matches or [item for item in OPTIONS if item[0].startswith(word)]
    if len(matches) != 1:
        known = ", ".join(item[0] for item in matches)
        raise UsageError(
            f"ambiguous option: {word} could match {known}"
            if matches
            else f"unrecognized arguments: {word}"
        )
    name, metavar, repeats, _help = matches[0]
    return name, metavar, repeats


def _is_option(word: str) -> bool:
    """Whether argparse (run_test.py's parser) would take ``word`` for an option.

    A negative number, a lone ``-`` or a word with a space is a value.
    """
    if not word.startswith("-") or word == "-":
        return False
    name, equals, _value = word.partition("=")
    if equals and any(option[0].startswith(name) for option in OPTIONS):
        return True  # --output-file=/a b: an option, whatever its value holds
    return " " not in word and not word[1:].replace(".", "", 1).isdigit()


def _parse_options(argv: Sequence[str]) -> tuple[list[str], dict[str, list[list[str]]]]:
    """Positional arguments and each option's values, one list per occurrence.

    A flag's occurrence holds one ``""``. Every occurrence of ``--env`` and
    ``--append-env`` counts; other options keep their last. After ``--`` every word is
    positional.
    """
    positional: list[str] = []
    values: dict[str, list[list[str]]] = {}
    words = list(argv)
    while words:
        word = words.pop(0)
        if word == "--":
            positional += words
            break
        if not _is_option(word):
            positional.append(word)
            continue
        if not word.startswith("--"):
            raise UsageError(f"unrecognized arguments: {word}")
        word, equals, inline = word.partition("=")
        name, metavar, repeats = _option(word)
        if metavar is None:
            if equals:
                raise UsageError(f"argument {name}: ignored explicit argument {inline!r}")
            values[name] = [[""]]
            continue
        taken = [inline] if equals else []
        while not equals and words and not _is_option(words[0]) and words[0] != "--":
            taken.append(words.pop(0))
            if not repeats:
                break
        if not taken:
            count = "at least one argument" if repeats else "one argument"
            raise UsageError(f"argument {name}: expected {count}")
        values[name] = [*values.get(name, []), taken] if repeats else [taken]
    return positional, values


def _return_code(value: str) -> int:
    try:
        code = int(value)
    except ValueError:
        code = -1
    if not 0 <= code <= 255:
        raise UsageError(f"argument --skip-return-code: {value!r} is not a code from 0 to 255")
    return code


def _assignments(values: Sequence[str], option: str, append: bool) -> list[EnvAssignment]:
    """``K=V`` items; an item without ``=`` continues the previous value, joined by ``;``.

    That is how CMake's list splitting of a value containing ``;`` is undone.
    """
    merged: list[EnvAssignment] = []
    for value in values:
        name, equals, rest = value.partition("=")
        if not equals:
            if not merged:
                raise UsageError(f"{option} argument {value!r} contains no '=' (expected K=V)")
            last = merged.pop()
            merged.append(EnvAssignment(last.name, f"{last.value};{value}", append))
            continue
        if not name:
            raise UsageError(f"{option} argument {value!r} has no variable name before '='")
        merged.append(EnvAssignment(name, rest, append))
    return merged


def _reruns_of(env: Sequence[EnvAssignment]) -> int | None:
    """ROS_ISOLATED_TEST_RERUNS as the test's ``--env`` sets it last; None: not set there.

    ament_add_test's ENV reaches the runner only as ``--env``: the CMake macros' RERUNS
    argument is passed that way, and like DISABLE_ROS_ISOLATION it has the last word.
    """
    found = [item for item in env if item.name == settings.RERUNS_ENV and not item.append]
    if not found:
        return None
    value = found[-1].value
    return settings.reruns_from(value, f"--env {settings.RERUNS_ENV}") if value.strip() else 0


def _resources_of(env: Sequence[EnvAssignment]) -> str | None:
    """ROS_ISOLATED_TEST_RESOURCES as the test's ``--env`` sets it last; None: not set there.

    Read like ROS_ISOLATED_TEST_RERUNS (the CMake macros' RESOURCES argument arrives this
    way) and checked by settings; an empty value asks for nothing.
    """
    found = [item for item in env if item.name == settings.RESOURCES_ENV and not item.append]
    return found[-1].value if found else None


def _guess_result_file(argv: Sequence[str]) -> Path | None:
    """The result file, to report a usage error in it: ament always passes it first."""
    if argv and not argv[0].startswith("-"):
        return Path(argv[0])
    return None


def parse(argv: Sequence[str]) -> RunRequest:
    """Parse run_test.py arguments; :class:`UsageError` says what is wrong."""
    argv = list(argv)
    command: list[str] = []
    if "--command" in argv:
        index = argv.index("--command")
        argv, command = argv[:index], argv[index + 1 :]
    try:
        positional, values = _parse_options(argv)
        if not positional:
            raise UsageError("the following arguments are required: result_file")
        if len(positional) > 1:
            raise UsageError(f"unrecognized arguments: {' '.join(positional[1:])}")
    except UsageError as error:
        raise UsageError(str(error), _guess_result_file(argv)) from None
    result_file = Path(positional[0])
    if not command:
        raise UsageError(
            "no test command: pass it after --command (it must come last)", result_file
        )
    try:
        env = [
            assignment
            for option, append in (("--env", False), ("--append-env", True))
            for occurrence in values.get(option, [])
            for assignment in _assignments(occurrence, option, append)
        ]
        single = {name: found[-1][0] for name, found in values.items()}
        return RunRequest(
            command=tuple(command),
            mode=Mode.AMENT,
            # RUNNER mode has no options of its own for these: the environment only, and
            # for reruns and resources the test's ENV too, which wins
            # (ament_add_test(... ENV ROS_ISOLATED_TEST_RESOURCES=gpu=1)).
            settings=settings.read(
                reruns=_reruns_of(env),
                resources=_resources_of(env),
                resources_origin=f"--env {settings.RESOURCES_ENV}",
            ),
            result_file=result_file,
            package_name=single.get("--package-name"),
            output_file=Path(single["--output-file"]) if "--output-file" in single else None,
            env=tuple(env),
            skip_test="--skip-test" in single,
            skip_return_code=(
                _return_code(single["--skip-return-code"])
                if "--skip-return-code" in single
                else None
            ),
            generate_result_on_success="--generate-result-on-success" in single,
            env_origin="--env (ament_add_test ENV)",
            # The split from the environment only: ctest runs every test of a machine
            # with the same one (a test's ENV naming a share would split nothing).
            shard=settings.split(),
        )
    except not_run.NotRun as error:
        # Only what the user can fix: any other error is a bug, and must show as one.
        raise UsageError(str(error), result_file) from None


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the RUNNER script."""
    argv = sys.argv[1:] if argv is None else argv
    if any(item in ("-h", "--help") for item in argv[: _command_index(argv)]):
        sys.stdout.write(help_text())
        return exit_codes.PASSED
    try:
        request = parse(argv)
    except UsageError as error:
        # session prefixes "ros-isolated-test: error: ": no second prefix here.
        message = f"{error}; see {PROG} --help"
        return session.report_usage_error(message, error.result_file)
    return session.run(request)


def _command_index(argv: Sequence[str]) -> int:
    return argv.index("--command") if "--command" in argv else len(argv)

"""ctest RUNNER mode: run_test.py's argument set, parsed into a :class:`RunRequest`.

ament_cmake calls ``python3 -u <RUNNER> RESULT_FILE --package-name P [...] --command CMD...``;
everything after ``--command`` is the test's command line, options included.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn

from ros_isolated_test.runner import discovery, exit_codes, session
from ros_isolated_test.runner.request import (
    EnvAssignment,
    Mode,
    RunRequest,
    wait_timeout_from_env,
)

PROG = "run_test_isolated.py"


class UsageError(Exception):
    """The arguments cannot be understood; ``result_file`` is set if it could be found."""

    def __init__(self, message: str, result_file: Path | None = None) -> None:
        super().__init__(message)
        self.result_file = result_file


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        raise UsageError(message)


def _return_code(value: str) -> int:
    code = int(value)
    if not 0 <= code <= 255:
        raise argparse.ArgumentTypeError("must be between 0 and 255")
    return code


def build_parser() -> argparse.ArgumentParser:
    """The same options as ament_cmake_test's run_test.py, explained for ``--help``."""
    parser = _Parser(
        prog=PROG,
        description=(
            "ctest RUNNER for ament_add_test / add_launch_test: reserves a free ROS_DOMAIN_ID "
            "on this machine, runs the test with it and makes sure a result file is left. "
            "Accepts the arguments of ament_cmake_test's run_test.py."
        ),
        epilog="Set DISABLE_ROS_ISOLATION=1 to run without a reserved domain ID.",
    )
    parser.add_argument("result_file", type=Path, help="the xUnit result file of the test")
    parser.add_argument("--package-name", help="prefix for gtest classnames, suite names")
    parser.add_argument("--env", nargs="+", default=[], metavar="K=V", help="variables to set")
    parser.add_argument(
        "--append-env",
        nargs="+",
        default=[],
        metavar="K=V",
        help="values to append to path-like variables (set when unset)",
    )
    parser.add_argument("--output-file", type=Path, help="also write all output to this file")
    parser.add_argument(
        "--generate-result-on-success",
        action="store_true",
        help="write a passed result when the command returns 0 and wrote none",
    )
    parser.add_argument("--skip-test", action="store_true", help="do not run; report skipped")
    parser.add_argument(
        "--skip-return-code",
        type=_return_code,
        metavar="N",
        help="report the test skipped when it returns N and wrote no result file",
    )
    parser.add_argument(
        "--command",
        nargs=argparse.REMAINDER,
        help="the test command and all its arguments; must come last",
    )
    return parser


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
        args = build_parser().parse_args(argv)
    except UsageError as error:
        raise UsageError(str(error), _guess_result_file(argv)) from None
    if not command:
        raise UsageError(
            "no test command: pass it after --command (it must come last)", args.result_file
        )
    try:
        env = _assignments(args.env, "--env", append=False)
        env += _assignments(args.append_env, "--append-env", append=True)
    except UsageError as error:
        raise UsageError(str(error), args.result_file) from None
    try:
        wait_timeout = wait_timeout_from_env()
        override = os.environ.get(discovery.OVERRIDE_ENV, "").strip() or None
    except ValueError as error:
        raise UsageError(str(error), args.result_file) from None
    return RunRequest(
        command=tuple(command),
        mode=Mode.AMENT,
        wait_timeout=wait_timeout,
        discovery_range=override,
        result_file=args.result_file,
        package_name=args.package_name,
        output_file=args.output_file,
        env=tuple(env),
        skip_test=args.skip_test,
        skip_return_code=args.skip_return_code,
        generate_result_on_success=args.generate_result_on_success,
        env_origin="--env (ament_add_test ENV)",
    )


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the RUNNER script."""
    argv = sys.argv[1:] if argv is None else argv
    if any(item in ("-h", "--help") for item in argv[: _command_index(argv)]):
        build_parser().print_help()
        return exit_codes.PASSED
    try:
        request = parse(argv)
    except UsageError as error:
        message = f"{PROG}: {error}; see {PROG} --help"
        return session.report_usage_error(message, error.result_file)
    return session.run(request)


def _command_index(argv: Sequence[str]) -> int:
    return argv.index("--command") if "--command" in argv else len(argv)

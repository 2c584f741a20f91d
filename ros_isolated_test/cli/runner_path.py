"""``ros-isolated-test runner-path``: where the ctest RUNNER script is, for a CMakeLists.txt."""

from __future__ import annotations

import click


@click.command("runner-path")
def runner_path() -> None:
    """Print the path of the ctest RUNNER script for ament_add_test / add_launch_test.

    \b
    In CMakeLists.txt:
      execute_process(COMMAND ros-isolated-test runner-path
        OUTPUT_VARIABLE RUNNER OUTPUT_STRIP_TRAILING_WHITESPACE COMMAND_ERROR_IS_FATAL ANY)
      ament_add_test(my_test RUNNER "${RUNNER}" COMMAND ...)
    """  # noqa: D301 (click reads a backspace, not a backslash, as "keep these lines")
    from ros_isolated_test.ament import installed

    click.echo(str(installed.runner_script()))

"""``ros-isolated-test cmake-include``: the CMake include, or a colcon defaults file naming it."""

from __future__ import annotations

from pathlib import Path

import click

from ros_isolated_test.cli import usage


@click.command("cmake-include")
@click.option(
    "--colcon-defaults",
    is_flag=True,
    help="Print a colcon defaults file that passes it to every build; with FILE, add it to "
    "that defaults file (made if missing), keeping every setting the file has.",
)
@click.argument("defaults_file", metavar="[FILE]", required=False, type=Path)
def cmake_include(colcon_defaults: bool, defaults_file: Path | None) -> None:
    """Print the path of the CMake file that isolates every ament_cmake package's tests.

    \b
    Nothing edited; each package's CMake cache keeps it for later builds:
      colcon build --cmake-args -DCMAKE_PROJECT_INCLUDE=$(ros-isolated-test cmake-include)
    Once for every build, in the defaults file colcon reads (COLCON_DEFAULTS_FILE, else
    $COLCON_HOME/defaults.yaml): added to the one you have, every other setting kept
      ros-isolated-test cmake-include --colcon-defaults ~/.colcon/defaults.yaml
    or a new one (never redirect it over a file you have: that drops its settings)
      ros-isolated-test cmake-include --colcon-defaults > isolated.yaml
      COLCON_DEFAULTS_FILE=isolated.yaml colcon build
    A FILE that cannot be changed safely is left as it is: the lines to add are
    printed, and the exit code is 1.
    Off: --cmake-args -DROS_ISOLATED_TEST_ALL=OFF, or -UCMAKE_PROJECT_INCLUDE to drop it.
    """  # noqa: D301 (click reads a backspace, not a backslash, as "keep these lines")
    from ros_isolated_test.ament import colcon_defaults as defaults
    from ros_isolated_test.ament import installed

    if defaults_file is not None and not colcon_defaults:
        raise click.UsageError("FILE is the colcon defaults file of --colcon-defaults: add it")
    path = installed.cmake_include()
    if path is None:
        usage.fail(
            f"the CMake files are not installed "
            f"({installed.CMAKE_INCLUDE} beside this package); reinstall ros-isolated-test "
            "with pip",
            usage.USAGE,
        )
    if not colcon_defaults:
        click.echo(str(path))
    elif defaults_file is None:
        click.echo(installed.colcon_defaults(path))
    else:
        try:
            added = defaults.add_to_file(defaults_file, path)
        except defaults.DefaultsError as error:
            click.echo(defaults.lines_to_add(path), nl=False)
            usage.fail(
                f"{defaults_file} was left as it is: {error}; add the lines above to it by hand",
                usage.FAILED,
            )
        click.echo(defaults.said(defaults_file, path, added))

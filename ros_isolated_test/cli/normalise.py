"""``ros-isolated-test normalise``: one result file made canonical, for a test run elsewhere."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from ros_isolated_test.cli import usage


@click.command()
@click.argument("source", type=click.Path(exists=True, path_type=Path))
@click.option(
    "--output",
    "-o",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Write the canonical file here instead of printing it.",
)
@click.option("--package-name", required=True, help="Package: suite name and classname prefix.")
@click.option("--test-name", help="Test name in the suite name (default: SOURCE's stem).")
def normalise(source: Path, output: Path | None, package_name: str, test_name: str | None) -> None:
    """Turn one result file into the canonical form of schemas/junit.xsd.

    Reads gtest, pytest, launch_testing, unittest-xml-reporting and ctest files (and
    broken ones), as the runner does after every test; for tests that did not run
    through it. Exits 1 when the result reports failures or errors, like `report`.
    """
    from ros_isolated_test.xunit import canonical

    try:
        data, failed = canonical.normalise_to(source, output, package_name, test_name)
    except canonical.OutputError as error:
        # Its output path cannot be used: one line, exit 2.
        usage.fail(str(error), usage.USAGE)
    if output is None:
        click.echo(data.decode("utf-8"), nl=False)
    if failed:
        sys.exit(usage.FAILED)

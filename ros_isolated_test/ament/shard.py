"""A package's share of a split, decided once when ctest loads it: the others never start.

A RUNNER decides for its one test (``runner.shard``), but only once ctest has started it:
in a split every machine would start a RUNNER, an interpreter, for every test of the
workspace. So the CMake include and macros give each package's test folders a
``TEST_INCLUDE_FILES`` script (``ros_isolated_test_share.cmake``) which, only when
``ROS_ISOLATED_TEST_SHARD`` is set as ctest loads the tests, runs this module once per
package: ``python -m ros_isolated_test.ament.shard PACKAGE LIST``. ``LIST`` holds
the package's tests as configuring registered them, a line each: the ctest name, a tab,
the result file. Each is placed by the identity its RUNNER would give it (``--package-name``, and
the result file's name as ``RunRequest.test_name`` reads it) under the very selection the
RUNNER reads (``runner.settings.split``: the same variables, file and plan), and the lines of
the other shares' tests are printed: the script marks them ``DISABLED``, once ctest's own
``add_test`` shows their command names that package and result file.

What a RUNNER does for a test of another share is done here for it: its stale result
file (a build folder restored from a cache) is removed, and the machine's record is left
in every result folder of the package, so a merge knows this share reported there even
when it ran nothing. A test whose stale file cannot be removed, or whose names form no
identity, is not printed: its RUNNER starts and says what is wrong, as before.

A bad share or durations file prints the RUNNER's one-line error and exits 2 with nothing
disabled: every RUNNER then fails with that line and a result file saying so.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

TYPE_CHECKING = False
if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence
    from typing import TextIO

    from ros_isolated_test.shard.selection import Selection

#: The exit code for a bad share, durations file or list: nothing is disabled then.
USAGE = 2

__all__ = ["USAGE", "main", "others", "read_list"]


def read_list(path: Path) -> list[tuple[str, Path]]:
    """The tests configuring registered: ``(ctest name, result file)``, the last of a name kept."""
    tests: dict[str, Path] = {}
    for line in path.read_text(encoding="utf-8", errors="surrogateescape").splitlines():
        name, tab, result = line.partition("\t")
        if tab and name and result:
            tests.pop(name, None)
            tests[name] = Path(result)
    return list(tests.items())


def others(
    selection: Selection, package: str, tests: Sequence[tuple[str, Path]], errors: TextIO
) -> list[tuple[str, Path]]:
    """The tests of other shares, their stale results removed, and the records left.

    What is printed for them is what disables them; a test left out here starts its
    RUNNER, which decides for it (and says what was wrong).
    """
    from ros_isolated_test import __version__
    from ros_isolated_test.shard import record
    from ros_isolated_test.shard.identity import IdentityError
    from ros_isolated_test.xunit.canonical import test_name_of
    from ros_isolated_test.xunit.result_file import ResultFile
    from ros_isolated_test.xunit.validate import hostname

    found: list[tuple[str, Path]] = []
    folders: dict[Path, None] = {}
    for name, result in tests:
        folders[result.parent] = None
        test = test_name_of(result)
        try:
            if selection.runs(package, test):
                continue
        except IdentityError:
            continue
        try:
            ResultFile(result, (), package, test).prepare()
        except (OSError, ValueError):
            continue  # its RUNNER says why the stale file stays
        found.append((name, result))
    host = hostname()
    for folder in folders:
        try:
            record.leave(folder, selection, host, __version__)
        except OSError as error:
            errors.write(
                f"ros-isolated-test: cannot leave the shard record "
                f"{record.file_name(selection.share)} in {folder} ({error.strerror or error}): "
                "a merge of the machines' results may not know this share reported; make "
                "the folder writable\n"
            )
    return found


def main(argv: Sequence[str], environ: Mapping[str, str], out: TextIO, errors: TextIO) -> int:
    """Print the lines of the tests ctest is not to start; 0, or 2 with nothing printed."""
    if len(argv) != 2:
        errors.write("usage: python -m ros_isolated_test.ament.shard PACKAGE LIST\n")
        return USAGE
    from ros_isolated_test.runner import settings
    from ros_isolated_test.shard.spec import ShardSettingError

    package, listing = argv
    try:
        selection = settings.split(environ=environ)
    except ShardSettingError as error:
        errors.write(f"ros-isolated-test: {error}\n")
        return USAGE
    if selection is None:
        return 0
    try:
        tests = read_list(Path(listing))
    except OSError as error:
        errors.write(
            f"ros-isolated-test: cannot read the tests of {package} ({listing}: "
            f"{error.strerror or error}); configure the package again\n"
        )
        return USAGE
    for name, result in others(selection, package, tests, errors):
        out.write(f"{name}\t{result}\n")
    return 0


if __name__ == "__main__":
    import io

    # Names as the list holds them, undecodable bytes included: ctest reads bytes.
    stdout = io.TextIOWrapper(sys.stdout.buffer, encoding="utf-8", errors="surrogateescape")
    code = main(sys.argv[1:], os.environ, stdout, sys.stderr)
    stdout.flush()
    stdout.detach()
    sys.exit(code)

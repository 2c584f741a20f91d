"""The files beside a result path: where the test writes its own file, and where it is kept.

Apart from the result file's life cycle (``result_file``) because these names are a
promise to users and CI: the test's own file of attempt ``k`` is written to
``<name>.attempt<k>.orig`` and kept as ``<name>.orig`` (the last attempt's) or as
``<name>.attempt<k>.orig`` (an earlier one's). None ends in ``.xml``, so no glob of
results (``colcon test-result``, a CI's ``*.xml``) ever reads one as a result.
"""

from __future__ import annotations

import os
import stat

TYPE_CHECKING = False
if TYPE_CHECKING:
    from pathlib import Path

ORIGINAL_SUFFIX = ".orig"


def original_of(path: Path) -> Path:
    """Where the test's own file is kept once its canonical form replaces it."""
    return path.with_name(path.name + ORIGINAL_SUFFIX)


def attempt_original_of(path: Path, number: int) -> Path:
    """Where attempt ``number`` writes its own file, and where it is kept when a rerun follows."""
    return path.with_name(f"{path.name}.attempt{number}{ORIGINAL_SUFFIX}")


def keep_aside(path: Path, original: Path) -> None:
    """Put the test's file at ``original`` too, whatever the test left there before.

    ``original`` is ours (``prepare`` cleared it): anything there now the test made,
    a file or a whole tree, and it gives way.
    """
    remove(original)
    mode = os.lstat(path).st_mode
    if stat.S_ISDIR(mode):
        os.rename(path, original)
        return
    try:
        os.link(path, original, follow_symlinks=False)
    except OSError:
        # A file system without hard links: a copy (a symlink stays a symlink).
        import shutil

        shutil.copy2(path, original, follow_symlinks=False)


def remove(path: Path) -> None:
    """Remove a file, a symlink or a whole directory tree at ``path``, if any."""
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return
    if stat.S_ISDIR(mode):
        import shutil

        shutil.rmtree(path)  # never follows a symlink inside
    else:
        os.unlink(path)

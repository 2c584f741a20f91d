"""What a test's private /dev/shm would hide from it: the paths it is given in the host's.

In namespace mode the test gets a tmpfs of its own on /dev/shm, empty (``process.namespace``),
and the host's is out of its reach. What it is handed there is gone for it (measured): a
command or a file named under /dev/shm is not found, and a working directory there is
worse: the test starts in the host's directory, so relative paths reach the host's files
and what it writes relatively lands in the host's /dev/shm, past its isolation, while
absolute paths, and a ``getcwd()`` made absolute, find nothing (pytest: "file or directory
not found", then a traceback). So namespace mode refuses (``auto`` runs on the ID alone)
a test that would start in the host's /dev/shm or be handed a path in a folder there:
its command, an argument (a path, ``--opt=PATH``, ``xml:PATH``, a symlink into it), an
entry of an environment variable (``PYTHONPATH`` or ``AMENT_PREFIX_PATH`` of a workspace
built there; not the shell's ``PWD``), or its result file when the command names it (the
test would write it inside, the runner reads it outside). A name missing from /dev/shm
itself is the test's own to make in its private one (a shared-memory segment), and
/dev/shm is there inside too: neither is refused. The runner's own files (``--output-file``,
a result file the command does not name) are written outside: they may be anywhere.
"""

from __future__ import annotations

import os

from ros_isolated_test.process.namespace import SHM

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from collections.abc import Iterator, Mapping, Sequence
    from pathlib import Path

#: Variables a shell keeps for itself, no path the test is handed to use.
_BOOKKEEPING = frozenset({"PWD", "OLDPWD", "_"})
#: What namespace mode gives that hides them, and the fix, for a refusal's words.
GIVES = f"gives the test a {SHM} of its own (a private tmpfs, empty)"
FIX = "move the test's files out of /dev/shm (a folder on disk, or /tmp) and run it from there"


def _pieces(word: str) -> Iterator[str]:
    """The paths an argument may name: itself, and what follows ``=`` or ``:`` in it."""
    yield word
    for cut, char in enumerate(word):
        if char in "=:" and word[cut + 1 :]:
            yield word[cut + 1 :]


def hidden(
    command: Sequence[str],
    env: Mapping[str, str],
    result_file: Path | None = None,
    cwd: str | None = None,
    shm: str = SHM,
) -> list[str]:
    """What of the test's paths lies in the host's ``shm``, each named for a message.

    ``cwd``: where the test starts (default: here, as the runner's child inherits it).
    Empty when nothing would be hidden. One ``stat`` a path of the command: only what
    lives on the file system of ``shm`` is resolved further (a symlink into it counts);
    of the environment's paths, only those named under ``shm``.
    """
    try:
        device = os.stat(shm).st_dev
    except OSError:
        return []  # no /dev/shm here: namespace mode mounts none either
    root = os.path.realpath(shm)
    # An environment holds hundreds of paths: only those named under /dev/shm are looked at.
    named = tuple(f"{prefix}{os.sep}" for prefix in {os.path.normpath(shm), root})
    try:
        start = os.getcwd() if cwd is None else cwd
    except OSError:
        start = os.sep  # a directory deleted under us: nothing of it to hide

    def there(path: str, exact: bool = False) -> bool:
        """Whether ``path`` is in ``shm``: it, or (absolute) the nearest folder of it that exists.

        A name missing from /dev/shm itself is the test's own to make (``exact`` off); a
        relative one missing is no path (``-q``), or one in the working directory.
        """
        absolute = path.startswith(os.sep)
        path = os.path.join(start, path)
        while True:
            try:
                if os.stat(path).st_dev != device:
                    return False
                break
            except (FileNotFoundError, NotADirectoryError):
                if not absolute:
                    return False
                path, exact = os.path.dirname(path), False
            except (OSError, ValueError):
                return False  # too long, a NUL: no path at all
        real = os.path.realpath(path)
        return real.startswith(root + os.sep) or (exact and real == root)

    found = [f"its working directory {start}"] if there(start, exact=True) else []
    written = None if result_file is None else os.path.abspath(os.path.join(start, result_file))
    if written is not None and not there(os.path.dirname(written), exact=True):
        written = None
    for index, word in enumerate(command):
        for piece in _pieces(word):
            if written is not None and os.path.abspath(os.path.join(start, piece)) == written:
                found.append(f"its result file {piece} (the test writes it)")
                break
            if there(piece):
                found.append(f"{'its command' if index == 0 else 'its argument'} {piece}")
                break
    for name, value in sorted(env.items()):
        if name in _BOOKKEEPING:
            continue
        for entry in value.split(os.pathsep):
            # An entry that exists: a stale one is as missing outside as inside.
            if entry.startswith(named) and os.path.exists(entry) and there(entry):
                found.append(f"the entry {entry} of {name}")
                break
    return found


def cause(paths: Sequence[str]) -> str:
    """The clause naming what would be hidden: the first three, and how many more."""
    shown = [*paths[:3], *([f"{len(paths) - 3} more"] if len(paths) > 3 else [])]
    listed = shown[0] if len(shown) == 1 else f"{', '.join(shown[:-1])} and {shown[-1]}"
    return f"{listed} {'is' if len(paths) == 1 else 'are'} in the host's {SHM}, out of its reach"


__all__ = ["FIX", "GIVES", "cause", "hidden"]

"""``atomic_file``: a file replaced whole, never a device node, FIFO or socket (or a link to one).

As root, ``run --junit-xml /dev/null`` once replaced the machine's /dev/null with a
regular file. ``write_atomically`` renames a finished file into place; what is at the
path is checked before the temporary file is made and again just before the rename, so
a special file that appears meanwhile is kept too. Real FIFOs, sockets and (as root) real
device nodes; the second check is reached for real, by an audit hook that makes a FIFO
the instant the temporary file is opened, and so is the rename itself (renameat2 swaps
the names and a special file it took is swapped back), by one that makes it as the
rename is called. The control: a regular file is still replaced
atomically (a new inode, the whole content), and so is a symlink to one (the link).
"""

from __future__ import annotations

import os
import socket
import stat
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import HUNG

from ros_isolated_test.atomic_file import (
    NotReplaceableError,
    discards,
    special_kind,
    write_atomically,
)

DATA = b"<testsuites/>\n"


def _leftovers(folder: Path) -> list[str]:
    """Temporary files a write left behind (none, whatever happened)."""
    return sorted(item.name for item in folder.iterdir() if item.name.endswith(".tmp"))


def test_control_a_regular_file_is_replaced_whole_by_a_new_inode(tmp_path: Path) -> None:
    path = tmp_path / "r.xml"
    path.write_bytes(b"the old result, longer than the new one\n")
    before = os.lstat(path)
    write_atomically(path, DATA)
    after = os.lstat(path)
    assert after.st_ino != before.st_ino, "a rename puts a new file in place"
    assert stat.S_ISREG(after.st_mode) and stat.S_IMODE(after.st_mode) == 0o644
    assert path.read_bytes() == DATA
    assert _leftovers(tmp_path) == []


def test_control_a_symlink_to_a_regular_file_is_replaced_and_its_target_kept(
    tmp_path: Path,
) -> None:
    target = tmp_path / "target.xml"
    target.write_bytes(b"target\n")
    link = tmp_path / "r.xml"
    link.symlink_to(target)
    assert special_kind(link) is None and not discards(link)
    write_atomically(link, DATA)
    assert not link.is_symlink() and link.read_bytes() == DATA
    assert target.read_bytes() == b"target\n"


@pytest.fixture
def unix_socket(tmp_path: Path) -> Iterator[Path]:
    """A listening Unix socket in the test's folder."""
    path = tmp_path / "socket"
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as server:
        server.bind(str(path))
        server.listen()
        yield path


def _fifo(tmp_path: Path) -> Path:
    path = tmp_path / "fifo"
    os.mkfifo(path)
    return path


@pytest.mark.parametrize("kind", ["FIFO", "socket", "symlink to a FIFO", "symlink to a socket"])
def test_a_fifo_or_socket_or_a_symlink_to_one_is_never_replaced(
    tmp_path: Path, unix_socket: Path, kind: str
) -> None:
    special = unix_socket if kind.endswith("socket") else _fifo(tmp_path)
    path = special
    if kind.startswith("symlink"):
        path = tmp_path / "link"
        path.symlink_to(special)
    before = os.lstat(path)
    assert special_kind(path) == f"a {kind}"
    assert not discards(path)
    with pytest.raises(NotReplaceableError) as raised:
        write_atomically(path, DATA)
    assert f"it is a {kind}" in str(raised.value) and str(path) in str(raised.value)
    after = os.lstat(path)
    assert (after.st_ino, after.st_mode) == (before.st_ino, before.st_mode)
    assert _leftovers(tmp_path) == []


def test_the_one_special_file_named_as_replacing_may_go(tmp_path: Path) -> None:
    """The test's own FIFO, kept aside (a hard link) before its canonical form replaces it."""
    path = _fifo(tmp_path)
    kept = tmp_path / "fifo.orig"
    os.link(path, kept)
    other = tmp_path / "another fifo"
    os.mkfifo(other)
    with pytest.raises(NotReplaceableError):
        write_atomically(path, DATA, replacing=os.lstat(other))
    assert stat.S_ISFIFO(os.lstat(path).st_mode)
    write_atomically(path, DATA, replacing=os.lstat(kept))
    assert path.read_bytes() == DATA
    assert stat.S_ISFIFO(os.lstat(kept).st_mode), "the node itself is kept"


#: Writes through write_atomically; the instant its temporary file is opened (after the
#: check at the start), an audit hook makes a FIFO at the path, or, with "file", a regular
#: file. argv: path, what appears. Prints "written" or "refused: <why>".
APPEARS_MEANWHILE = """
import os, sys
from pathlib import Path
from ros_isolated_test.atomic_file import NotReplaceableError, write_atomically
path, what = Path(sys.argv[1]), sys.argv[2]
done = []
def hook(event, args):
    if event == "open" and not done and str(args[0]).endswith(".tmp"):
        done.append(1)
        if what == "fifo":
            os.mkfifo(path)
        else:
            path.write_bytes(b"appeared")
sys.addaudithook(hook)
try:
    write_atomically(path, b"data")
except NotReplaceableError as error:
    print("refused:", error)
else:
    print("written")
print("hooked" if done else "never hooked")
"""


def _write_while(script: str, path: Path, what: str) -> tuple[str, str]:
    """Run ``script`` (a write with an audit hook that makes ``what`` appear): its two lines."""
    proc = subprocess.run(
        [sys.executable, "-c", script, str(path), what],
        capture_output=True, text=True, timeout=HUNG, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    said, second = proc.stdout.splitlines()
    return said, second


@pytest.mark.parametrize("what", ["fifo", "file"])
def test_a_fifo_that_appears_during_the_write_is_not_replaced_either(
    tmp_path: Path, what: str
) -> None:
    """The check is made again just before the rename (a FIFO made meanwhile is kept).

    The control: a regular file that appears at the same instant is replaced.
    """
    path = tmp_path / "r.xml"
    said, hooked = _write_while(APPEARS_MEANWHILE, path, what)
    assert hooked == "hooked", "the FIFO must appear after the first check"
    if what == "fifo":
        assert said.startswith("refused: ") and "it is a FIFO" in said, said
        assert stat.S_ISFIFO(os.lstat(path).st_mode)
    else:
        assert said == "written", said
        assert path.read_bytes() == b"data"
    assert _leftovers(tmp_path) == []


#: As APPEARS_MEANWHILE, but the FIFO (or file) appears at the last instant, after every
#: check: as os.rename is called, or as renameat2 is looked up in the C library, which the
#: first write of a process does just before calling it. argv: path, what appears. Prints
#: "written" or "refused: <why>", then the inode of what appeared.
APPEARS_AT_THE_RENAME = """
import os, sys
from pathlib import Path
from ros_isolated_test.atomic_file import NotReplaceableError, write_atomically
path, what = Path(sys.argv[1]), sys.argv[2]
opened, made = [], []
def hook(event, args):
    if event == "open" and str(args[0]).endswith(".tmp"):
        opened.append(1)
    elif opened and not made and (event == "os.rename" or args[1:2] == ("renameat2",)):
        if what == "fifo":
            os.mkfifo(path)
        else:
            path.write_bytes(b"appeared")
        made.append(os.lstat(path).st_ino)
sys.addaudithook(hook)
try:
    write_atomically(path, b"data")
except NotReplaceableError as error:
    print("refused:", error)
else:
    print("written")
print(made[0] if made else "never hooked")
"""


@pytest.mark.parametrize("what", ["fifo", "file"])
def test_a_fifo_that_appears_as_the_rename_is_called_is_not_replaced_either(
    tmp_path: Path, what: str
) -> None:
    """No window between the last check and the rename: the rename decides by what it took.

    The control: a regular file that appears at the same instant is replaced.
    """
    path = tmp_path / "r.xml"
    said, made = _write_while(APPEARS_AT_THE_RENAME, path, what)
    assert made != "never hooked", "nothing appeared at the rename"
    if what == "fifo":
        assert said.startswith("refused: ") and "it is a FIFO" in said, said
        found = os.lstat(path)
        assert stat.S_ISFIFO(found.st_mode) and found.st_ino == int(made), "not the same FIFO"
    else:
        assert said == "written", said
        assert path.read_bytes() == b"data"
    assert _leftovers(tmp_path) == []


def _mknod_char(path: Path, major: int, minor: int) -> Path:
    os.mknod(path, 0o666 | stat.S_IFCHR, os.makedev(major, minor))
    return path


@capabilities.ROOT
@pytest.mark.parametrize(
    ("name", "device", "null"),
    [("null", (1, 3), True), ("zero", (1, 5), False)],
)
def test_a_device_node_is_never_replaced_and_only_the_null_device_discards(
    tmp_path: Path, name: str, device: tuple[int, int], null: bool
) -> None:
    """A node of the null device (1:3) anywhere, and a symlink to it, discard what is written."""
    node = _mknod_char(tmp_path / name, *device)
    link = tmp_path / f"link-to-{name}"
    link.symlink_to(node)
    for path, kind in ((node, "a character device"), (link, "a symlink to a character device")):
        assert discards(path) is null
        assert special_kind(path) == kind
        with pytest.raises(NotReplaceableError):
            write_atomically(path, DATA)
    found = os.lstat(node)
    assert stat.S_ISCHR(found.st_mode) and found.st_rdev == os.makedev(*device)
    assert link.is_symlink() and os.readlink(link) == str(node)
    assert _leftovers(tmp_path) == []


def test_the_systems_null_device_discards_and_a_regular_file_does_not(tmp_path: Path) -> None:
    assert discards(Path(os.devnull))
    path = tmp_path / "r.xml"
    assert not discards(path)  # nothing there
    path.write_bytes(DATA)
    assert not discards(path) and special_kind(path) is None

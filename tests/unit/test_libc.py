"""``libc``: prctl and renameat2 through ``_ctypes``, checked against what the kernel did.

Each call is judged by its effect, read back another way (``/proc``, the files), never
by its return value alone; the failing calls are the controls that the return value
and errno mean something.
"""

from __future__ import annotations

import errno
import os
import signal
from pathlib import Path

from ros_isolated_test import libc

_PR_SET_PDEATHSIG, _PR_GET_PDEATHSIG = 1, 2
_AT_FDCWD, _RENAME_NOREPLACE, _RENAME_EXCHANGE = -100, 1, 2


def test_prctl_sets_the_death_signal_that_the_kernel_then_reports() -> None:
    read_back, write_back = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: set, read back, report, exit without Python's teardown
        call = libc.prctl()
        code = 1 if call is None else call(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0)
        os.write(write_back, f"{code} {libc.prctl_get_int(_PR_GET_PDEATHSIG)}".encode())
        os._exit(0)
    os.close(write_back)
    said = os.read(read_back, 100).decode()
    os.waitpid(pid, 0)
    assert said == f"0 {int(signal.SIGTERM)}"


def test_a_refused_prctl_returns_minus_one_and_sets_errno() -> None:
    call = libc.prctl()
    assert call is not None
    assert call(_PR_SET_PDEATHSIG, 9999, 0) == -1  # no such signal
    assert libc.errno() == errno.EINVAL


def test_renameat2_exchanges_and_refuses_to_replace(tmp_path: Path) -> None:
    call = libc.renameat2()
    assert call is not None
    first, second = tmp_path / "first", tmp_path / "second"
    first.write_text("one")
    second.write_text("two")
    names = os.fsencode(first), os.fsencode(second)
    assert call(_AT_FDCWD, names[0], _AT_FDCWD, names[1], _RENAME_EXCHANGE) == 0
    assert (first.read_text(), second.read_text()) == ("two", "one")
    # The control: without EXCHANGE and with NOREPLACE, the same rename is refused.
    assert call(_AT_FDCWD, names[0], _AT_FDCWD, names[1], _RENAME_NOREPLACE) == -1
    assert libc.errno() == errno.EEXIST
    assert (first.read_text(), second.read_text()) == ("two", "one")


def test_a_function_the_c_library_lacks_is_none() -> None:
    assert libc._bind("no_such_function_in_any_libc", ()) is None
    assert libc.prctl() is not None  # the control: one it has

"""The C library calls Python's ``os`` lacks on a test's path: prctl and renameat2.

Bound through ``_ctypes``, the C half of ``ctypes``: its Python half costs about 0.8 ms
to import, and the RUNNER would pay that for every test it starts. Each function is
looked up once, on first use; one the C library lacks is None.
"""

from __future__ import annotations

import _ctypes

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from collections.abc import Callable

    Prctl = Callable[[int, int, int], int]
    Renameat2 = Callable[[int, bytes, int, bytes, int], int]


class _Int(_ctypes._SimpleCData):  # type: ignore[type-arg]  # C int, as ctypes.c_int
    _type_ = "i"


class _UInt(_ctypes._SimpleCData):  # type: ignore[type-arg]  # C unsigned int
    _type_ = "I"


class _ULong(_ctypes._SimpleCData):  # type: ignore[type-arg]  # C unsigned long
    _type_ = "L"


class _Text(_ctypes._SimpleCData):  # type: ignore[type-arg]  # const char *, as ctypes.c_char_p
    _type_ = "z"


class _Function(_ctypes.CFuncPtr):
    """A C function returning int that keeps errno for :func:`errno` (``use_errno=True``)."""

    _flags_ = _ctypes.FUNCFLAG_CDECL | _ctypes.FUNCFLAG_USE_ERRNO
    _restype_ = _Int


class _Process:
    """The running process's own symbols (``dlopen(NULL)``): no library search."""

    def __init__(self) -> None:
        self._handle = _ctypes.dlopen(None, 0)  # type: ignore[arg-type]  # RTLD_NOW added


_BOUND: dict[str, object] = {}


def _bind(name: str, argtypes: tuple[type, ...]) -> object:
    if name not in _BOUND:
        try:
            function = _Function((name, _Process()))  # type: ignore[arg-type]
        except (OSError, AttributeError):  # not in this C library
            _BOUND[name] = None
        else:
            function.argtypes = argtypes
            _BOUND[name] = function
    return _BOUND[name]


def prctl() -> Prctl | None:
    """``prctl(option, arg2, arg3)``, returning 0 or -1 (then :func:`errno`)."""
    return _bind("prctl", (_Int, _ULong, _ULong))  # type: ignore[return-value]


def renameat2() -> Renameat2 | None:
    """``renameat2(olddirfd, oldpath, newdirfd, newpath, flags)``; None before glibc 2.28."""
    return _bind("renameat2", (_Int, _Text, _Int, _Text, _UInt))  # type: ignore[return-value]


def errno() -> int:
    """The errno the last of these calls left (kept per thread by ``_ctypes``)."""
    return int(_ctypes.get_errno())


def prctl_get_int(option: int) -> int | None:
    """``prctl(option, &value)`` for the options that write an int back; None on failure."""
    call = prctl()
    value = _Int(0)
    if call is None or call(option, _ctypes.addressof(value), 0) != 0:
        return None
    return int(value.value)

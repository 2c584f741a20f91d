"""A test's identity across machines and runs: ``<package>/<test>``, and its stable share.

A CMake test is its package and its ctest test name (``nav2_util/test_lifecycle``); a
pytest item of an ament_python package is its package and its node id
(``my_pkg/test/test_talker.py::TestTalker::test_rate[2]``: relative to pytest's
rootdir, the package's folder where colcon runs pytest unless an ini file above it says
otherwise; the same on every machine of one checkout). One string form, split at the
first ``/``: a package name never holds one (it names a folder of the install tree; ROS
allows lowercase letters, digits and ``_``), while a test name or node id may hold
anything, ``/`` and ``::`` included, so the form is unambiguous both ways.

:func:`spread` gives a test the plan does not place (a new test, or any test when the
split is by count) its share from its identity alone: SHA-256, so every machine, every
Python and every process draws the same share (``hash()`` is salted per process).
"""

from __future__ import annotations

from ros_isolated_test import names
from ros_isolated_test.shard.digest import sha256
from ros_isolated_test.shard.spec import ShardSettingError, named

SEPARATOR = "/"
#: The testcase property a pytest item's identity is recorded under in pytest's
#: ``--junit-xml`` file (the plugin adds it), so ``report --durations`` can name the item.
PROPERTY = names.IDENTITY
#: The testcase property the plugin records the item's run time under beside it, in
#: seconds to the microsecond: pytest's own ``time`` has three decimals, so a quicker
#: item would read as 0 s.
SECONDS_PROPERTY = names.SECONDS

__all__ = [
    "PROPERTY",
    "SECONDS_PROPERTY",
    "SEPARATOR",
    "IdentityError",
    "PackageNameError",
    "checked",
    "identity",
    "split",
    "spread",
]


class IdentityError(ValueError):
    """A package or test name that cannot form an identity (empty, or a ``/`` in a package)."""


def identity(package: str, name: str) -> str:
    """The identity of test ``name`` (ctest name or pytest node id) of ``package``."""
    if not package or SEPARATOR in package:
        raise IdentityError(
            f"{package!r} is no package name: a package name is not empty and has no "
            f"{SEPARATOR!r} (the identity is <package>{SEPARATOR}<test>)"
        )
    if not name:
        raise IdentityError(f"package {package!r}: a test needs a name")
    return f"{package}{SEPARATOR}{name}"


class PackageNameError(ShardSettingError):
    """A test an entry point was asked to run in a split that no identity can name."""


def checked(package: str, name: str, origin: str = "--package-name") -> str:
    """The identity of a test an entry point runs in a split, or a one-line usage error.

    Checked when the request is read, before anything runs: a package name with a ``/``
    would otherwise surface as a traceback when the split places the test. ``origin``
    is the option that named the package.
    """
    try:
        return identity(package, name)
    except IdentityError:
        if SEPARATOR in package:
            raise PackageNameError(
                f"{named(origin, repr(package))} cannot name a test of a split: a package "
                f"name has no {SEPARATOR!r} (a test is <package>{SEPARATOR}<test> in every "
                "share); give the package's own name, as its package.xml says"
            ) from None
        raise PackageNameError(
            f"{named(origin, repr(package))}: the test {name!r} cannot be placed in a split: "
            "a package and a test each need a name; give both"
        ) from None


def split(text: str) -> tuple[str, str]:
    """``(package, name)`` of an identity: the inverse of :func:`identity`."""
    package, separator, name = text.partition(SEPARATOR)
    if not separator or not package or not name:
        raise IdentityError(f"{text!r} is not <package>{SEPARATOR}<test>")
    return package, name


def spread(text: str, total: int) -> int:
    """The share, from 1 to ``total``, that the identity ``text`` draws by its hash alone.

    The first 8 bytes of the identity's SHA-256 (UTF-8; a name that was not UTF-8 keeps
    its surrogates, encoded as they are), modulo ``total``: uniform enough for up to
    1000 shares that no share is favoured by more than one part in 10^16.
    """
    digest = sha256(text.encode("utf-8", "surrogatepass"))
    return int.from_bytes(digest[:8], "big") % total + 1

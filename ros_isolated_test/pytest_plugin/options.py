"""The pytest plugin's options, and the rules that turn it on for a run.

Apart from holding.py, which reserves and releases: this is what every pytest run in the
environment reads, active or not, so it imports nothing but pytest (and ``switches``,
the on/off words, to read the ini option). On: asked for (``--ros-isolation``
or the ``ros_isolation`` ini option), machine resources requested, or, automatically,
inside a ROS package (a package.xml at or above the rootdir or the test paths).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from ros_isolated_test import names

INI = "ros_isolation"
#: The session's request of machine resources: the ini option and its command-line twin.
RESOURCES_INI = "ros_isolated_test_resources"
RESOURCES_OPTION = "--ros-isolated-test-resources"
#: The session's share of a split (shard.py reads it).
SHARD_OPTION = "--ros-isolated-test-shard"
#: Options that run no test (as --help): nothing is reserved for them.
_NO_TEST_OPTIONS = ("help", "markers", "showfixtures", "show_fixtures_per_test", "collectonly")
#: The session's package.xml, found once (:func:`manifest`).
_MANIFEST: pytest.StashKey[Path | None] = pytest.StashKey()


def split_asked(config: pytest.Config) -> tuple[bool, str | None]:
    """Whether the session is asked to split, and its option's value (None: not given).

    ``ROS_ISOLATED_TEST_SHARD`` is read here, outside ``runner.settings``, because every
    pytest run asks and only a split may load the runner; its value is parsed there.
    """
    option: str | None = config.getoption("ros_isolated_test_shard")
    return option is not None or bool(os.environ.get(names.SHARD, "").strip()), option


def add(parser: pytest.Parser) -> None:
    """The options and ini options (the plugin's ``pytest_addoption``)."""
    group = parser.getgroup("ros_isolated_test", "ROS isolation (ros-isolated-test)")
    group.addoption(
        "--ros-isolation",
        action="store_const",
        const=True,
        dest="ros_isolation",
        default=None,
        help="reserve a ROS_DOMAIN_ID of its own for this session (each xdist worker), "
        "also outside a ROS package; a preset ROS_DOMAIN_ID is then refused",
    )
    group.addoption(
        "--no-ros-isolation",
        action="store_const",
        const=False,
        dest="ros_isolation",
        help="never reserve a ROS_DOMAIN_ID (as -p no:ros_isolated_test)",
    )
    parser.addini(
        INI,
        "ROS isolation: auto (default: on inside a ROS package), true, or false",
        default="auto",
    )
    resources_help = (
        "machine resources the session holds with its ROS_DOMAIN_ID until pytest ends, "
        "waiting until every runner on the machine has left enough free, e.g. "
        "cpu=2,mem=4G,gpu=1 (capacity: ROS_ISOLATED_TEST_CAPACITY); a request turns "
        "isolation on outside a ROS package too, as --ros-isolation does. With "
        "pytest-xdist each worker holds them (-n 4 with gpu=1 holds 4 GPUs), the "
        "controller nothing"
    )
    group.addoption(
        RESOURCES_OPTION,
        dest="ros_isolated_test_resources",
        metavar="SPEC",
        default=None,
        help=f"{resources_help}; wins over the ini option {RESOURCES_INI}",
    )
    parser.addini(RESOURCES_INI, f"{resources_help}; {RESOURCES_OPTION} wins", default="")
    group.addoption(
        SHARD_OPTION,
        dest="ros_isolated_test_shard",
        metavar="I/N",
        default=None,
        help="run only share I of N of the collected tests (a split over N machines), "
        "balanced by ROS_ISOLATED_TEST_DURATIONS; the others are deselected; wins over "
        "ROS_ISOLATED_TEST_SHARD",
    )


def decide(config: pytest.Config) -> bool | None:
    """Whether the plugin isolates this run: None not at all, else if asked for explicitly.

    True: ``--ros-isolation``, the ini option, or resources requested (held as with
    ``--ros-isolation``). False: automatic, inside a ROS package. A run of no test
    (``--help``, ``--collect-only``, ...) is never isolated.
    """
    if any(getattr(config.option, name, False) for name in _NO_TEST_OPTIONS):
        return None  # --help, --markers, --fixtures, --collect-only: no test runs
    requested = _requested(config)
    if requested is None and not _in_ros_package(config):
        if not resources(config)[0].strip():
            return None
        requested = True  # resources asked for: held as with --ros-isolation
    if requested is False:
        return None
    return requested is True


def _requested(config: pytest.Config) -> bool | None:
    """True/False when asked for explicitly (option first, then ini); None: automatic."""
    option: bool | None = config.getoption("ros_isolation")
    if option is not None:
        return option
    from ros_isolated_test.switches import NotOnOff, on_off  # imports nothing more

    word = str(config.getini(INI)).strip().lower()
    try:
        return None if word == "auto" else on_off(word, unset=None)
    except NotOnOff:
        raise pytest.UsageError(f"ini option {INI}={word!r}: use auto, true or false") from None


def resources(config: pytest.Config) -> tuple[str, str]:
    """The session's request ("": none) and where it was given, which its error names."""
    option: str | None = config.getoption("ros_isolated_test_resources")
    if option is not None:
        return option, RESOURCES_OPTION
    return str(config.getini(RESOURCES_INI)), f"ini option {RESOURCES_INI}"


def _in_ros_package(config: pytest.Config) -> bool:
    """A package.xml at or above the rootdir or a path on the command line: colcon's case."""
    return manifest(config) is not None


def manifest(config: pytest.Config) -> Path | None:
    """The session's ``package.xml``: at or above the rootdir, else above a test path.

    Walked once per session (kept in the config's stash): it both switches the plugin on
    and names the package of the session's items (``sharding.package_name``).
    """
    if _MANIFEST in config.stash:
        return config.stash[_MANIFEST]
    found = None
    starts = [config.rootpath, *(Path(arg.split("::")[0]) for arg in config.args)]
    seen: set[Path] = set()
    for start in starts:
        folder = start.absolute()
        for candidate in (folder, *folder.parents):
            if candidate in seen:
                break
            seen.add(candidate)
            if (candidate / "package.xml").is_file():
                found = candidate / "package.xml"
                break
        if found is not None:
            break
    config.stash[_MANIFEST] = found
    return found

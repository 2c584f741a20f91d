"""The runner's own settings: read from arguments and the environment once, checked once.

Every entry point (``run``, the ctest RUNNER script, ``status``) builds one
:class:`Settings` here, before anything else happens, and hands it on: nothing deeper
(policy, coordinator, status) reads a ros-isolated-test variable itself, so a variable
has one parser, one error message and one meaning everywhere. An option given on the
command line wins over its variable, and the variable is then not read at all. Entry
points that never rerun (``status``, the pytest plugin) pass ``reruns=0`` for that
reason: a bad ROS_ISOLATED_TEST_RERUNS exported for ``run`` must not break them.

A split's variables (``ROS_ISOLATED_TEST_SHARD``, ``ROS_ISOLATED_TEST_DURATIONS``) are
read here too (:func:`split`, :func:`machine_share`, :func:`durations_file`), for every
entry point: ``run``, the RUNNER, ``report``, ``shard``, the pytest plugin and the colcon
summary. The ``shard`` package parses what it is handed and reads no variable itself.
One exception: the pytest plugin's ``options.split_asked`` looks whether
``ROS_ISOLATED_TEST_SHARD`` is set at all, since every pytest run asks and only a split
may load the runner; the value is still parsed here (:func:`split`).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

from ros_isolated_test import names, not_run
from ros_isolated_test.domain_coordinator.lock_dir import LOCK_DIR_ENV, lock_dir_from_env
from ros_isolated_test.domain_coordinator.pool import (
    LINUX_DEFAULT_PORT_RANGE,
    POOL_ENV,
    PoolSpecError,
    choose_pool,
)
from ros_isolated_test.domain_coordinator.resources import (
    CAPACITY_ENV,
    RESOURCES_ENV,
    ResourceSpecError,
    capacity_for,
    describe,
    parse,
    show_amount,
)
from ros_isolated_test.runner import discovery, partition
from ros_isolated_test.switches import NotOnOff, on_off

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from collections.abc import Mapping

    from ros_isolated_test.shard.selection import Selection
    from ros_isolated_test.shard.spec import Share

WAIT_TIMEOUT_ENV = names.WAIT_TIMEOUT
DEFAULT_WAIT_TIMEOUT = 600.0
DISCOVERY_RANGE_ENV = discovery.OVERRIDE_ENV
#: How many times a failed test runs again (``run --rerun-failures``; CMake's ``RERUNS``).
RERUNS_ENV = names.RERUNS
#: How many times a failed test runs again when the test history calls it flaky
#: (``run --rerun-flaky``): reruns where they are needed, not for every failure.
RERUNS_FLAKY_ENV = names.RERUNS_FLAKY
#: The most reruns allowed: every attempt's result is kept in memory until the merge, and
#: a flake that needs more than this is a failure to fix, not to retry.
MAX_RERUNS = 100
DISABLE_VAR = names.DISABLE
#: How a test is kept apart (``run --isolation``; the RUNNER also reads it from ``--env``).
ISOLATION_ENV = names.ISOLATION
#: ``domain``: a reserved ROS_DOMAIN_ID (the default); ``namespace``: Linux namespaces of
#: the test's own too, no waiting for an ID; ``auto``: namespace where allowed, else domain.
ISOLATION_MODES = ("domain", "namespace", "auto")
DEFAULT_ISOLATION = "domain"
#: The test history database that ``run`` and the pytest plugin record into (``history``).
HISTORY_ENV = names.HISTORY

__all__ = [
    "CAPACITY_ENV",
    "DEFAULT_ISOLATION",
    "DEFAULT_WAIT_TIMEOUT",
    "DISABLE_VAR",
    "DISCOVERY_RANGE_ENV",
    "HISTORY_ENV",
    "ISOLATION_ENV",
    "ISOLATION_MODES",
    "LOCK_DIR_ENV",
    "MAX_RERUNS",
    "POOL_ENV",
    "RERUNS_ENV",
    "RERUNS_FLAKY_ENV",
    "RESOURCES_ENV",
    "WAIT_TIMEOUT_ENV",
    "Settings",
    "SettingsError",
    "defaults",
    "disables_isolation",
    "history_database",
    "isolation_from",
    "read",
    "reruns_from",
    "resources_from",
]


class SettingsError(not_run.NotRun, ValueError):
    """A setting that cannot be used: one line naming the option or variable and the fix."""


class Settings:
    """What the runner was configured to do, whoever configured it."""

    __slots__ = (
        "capacity",
        "discovery_range",
        "gz_partition",
        "isolation",
        "isolation_disabled",
        "isolation_origin",
        "lock_dir",
        "notes",
        "pool",
        "reruns",
        "reruns_flaky",
        "resources",
        "wait_timeout",
    )

    def __init__(
        self,
        *,
        lock_dir: Path,
        pool: tuple[int, ...],
        wait_timeout: float = DEFAULT_WAIT_TIMEOUT,
        discovery_range: str | None = None,
        isolation_disabled: bool = False,
        notes: tuple[str, ...] = (),
        reruns: int = 0,
        reruns_flaky: int = 0,
        gz_partition: bool = True,
        resources: dict[str, int] | None = None,
        capacity: dict[str, int] | None = None,
        isolation: str = DEFAULT_ISOLATION,
        isolation_origin: str = ISOLATION_ENV,
    ) -> None:
        #: The shared lock directory (ROS_ISOLATED_TEST_LOCK_DIR).
        self.lock_dir = lock_dir
        #: The IDs to hand out (ROS_ISOLATED_TEST_DOMAINS).
        self.pool = pool
        #: Seconds to wait for a free ID (--wait-timeout, ROS_ISOLATED_TEST_WAIT_TIMEOUT).
        self.wait_timeout = wait_timeout
        #: A checked range name (--discovery-range, its variable), None: the default policy.
        self.discovery_range = discovery_range
        #: DISABLE_ROS_ISOLATION in the runner's own environment.
        self.isolation_disabled = isolation_disabled
        #: One line each, said before the test runs and kept in the result file: what the
        #: settings changed on their own (IDs left out of the default pool) or warn about.
        self.notes = notes
        #: How many more times a failed test runs (--rerun-failures, ROS_ISOLATED_TEST_RERUNS).
        self.reruns = reruns
        #: How many more times a failed test runs when the history calls it flaky
        #: (--rerun-flaky, ROS_ISOLATED_TEST_RERUNS_FLAKY); the larger of the two counts.
        self.reruns_flaky = reruns_flaky
        #: Give each test a Gazebo transport partition of its own (ROS_ISOLATED_TEST_GZ_PARTITION).
        self.gz_partition = gz_partition
        #: What the test holds besides its ID (--resources, ROS_ISOLATED_TEST_RESOURCES):
        #: {name: amount}, mem in bytes; empty: nothing.
        self.resources = resources or {}
        #: The capacity of every resource named in ROS_ISOLATED_TEST_CAPACITY or asked for
        #: (the default where the variable is silent): what all runners must agree on.
        self.capacity = capacity or {}
        #: One of :data:`ISOLATION_MODES` (--isolation, ROS_ISOLATED_TEST_ISOLATION), and
        #: where it was given, for messages.
        self.isolation = isolation
        self.isolation_origin = isolation_origin

    def __repr__(self) -> str:
        return (
            f"Settings(lock_dir={self.lock_dir!r}, pool={len(self.pool)} IDs, "
            f"wait_timeout={self.wait_timeout!r}, discovery_range={self.discovery_range!r}, "
            f"isolation_disabled={self.isolation_disabled!r}, isolation={self.isolation!r}, "
            f"reruns={self.reruns!r}, "
            f"resources={describe(self.resources)!r})"
        )


def history_database(environ: Mapping[str, str] | None = None) -> Path | None:
    """The history database ``ROS_ISOLATED_TEST_HISTORY`` names; None when unset or empty."""
    value = (os.environ if environ is None else environ).get(HISTORY_ENV, "")
    return Path(value) if value else None


def history_to_record(environ: Mapping[str, str] | None = None) -> Path | None:
    """The database ``run`` or the plugin records its own results into; None: not theirs.

    None also under ``colcon test`` with our extension on (it sets
    ``ROS_ISOLATED_TEST_HISTORY_BY_COLCON``): colcon records the whole run as one, and a
    test or session recorded on its own as well would be a run of its own beside it.
    """
    environ = os.environ if environ is None else environ
    if environ.get(names.HISTORY_BY_COLCON, ""):
        return None
    return history_database(environ)


def split(
    option: str | None = None,
    origin: str = "--shard",
    environ: Mapping[str, str] | None = None,
) -> Selection | None:
    """The split an entry point runs under; None: no split, and nothing of it loaded.

    From ``option`` (given as ``origin``), else ``ROS_ISOLATED_TEST_SHARD``, balanced by
    ``ROS_ISOLATED_TEST_DURATIONS``. Raises
    :class:`~ros_isolated_test.shard.spec.ShardSettingError` (one line naming the
    variable or option) for a bad share or durations file.
    """
    environ = os.environ if environ is None else environ
    if not split_asked(option, environ):
        return None
    from ros_isolated_test.shard.selection import select

    return select(environ, option, shard_origin=origin)


def split_asked(option: str | None = None, environ: Mapping[str, str] | None = None) -> bool:
    """Whether a split is asked for, by ``option`` or ``ROS_ISOLATED_TEST_SHARD`` (not blank)."""
    environ = os.environ if environ is None else environ
    return option is not None or bool(environ.get(names.SHARD, "").strip())


def machine_share(environ: Mapping[str, str] | None = None) -> Share | None:
    """The share ``ROS_ISOLATED_TEST_SHARD`` gives this machine (a report expects it alone)."""
    from ros_isolated_test.shard.spec import share_from

    return share_from(os.environ if environ is None else environ)


def durations_file(
    option: str | None = None,
    origin: str = "--durations",
    environ: Mapping[str, str] | None = None,
) -> tuple[Path, str] | None:
    """The durations file named: ``option``, else ``ROS_ISOLATED_TEST_DURATIONS``; by what."""
    from ros_isolated_test.shard import selection

    return selection.durations_file(os.environ if environ is None else environ, option, origin)


def disables_isolation(value: str | None) -> bool:
    """DISABLE_ROS_ISOLATION as upstream reads it (set means disabled), except explicit no's.

    Unset or blank does not disable; nor does an off word; any other value does.
    """
    try:
        return on_off(value, unset=False)
    except NotOnOff:
        return True


def isolation_from(text: str, origin: str = ISOLATION_ENV) -> str:
    """An isolation mode (lower case), or :class:`SettingsError` naming ``origin``."""
    value = text.strip().lower()
    if value not in ISOLATION_MODES:
        raise SettingsError(
            f"{origin}={text!r} is not an isolation mode; use one of "
            f"{', '.join(ISOLATION_MODES)} (default {DEFAULT_ISOLATION})"
        )
    return value


def _seconds(text: str, name: str, fix: str) -> float:
    """A finite, non-negative number of seconds, or :class:`SettingsError` naming ``name``.

    nan and inf are refused: either would silently turn a limit off.
    """
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not (math.isfinite(value) and value >= 0):
        raise SettingsError(f"{name}={text!r} is not a number of seconds; {fix}")
    return value


def reruns_from(text: str, origin: str = RERUNS_ENV) -> int:
    """A count of reruns (0 to :data:`MAX_RERUNS`), or :class:`SettingsError` naming ``origin``.

    Whole numbers only: "1.5" or "-1" is a typo, never silently rounded or ignored.
    """
    value = text.strip()
    # Checked by length first: int() refuses (ValueError) strings of thousands of digits.
    if (
        not (value.isdigit() and value.isascii() and len(value.lstrip("0")) <= 3)
        or int(value) > MAX_RERUNS
    ):
        raise SettingsError(
            f"{origin}={text!r} is not a number of reruns; set a whole number from 0 to "
            f"{MAX_RERUNS} (e.g. 2), or unset it"
        )
    return int(value)


def resources_from(
    text: str, origin: str, capacity: dict[str, int], capacity_origin: str = CAPACITY_ENV
) -> dict[str, int]:
    """A request checked against ``capacity``: one above it is refused now, never waited for."""
    try:
        request = parse(text, origin)
    except ResourceSpecError as error:
        raise SettingsError(str(error)) from None
    for name, amount in request.items():
        have = capacity_for([name], capacity)[name]
        if amount > have:
            where = "as set in " + capacity_origin if name in capacity else "by default"
            raise SettingsError(
                f"{origin}: {name}={show_amount(name, amount)} is more than this machine's "
                f"capacity of {name}, {show_amount(name, have)} ({where}); ask for less, or "
                f"raise it with {CAPACITY_ENV}={name}=<amount> for every runner"
            )
    return request


def read(
    environ: Mapping[str, str] | None = None,
    *,
    wait_timeout: float | None = None,
    discovery_range: str | None = None,
    port_range: tuple[int, int] | None = None,
    reruns: int | None = None,
    resources: str | None = None,
    resources_origin: str = "--resources",
    isolation: str | None = None,
    reruns_flaky: int | None = None,
) -> Settings:
    """The settings from options (None: not given) and ``environ`` (default: os.environ).

    ``port_range``: the ephemeral port range the pool must keep clear of; None reads this
    network namespace's. ``resources``: the request as given by an option ("" for an entry
    point that asks for none); None reads ROS_ISOLATED_TEST_RESOURCES. ``resources_origin``
    names where that string came from, in its error (the RUNNER's ``--env``, a pytest option).
    ``isolation``: ``--isolation`` as given; None reads ROS_ISOLATED_TEST_ISOLATION.
    Raises :class:`SettingsError` for a value that cannot be used.
    """
    environ = os.environ if environ is None else environ
    if wait_timeout is None:
        text = environ.get(WAIT_TIMEOUT_ENV, "").strip()
        wait_timeout = DEFAULT_WAIT_TIMEOUT
        if text:
            wait_timeout = _seconds(text, WAIT_TIMEOUT_ENV, "set e.g. 600, or unset it")
    if discovery_range is not None:
        origin = "--discovery-range"
    else:
        discovery_range = environ.get(DISCOVERY_RANGE_ENV, "").strip() or None
        origin = DISCOVERY_RANGE_ENV
    if discovery_range is not None:
        try:
            discovery_range = discovery.check_range(discovery_range, origin)
        except discovery.DiscoveryError as error:
            raise SettingsError(str(error)) from None
    if reruns is None:
        text = environ.get(RERUNS_ENV, "")
        reruns = reruns_from(text) if text.strip() else 0
    if reruns_flaky is None:
        text = environ.get(RERUNS_FLAKY_ENV, "")
        reruns_flaky = reruns_from(text, RERUNS_FLAKY_ENV) if text.strip() else 0
    try:
        explicit = parse(environ.get(CAPACITY_ENV, ""), CAPACITY_ENV)
    except ResourceSpecError as error:
        raise SettingsError(str(error)) from None
    if resources is None:
        request = resources_from(environ.get(RESOURCES_ENV, ""), RESOURCES_ENV, explicit)
    else:
        request = resources_from(resources, resources_origin, explicit)
    if isolation is not None:
        mode, mode_origin = isolation_from(isolation, "--isolation"), "--isolation"
    else:
        text = environ.get(ISOLATION_ENV, "")
        mode = isolation_from(text) if text.strip() else DEFAULT_ISOLATION
        mode_origin = ISOLATION_ENV
    try:
        gz_partition = partition.enabled(environ.get(partition.OPT_OUT_ENV))
    except partition.PartitionSettingError as error:
        raise SettingsError(str(error)) from None
    try:
        pool, notes = choose_pool(environ, port_range)
    except PoolSpecError as error:
        raise SettingsError(str(error)) from None
    return Settings(
        lock_dir=lock_dir_from_env(environ),
        pool=pool,
        wait_timeout=wait_timeout,
        discovery_range=discovery_range,
        isolation_disabled=disables_isolation(environ.get(DISABLE_VAR)),
        notes=notes,
        reruns=reruns,
        reruns_flaky=reruns_flaky,
        gz_partition=gz_partition,
        resources=request,
        capacity={**explicit, **capacity_for(request, explicit)},
        isolation=mode,
        isolation_origin=mode_origin,
    )


def defaults() -> Settings:
    """The built-in settings, no variable read: for a request that never runs.

    A usage error's result file needs a request, and must not fail on (or report) a
    bad variable the user never got to, nor on this host's port range.
    """
    return read({}, port_range=LINUX_DEFAULT_PORT_RANGE)

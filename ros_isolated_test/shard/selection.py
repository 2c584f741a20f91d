"""What one machine of a split runs: the API every entry point calls.

An entry point (the ctest RUNNER, ``run``, the pytest plugin) reads the split once per
process with :func:`select`, which gives None when there is no split, then asks
:meth:`Selection.runs` for each test it would start: True for its own share's tests.
The file is read and planned once per :class:`Selection`; a RUNNER asks once, the plugin
once per item. :meth:`Selection.properties` is what its results record, so a merge of
the machines' results can tell a missing share, a test run twice, and machines that
planned from different files.
"""

from __future__ import annotations

from pathlib import Path

from ros_isolated_test import names
from ros_isolated_test.shard.durations import DURATIONS_ENV, Durations, load
from ros_isolated_test.shard.identity import identity
from ros_isolated_test.shard.plan import Plan
from ros_isolated_test.shard.spec import ShardSettingError, Share, named, share_from
from ros_isolated_test.text import display_text

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from collections.abc import Mapping

#: The plan's name in results when there is no durations file.
BY_COUNT = "count"
#: The result-file properties a share is recorded under.
SHARD_PROPERTY = names.SHARD_PROPERTY
PLAN_PROPERTY = names.SHARD_PLAN

__all__ = [
    "BY_COUNT",
    "PLAN_PROPERTY",
    "SHARD_PROPERTY",
    "Selection",
    "durations_file",
    "select",
]


class Selection:
    """A machine's share of a split, and the plan every machine computes alike."""

    __slots__ = ("durations_file", "plan", "share")

    def __init__(
        self, share: Share, durations: Durations | None, durations_file: Path | None = None
    ) -> None:
        self.share = share
        self.plan = Plan(share.total, durations)
        #: The file the durations were read from, to name in messages.
        self.durations_file = durations_file

    @property
    def plan_name(self) -> str:
        """The durations file's fingerprint, or ``count`` when there is none."""
        durations = self.plan.durations
        return BY_COUNT if durations is None else durations.fingerprint

    def runs(self, package: str, name: str) -> bool:
        """Whether this share runs test ``name`` (ctest name, pytest node id) of ``package``."""
        return self.plan.share_of(identity(package, name)) == self.share.index

    def share_of(self, package: str, name: str) -> int:
        """The share that runs the test: this one's index or another's."""
        return self.plan.share_of(identity(package, name))

    def not_here(self, package: str, name: str) -> str:
        """One line saying why a test is not run here: ``not in shard 2/4 (shard 3 runs it ...``."""
        other = self.share_of(package, name)
        how = "by count" if self.plan.by_count else f"plan {self.plan_name}"
        return f"not in shard {self.share} (shard {other}/{self.share.total} runs it; {how})"

    def properties(self) -> dict[str, str]:
        """What a result of this share records: ``shard`` (``I/N``) and ``shard_plan``."""
        return {SHARD_PROPERTY: str(self.share), PLAN_PROPERTY: self.plan_name}


def select(
    environ: Mapping[str, str],
    shard: str | None = None,
    durations: str | None = None,
    *,
    shard_origin: str = "--shard",
    durations_origin: str = "--durations",
) -> Selection | None:
    """The split an entry point runs under; None when there is none.

    ``shard`` and ``durations`` are its options' values (None: not given), which win
    over ``ROS_ISOLATED_TEST_SHARD`` and ``ROS_ISOLATED_TEST_DURATIONS``; a variable an
    option overrides is not read. Without a share the durations are not read either
    (:func:`durations_file` says which file is named).
    Raises :class:`~ros_isolated_test.shard.spec.ShardSettingError` (one line naming
    the variable or option and the fix) for a bad share or durations file.
    """
    share = share_from(environ, shard, shard_origin)
    if share is None:
        return None
    named_file = durations_file(environ, durations, durations_origin)
    if named_file is None:
        return Selection(share, None)
    path, origin = named_file
    return Selection(share, load(path, origin), path)


def durations_file(
    environ: Mapping[str, str], option: str | None = None, origin: str = "--durations"
) -> tuple[Path, str] | None:
    """The durations file named, and by what: the option's value, else the variable.

    None when neither names one (unset or blank). The variable must hold an absolute
    path: ctest starts each test in a folder of its own, so a relative one would name a
    different file for each; an option is relative to where its command was started.
    """
    if option is not None and option.strip():
        return Path(option), origin
    value = environ.get(DURATIONS_ENV)
    if option is not None or value is None or not value.strip():
        return None
    path = Path(value)
    if not path.is_absolute():
        raise ShardSettingError(
            f"{named(DURATIONS_ENV, display_text(value))} is not an absolute path: every test "
            f"starts in a folder of its own, so name the file from the root (e.g. $PWD/{value})"
        )
    return path, DURATIONS_ENV

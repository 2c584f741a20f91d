"""A pytest session's share of a split: other shares' items deselected, every item named.

colcon runs an ament_python package's tests with pytest directly, so no RUNNER decides
for them: the plugin splits such a package test by test. With ``ROS_ISOLATED_TEST_SHARD=I/N``
(or ``--ros-isolated-test-shard I/N``, which wins) each collected item is placed by its
identity, ``<package>/<node id>`` (the package from the ``package.xml`` at or above the
rootdir, the name colcon knows it by), under the same plan every machine computes
(``shard.selection``); the others are deselected, so they are not in ``--junit-xml``
at all, and a session whose share is empty exits 0, not 5 ("no tests collected").

Every item the plugin names carries its identity as the testcase property
``ros_isolated_test_identity`` (whether split or not), so ``report --durations`` can
measure it. ``--junit-xml`` gets the suite properties ``shard`` and ``shard_plan`` and,
beside it, the machine's record (``shard.record``): a merge then knows this share
reported even when it ran nothing.

Under a RUNNER of ours (ament_add_pytest_test through the CMake include) the runner has
decided for the whole test: its ``ROS_ISOLATED_TEST_SHARD`` is not passed on, and an
explicit option is not applied either (the header says so): splitting again would run a
share of a share.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

from ros_isolated_test import __version__
from ros_isolated_test.pytest_plugin.options import SHARD_OPTION as OPTION
from ros_isolated_test.shard.identity import PROPERTY, identity
from ros_isolated_test.shard.spec import SHARD_ENV, ShardSettingError

TYPE_CHECKING = False
if TYPE_CHECKING:
    from ros_isolated_test.shard.selection import Selection

#: pytest's exit code when no test was collected; a session whose share is empty is not that.
_NO_TESTS = 5


class Sharding:
    """What the plugin decided for this session's items."""

    def __init__(self, selection: Selection | None, package: str, named: bool) -> None:
        #: The split (None: every item runs).
        self.selection = selection
        #: The package that names the items, and whether they carry their identity.
        self.package = package
        self.named = named
        self.header: list[str] = []
        self.deselected = 0

    @property
    def properties(self) -> list[tuple[str, str]]:
        """The suite properties of pytest's --junit-xml: the share and its plan."""
        return [] if self.selection is None else list(self.selection.properties().items())


def decide(config: pytest.Config, active: bool) -> Sharding | None:
    """The session's split and naming; None when the plugin neither splits nor names.

    ``active``: the plugin isolates this session (it names the items then too, so a
    later ``report --durations`` can measure them). A bad share or durations file is
    pytest's usage error, one line naming the variable or option.
    """
    if config.getoption("help", False):
        return None
    option: str | None = config.getoption("ros_isolated_test_shard")
    asked = option is not None or bool(os.environ.get(SHARD_ENV, "").strip())
    if not asked and not active:
        return None
    from ros_isolated_test.runner.environment import held_for_us

    package = package_name(config)
    if held_for_us(os.environ):
        sharding = Sharding(None, package, named=False)
        if asked:
            sharding.header.append(
                f"ros-isolated-test: {OPTION} not applied: the runner that holds this "
                "session's ID decided its share for the whole test"
            )
        return sharding
    selection = None
    if asked:
        from ros_isolated_test.shard.selection import select

        try:
            selection = select(os.environ, option, shard_origin=OPTION)
        except ShardSettingError as error:
            raise pytest.UsageError(f"ros-isolated-test: {error}") from None
    sharding = Sharding(selection, package, named=True)
    if selection is not None:
        how = "by count" if selection.plan.by_count else f"plan {selection.plan_name}"
        sharding.header.append(
            f"ros-isolated-test: shard {selection.share} ({how}): the other shares' tests "
            f"of {package} are deselected"
        )
    return sharding


def package_name(config: pytest.Config) -> str:
    """The ROS package of the session: the ``package.xml`` at or above the rootdir names it.

    Else colcon's ``--junit-prefix`` (the package name), else the rootdir's name.
    """
    for folder in (config.rootpath, *config.rootpath.parents):
        manifest = folder / "package.xml"
        if manifest.is_file():
            found = _manifest_name(manifest)
            if found:
                return found
            break
    prefix = getattr(config.option, "junitprefix", None)
    if prefix and "/" not in prefix:
        return str(prefix)
    return config.rootpath.name.replace("/", "_") or "pytest"


def _manifest_name(manifest: Path) -> str:
    """The ``<name>`` of a package.xml, or "" when it names none that can name a package."""
    from xml.etree import ElementTree

    try:
        element = ElementTree.parse(manifest).getroot().find("name")
    except (OSError, ElementTree.ParseError):
        return ""
    name = (element.text or "").strip() if element is not None else ""
    return name if re.fullmatch(r"[^/\s]+", name) else ""


def select_items(sharding: Sharding, config: pytest.Config, items: list[pytest.Item]) -> None:
    """Name every item; deselect the other shares' (``pytest_collection_modifyitems``)."""
    package = sharding.package
    if sharding.named:
        for item in items:
            item.user_properties.append((PROPERTY, identity(package, item.nodeid)))
    selection = sharding.selection
    if selection is None:
        return
    kept: list[pytest.Item] = []
    others: list[pytest.Item] = []
    for item in items:
        (kept if selection.runs(package, item.nodeid) else others).append(item)
    if others:
        sharding.deselected += len(others)
        config.hook.pytest_deselected(items=others)
        items[:] = kept


def leave_record(sharding: Sharding, config: pytest.Config) -> None:
    """Leave the machine's record beside ``--junit-xml`` (an xdist worker writes no file)."""
    selection = sharding.selection
    xmlpath = getattr(config.option, "xmlpath", None)
    if selection is None or not xmlpath or hasattr(config, "workerinput"):
        return
    from ros_isolated_test.shard import record
    from ros_isolated_test.xunit.validate import hostname

    folder = Path(os.path.abspath(os.path.expanduser(xmlpath))).parent
    try:
        record.leave(folder, selection, hostname(), __version__)
    except OSError as error:
        name = record.file_name(selection.share)
        raise pytest.UsageError(
            f"ros-isolated-test: cannot leave the shard record {name} in {folder} "
            f"({error.strerror or error}): a merge of the machines' results would not know "
            "this share reported; make the folder writable"
        ) from None


def exit_status(sharding: Sharding, config: pytest.Config, status: int) -> int:
    """The session's exit code: 0 rather than pytest's 5 when its share held none of its tests."""
    if status != _NO_TESTS or sharding.selection is None:
        return status
    controller = getattr(config.option, "dist", "no") != "no" and not hasattr(config, "workerinput")
    return 0 if sharding.deselected or controller else status

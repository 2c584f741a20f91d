"""A pytest session's share of a split: other shares' items deselected, every item named.

colcon runs an ament_python package's tests with pytest directly, so no RUNNER decides
for them: the plugin splits such a package test by test. With ``ROS_ISOLATED_TEST_SHARD=I/N``
(or ``--ros-isolated-test-shard I/N``, which wins) each collected item is placed by its
identity, ``<package>/<node id>`` (the package from the ``package.xml`` at or above the
rootdir, the name colcon knows it by), under the same plan every machine computes
(``shard.selection``); the others are deselected, so they are not in ``--junit-xml``
at all, and a session whose share is empty because of the split exits 0, not 5 ("no
tests collected"): the split places the items that pytest's own selection (``-k``,
``-m``, ...) kept, so a session that selected nothing, or a package of no tests, still
exits 5 (an xdist controller learns from its workers what the split deselected).

Every item the plugin names carries its identity as the testcase property
``ros_isolated_test_identity`` (whether split or not), and its run time (setup, call and
teardown) to the microsecond as ``ros_isolated_test_seconds``, so ``report --durations``
can measure it: pytest's own ``time`` has three decimals, a quicker item would be 0 s.
``--junit-xml`` gets the suite properties ``shard`` and ``shard_plan`` and,
beside it, the machine's record (``shard.record``): a merge then knows this share
reported even when it ran nothing. The record says ``started`` from the session's start
until pytest has written the file. The record is one per folder and share, while several
sessions of one share may write there (``pytest a --junit-xml=out/a.xml``, then ``b``):
so the session also writes, at its start, a placeholder ``--junit-xml`` (an older file
there goes), one error case in its share saying the session ended before writing its
results, which pytest's own file replaces at the end (it rewrites the file whole). A
session killed in between leaves the placeholder, which fails the merge however the
record reads.

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
from ros_isolated_test.pytest_plugin.options import split_asked
from ros_isolated_test.shard.identity import PROPERTY, SECONDS_PROPERTY, identity
from ros_isolated_test.shard.spec import ShardSettingError

TYPE_CHECKING = False
if TYPE_CHECKING:
    from ros_isolated_test.shard.selection import Selection

#: pytest's exit code when no test was collected; a session whose share is empty is not that.
_NO_TESTS = 5
#: What an xdist worker tells its controller: how many items the split deselected.
DESELECTED_KEY = "ros_isolated_test_split_deselected"
#: An item's seconds so far: its setup's and call's, until its teardown reports.
_SPENT: pytest.StashKey[float] = pytest.StashKey()


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
    asked, option = split_asked(config)
    if not asked and not active:
        return None
    from ros_isolated_test.runner import settings
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
        try:
            selection = settings.split(option, OPTION)
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
    """The ROS package of the session: its ``package.xml`` names it (``options.manifest``).

    Else colcon's ``--junit-prefix`` (the package name), else the rootdir's name.
    """
    from ros_isolated_test.pytest_plugin.options import manifest

    found = manifest(config)
    name = _manifest_name(found) if found is not None else ""
    if name:
        return name
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
    output = getattr(config, "workeroutput", None)
    if output is not None:  # an xdist worker: its controller collects nothing itself
        output[DESELECTED_KEY] = sharding.deselected


def timed(item: pytest.Item, report: pytest.TestReport) -> None:
    """The item's phases summed; its teardown's report gets the total, to the microsecond.

    pytest writes a case's properties from its teardown's report (in an xdist worker
    too, which sends the report whole), so the property lands in ``--junit-xml``.
    """
    spent = item.stash.get(_SPENT, 0.0) + report.duration
    if report.when != "teardown":
        item.stash[_SPENT] = spent
        return
    item.stash[_SPENT] = 0.0  # a rerun of the item (pytest-rerunfailures) counts anew
    report.user_properties.append((SECONDS_PROPERTY, f"{spent:.6f}"))


def worker_done(sharding: Sharding, output: dict[str, object]) -> None:
    """The xdist controller: what a worker's split deselected (each worker collects all)."""
    found = output.get(DESELECTED_KEY)
    if isinstance(found, int):
        sharding.deselected = max(sharding.deselected, found)


def _junit_file(sharding: Sharding, config: pytest.Config) -> Path | None:
    """The ``--junit-xml`` file beside which the record goes; None: no record here.

    None without a split or the option, and in an xdist worker (which writes no file).
    """
    xmlpath = getattr(config.option, "xmlpath", None)
    if sharding.selection is None or not xmlpath or hasattr(config, "workerinput"):
        return None
    return Path(os.path.abspath(os.path.expanduser(xmlpath)))


def leave_record(sharding: Sharding, config: pytest.Config) -> None:
    """Leave the machine's record, started, beside ``--junit-xml``, and the placeholder there.

    Until :func:`complete_record`, the record says the session started; until pytest
    writes its file, the placeholder (:func:`placeholder`) says this session did not end:
    killed, it leaves an error in its share, and no older file to be taken for results.
    """
    junit = _junit_file(sharding, config)
    if junit is None or sharding.selection is None:
        return
    from ros_isolated_test.shard import record
    from ros_isolated_test.xunit.validate import hostname

    folder = junit.parent
    name = record.file_name(sharding.selection.share)
    try:
        record.leave(folder, sharding.selection, hostname(), __version__, started=True)
    except OSError as error:
        raise pytest.UsageError(
            f"ros-isolated-test: cannot leave the shard record {name} in {folder} "
            f"({error.strerror or error}): a merge of the machines' results would not know "
            "this share reported; make the folder writable"
        ) from None
    from ros_isolated_test.atomic_file import special_kind, write_atomically

    if special_kind(junit) is not None:
        return  # /dev/null, a FIFO: never replaced; pytest writes into it at the end
    try:
        write_atomically(junit, placeholder(sharding, junit))
    except OSError as error:
        raise pytest.UsageError(
            f"ros-isolated-test: cannot write the placeholder --junit-xml file {junit} "
            f"({error.strerror or error}): were this session to die, a merge would not know "
            "it left no results; make the folder writable"
        ) from None


def placeholder(sharding: Sharding, junit: Path) -> bytes:
    """The result ``junit`` holds until pytest writes it: one error, in this session's share.

    Its suite carries the share's properties, so the merge counts it in its share, and is
    named ``<package>.<junit file's name>``: one test per junit file, so two sessions of
    one share writing into one folder leave two. Stamped (``placeholder_written_at``), so
    ``report --durations`` reads no run time from it.
    """
    import time

    from ros_isolated_test.report.shard import SESSION_ENDED_TYPE
    from ros_isolated_test.xunit.canonical import test_name_of
    from ros_isolated_test.xunit.model import Case, Outcome, Suite
    from ros_isolated_test.xunit.placeholder import stamped
    from ros_isolated_test.xunit.serialise import serialize
    from ros_isolated_test.xunit.validate import hostname, timestamp

    assert sharding.selection is not None
    name = f"{sharding.package}.{test_name_of(junit)}"
    message = (
        f"the pytest session of shard {sharding.selection.share} ended before writing its "
        "results (killed or crashed); run that share again"
    )
    case = Case.saying(name, "pytest session", Outcome.ERROR, message, SESSION_ENDED_TYPE)
    now = time.time()
    properties = stamped(dict(sharding.properties), now)
    return serialize(Suite(name, [case], 0.0, timestamp(now), hostname(), properties))


def complete_record(sharding: Sharding, config: pytest.Config) -> None:
    """The record complete, once pytest wrote ``--junit-xml`` (after its sessionfinish)."""
    junit = _junit_file(sharding, config)
    if junit is None or sharding.selection is None or not junit.is_file():
        return  # no file written: the started record says so to the merge
    from ros_isolated_test.shard import record
    from ros_isolated_test.xunit.validate import hostname

    try:
        record.leave(junit.parent, sharding.selection, hostname(), __version__)
    except OSError as error:
        from ros_isolated_test.pytest_plugin.interrupts import note

        note(
            f"cannot complete the shard record {record.file_name(sharding.selection.share)} "
            f"in {junit.parent} ({error.strerror or error}): a merge will read this share "
            "as started with no results; make the folder writable"
        )


def exit_status(sharding: Sharding, status: int) -> int:
    """The session's exit code: 0 rather than pytest's 5 when the split emptied its share.

    Only then: a session that selected nothing itself, or found no test, stays 5.
    """
    if status != _NO_TESTS or sharding.selection is None:
        return status
    return 0 if sharding.deselected else status

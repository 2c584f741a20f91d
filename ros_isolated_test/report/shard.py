"""A split's trees merged: every share there, all under one plan, every test in one share.

The N machines of a split (``ROS_ISOLATED_TEST_SHARD=I/N``) each leave a tree, and one
job reads them all. Their counts simply add up, since each test ran on one machine and
a test of another share left no result; what can go wrong is what the sum cannot show:

- a share **missing** (its job failed before uploading, its artifact was not
  downloaded): its tests ran nowhere that is read, and the total is silently smaller.
  Every machine leaves its record (``shard.record``) even when it ran nothing, and
  every result of a split says its share (the ``shard`` property), so a share neither
  names is missing;
- shares run under **different plans** (another N, another durations file: a job
  restarted after the file changed): then some test ran twice or not at all;
- a test **run twice**: on two shares, or a result file of another producer found in
  several trees (a test not run through the RUNNER or the plugin runs on every machine);
- a share that **started and left no results**: a pytest session of the share that died
  before writing its ``--junit-xml`` (SIGKILL, SIGSEGV, OOM) leaves its record
  ``started`` and no result file of that share beside it, so its tests are not counted;
  and since several sessions of one share may write into one folder (one record for
  all), each session's ``--junit-xml`` holds a placeholder until pytest replaces it: one
  error case of type :data:`SESSION_ENDED_TYPE`, counted, and named here per file.

A record speaks only for its own run: the machine that writes one removes every other
record in its folder (``shard.record``), so a record an earlier run left in a reused or
restored build folder is gone once another share runs there, and that share reads as
missing unless its own tree is given.

Each is one line (:attr:`Split.problems`); the report exits 1 on any. A report on one
machine's own tree, where ``ROS_ISOLATED_TEST_SHARD`` says which share it is, expects
that share alone. Trees with no record and no ``shard`` property are no split: nothing
is said.
"""

from __future__ import annotations

from pathlib import Path

from ros_isolated_test.report.shard_durations import named_tests
from ros_isolated_test.report.tree import FileRead
from ros_isolated_test.shard import record
from ros_isolated_test.shard.selection import PLAN_PROPERTY, SHARD_PROPERTY
from ros_isolated_test.shard.spec import ShardSettingError, Share, parse
from ros_isolated_test.text import display_text

#: Examples named per kind of problem; more are counted.
SHOWN = 5
#: The ``type`` of the error case in the pytest plugin's placeholder ``--junit-xml``: the
#: session of a share that wrote it ended before pytest replaced it with its results.
SESSION_ENDED_TYPE = "PytestSessionEnded"

__all__ = ["Split"]


class Split:
    """What the trees say of a split, gathered file by file; its problems at the end."""

    def __init__(self, expected: Share | None = None) -> None:
        #: The one share a machine's own report expects (None: all N, the merge).
        self.expected = expected
        #: (total, plan) -> share index -> hosts that said so.
        self.plans: dict[tuple[int, str], dict[int, set[str]]] = {}
        #: Test identity (or another producer's file) -> where each result of it was.
        self._seen: dict[str, list[str]] = {}
        self._foreign: set[str] = set()
        self._odd: list[str] = []
        #: (folder, share) of every result file that says its share.
        self._results: set[tuple[Path, Share]] = set()
        self._started: list[str] = []
        self._placeholders: list[str] = []

    def _share(self, share: Share, plan: str, host: str) -> None:
        hosts = self.plans.setdefault((share.total, plan), {}).setdefault(share.index, set())
        if host:
            hosts.add(host)

    def add(self, item: FileRead) -> None:
        """One result file: the share it says it ran in, and its tests."""
        read = item.read
        if read is None:
            return
        properties = next(
            (suite.properties for suite in read.suites if SHARD_PROPERTY in suite.properties), {}
        )
        where = "a run without a split"
        said = properties.get(SHARD_PROPERTY)
        if said is not None:
            try:
                share = parse(said, SHARD_PROPERTY)
            except ShardSettingError:
                share = None
            if share is None:
                self._odd.append(f"{display_text(str(item.path))} says shard {said!r}: no share")
            else:
                host = next((s.attrs.get("hostname", "") for s in read.suites), "")
                self._share(share, properties.get(PLAN_PROPERTY, "") or "?", host)
                if any(case.type == SESSION_ENDED_TYPE for case in item.cases):
                    self._placeholders.append(
                        f"shard {share.index} of {share.total}: a pytest session started and "
                        f"left no results ({display_text(str(item.path))} is still its "
                        "placeholder, killed or crashed): its tests there are not counted; "
                        "run that share again"
                    )
                    return  # no result: it names no test, and completes no record
                self._results.add((item.path.parent, share))
                where = f"shard {share}"
        tests = named_tests(item)
        if not tests and said is None:
            # Another producer's file, naming no test a split places: by its place.
            key = f"{item.path.parent.name}/{item.path.name}"
            self._foreign.add(key)
            tests = [(key, None)]
        for key, _seconds in tests:
            self._seen.setdefault(key, []).append(where)

    def add_records(self, paths: list[Path]) -> None:
        """The records the machines left (``ros_isolated_test_shard-<I>-of-<N>.json``).

        After every result file (:meth:`add`): a started record is complete only with a
        result of its share beside it.
        """
        for path in paths:
            found = record.read(path)
            if isinstance(found, str):
                self._odd.append(f"the record {display_text(str(path))} {found}")
                continue
            self._share(found.share, found.plan, found.host)
            if found.started and (path.parent, found.share) not in self._results:
                share = found.share
                self._started.append(
                    f"shard {share.index} of {share.total} started and left no results in "
                    f"{display_text(str(path.parent))} (its record {path.name} says started, "
                    "and no result file of that share is beside it: its pytest session "
                    "ended before writing --junit-xml, killed or crashed): its tests there "
                    "are not counted; run that share again"
                )

    @property
    def is_split(self) -> bool:
        """Whether the trees come from a split at all."""
        return bool(self.plans or self._odd)

    def shares(self) -> list[tuple[str, str, list[str]]]:
        """Each share found, ``(I/N, plan, hosts)``, in order: for the page and ``--json``."""
        return [
            (f"{index}/{total}", plan, sorted(hosts))
            for (total, plan), found in sorted(self.plans.items())
            for index, hosts in sorted(found.items())
        ]

    @property
    def problems(self) -> list[str]:
        """Every problem of the split, one line each; none when the trees are no split."""
        if not self.is_split:
            return []
        found = list(self._odd)
        found += self._started
        found += self._placeholders
        found += self._plans_differ()
        found += self._missing()
        found += self._twice()
        return found

    def _plans_differ(self) -> list[str]:
        if len(self.plans) < 2:
            return []
        groups = "; ".join(
            f"{', '.join(f'{index}/{total}' for index in sorted(shares))} under plan {plan}"
            for (total, plan), shares in sorted(
                self.plans.items(), key=lambda group: (min(group[1]), group[0])
            )
        )
        return [
            f"the shards ran under different plans ({groups}), so some test may have run "
            "twice and another nowhere: run every share with the same N and the same "
            "durations file (ROS_ISOLATED_TEST_DURATIONS)"
        ]

    def _missing(self) -> list[str]:
        said: list[str] = []
        if self.expected is not None:
            wanted = {(self.expected.total, self.expected.index)}
        else:
            wanted = {
                (total, index) for total, _plan in self.plans for index in range(1, total + 1)
            }
        present = {(total, index) for (total, _), found in self.plans.items() for index in found}
        for total, index in sorted(wanted - present):
            said.append(
                f"shard {index} of {total} left no results (no record "
                f"{record.file_name(Share(index, total))} and no result file of it under the "
                "trees given): its tests are not counted; add its tree, or run that share again"
            )
        return said

    def _twice(self) -> list[str]:
        twice = sorted((key, where) for key, where in self._seen.items() if len(where) > 1)
        said = []
        for key, where in twice[:SHOWN]:
            name = display_text(key)
            if key in self._foreign:
                said.append(
                    f"{name} (a result file of another producer, which names no share) is in "
                    f"{len(where)} trees: a test not run through ros-isolated-test's RUNNER or "
                    "pytest plugin runs on every machine; register it through them"
                )
            elif len(set(where)) == 1:
                said.append(
                    f"test {name} has {len(where)} results of {where[0]} (a tree given twice?): "
                    "each test counts once; give each machine's tree once"
                )
            else:
                ran = " and ".join(sorted(set(where)))
                said.append(f"test {name} ran in {ran}: each test must run in one share only")
        if len(twice) > SHOWN:
            said.append(f"and {len(twice) - SHOWN} more test(s) with more than one result")
        return said

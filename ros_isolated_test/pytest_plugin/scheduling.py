"""pytest-xdist's unit of work: a launch's tests together on one worker, every other test alone.

A launch file's cases (launch_testing_cases.py makes them) share one launch, run by the
first of them: split across workers, each worker would launch the file again. The
controller schedules from node IDs alone, so the scope is read from the node ID.
"""

from __future__ import annotations

from typing import Any

import pytest


def launch_scope(nodeid: str) -> str | None:
    """The file of a launch case's node ID (``file.py::Class.method[...]``), else None.

    No pytest test function or class has a dot in its name; a launch case does (and so do
    doctests, kept together per file too, which costs nothing).
    """
    path, separator, name = nodeid.partition("::")
    if separator and "::" not in name and "." in name.partition("[")[0]:
        return path
    return None


def scheduler(config: pytest.Config, log: Any) -> Any:
    """Under xdist's load, loadgroup and worksteal: a launch file's cases as one unit of work.

    loadscope and loadfile keep a file on one worker already; ``each`` runs all of it on
    every worker: None, xdist's own scheduler. Everything else is scheduled one test at a
    time, as ``load`` does (with loadgroup, ``xdist_group`` groups as ever).
    """
    if config.getvalue("dist") not in ("load", "loadgroup", "worksteal"):
        return None
    from xdist.scheduler import LoadGroupScheduling  # type: ignore[import-untyped]

    class LaunchFilesTogether(LoadGroupScheduling):  # type: ignore[misc]
        def _split_scope(self, nodeid: str) -> str:
            return launch_scope(nodeid) or super()._split_scope(nodeid)

    return LaunchFilesTogether(config, log)

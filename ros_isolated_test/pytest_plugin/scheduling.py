"""pytest-xdist's unit of work: a launch's tests together on one worker, every other test alone.

A launch file's tests share one launch: launch_testing's cases (launch_testing_cases.py
makes them) are run by the first of them; launch_pytest's tests of a module-scoped launch
fixture run while it is up, its post-shutdown tests after it ended, in that order on the
worker that launched it. Split across workers, each worker would launch the file again
and run a post-shutdown test on a launch it never ended, or on none. The controller
schedules from node IDs alone: a launch_testing case is known by its name, a
launch_pytest file by its text.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest

#: What a launch_pytest test file says: it names launch_pytest, or marks tests with
#: ``pytest.mark.launch(...)`` (a launch test's mark names its fixture).
_LAUNCH_PYTEST = re.compile(rb"\blaunch_pytest\b|\bmark\.launch\s*\(")


def launch_scope(nodeid: str) -> str | None:
    """The file of a launch case's node ID (``file.py::Class.method[...]``), else None.

    No pytest test function or class has a dot in its name; a launch case does (and so do
    doctests, kept together per file too, which costs nothing).
    """
    path, separator, name = nodeid.partition("::")
    if separator and "::" not in name and "." in name.partition("[")[0]:
        return path
    return None


class LaunchPytestFiles:
    """Which files of a session are launch_pytest's, each read once (the controller's)."""

    def __init__(self, root: Path) -> None:
        self._root = root
        self._known: dict[str, bool] = {}

    def scope(self, nodeid: str) -> str | None:
        """The file of a test in a launch_pytest file, else None."""
        path, separator, _name = nodeid.partition("::")
        if not separator:
            return None
        if path not in self._known:
            try:
                text = (self._root / path).read_bytes()
            except OSError:
                text = b""
            self._known[path] = _LAUNCH_PYTEST.search(text) is not None
        return path if self._known[path] else None


def scheduler(config: pytest.Config, log: Any, launch_pytest: bool = False) -> Any:
    """Under xdist's load, loadgroup and worksteal: a launch file's tests as one unit of work.

    loadscope and loadfile keep a file (or a class) on one worker already; ``each`` runs
    all of it on every worker: None, xdist's own scheduler. Everything else is scheduled
    one test at a time, as ``load`` does (with loadgroup, ``xdist_group`` groups as ever).
    ``launch_pytest``: its plugin is loaded, so its files are found too.
    """
    if config.getvalue("dist") not in ("load", "loadgroup", "worksteal"):
        return None
    from xdist.scheduler import LoadGroupScheduling  # type: ignore[import-untyped]

    files = LaunchPytestFiles(config.rootpath) if launch_pytest else None

    class LaunchFilesTogether(LoadGroupScheduling):  # type: ignore[misc]
        def _split_scope(self, nodeid: str) -> str:
            scope = launch_scope(nodeid) or (files.scope(nodeid) if files else None)
            return scope or super()._split_scope(nodeid)

    return LaunchFilesTogether(config, log)

"""The ``colcon_core.event_handler`` entry: ``colcon test`` ends with our summary line.

On by default; off with ``--event-handlers ros_isolated_test-``, with
``ROS_ISOLATED_TEST_COLCON=off``, or by ``COLCON_EXTENSION_BLOCKLIST``. It notes each
package job of ``colcon test`` as it ends (where its results are: the test result base,
else the build base), then, when colcon shuts its events down, after colcon's own
summary, writes the page into the run's log folder and prints one line (``summary``).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any

from colcon_core.event.job import JobEnded  # type: ignore[import-untyped]
from colcon_core.event_handler import EventHandlerExtensionPoint  # type: ignore[import-untyped]
from colcon_core.event_reactor import EventReactorShutdown  # type: ignore[import-untyped]
from colcon_core.location import get_log_path  # type: ignore[import-untyped]
from colcon_core.plugin_system import satisfies_version  # type: ignore[import-untyped]

from ros_isolated_test.colcon import summary, switch


class SummaryEventHandler(EventHandlerExtensionPoint):  # type: ignore[misc]
    """After ``colcon test``: tests run, failed, flaky, domain IDs, and the page's path."""

    #: Below colcon's own handlers (100): its summary comes first, ours is the last line.
    PRIORITY = 20

    def __init__(self) -> None:
        super().__init__()
        satisfies_version(EventHandlerExtensionPoint.EXTENSION_POINT_VERSION, "^1.0")
        self._bases: list[Path] = []

    def __call__(self, event: tuple[Any, Any]) -> None:
        data = event[0]
        if isinstance(data, JobEnded):
            self._note(event[1])
        elif isinstance(data, EventReactorShutdown):
            self._finish()

    def _testing(self) -> bool:
        args = getattr(self.context, "args", None)
        return getattr(args, "verb_name", None) == "test" and switch.state(os.environ)[0]

    def _note(self, job: Any) -> None:
        if not self._testing():
            return
        args = getattr(getattr(job, "task_context", None), "args", None)
        base = getattr(args, "test_result_base", None) or getattr(args, "build_base", None)
        if base:
            self._bases.append(Path(base))

    def _finish(self) -> None:
        if not self._testing() or not self._bases:
            return
        log_path = get_log_path()
        line = summary.summarise(
            summary.result_paths(self._bases),
            Path(log_path) if log_path is not None else None,
            os.environ,
            workspace=Path.cwd(),  # the test history is the workspace's
        )
        print(line, flush=True)
        sys.stdout.flush()

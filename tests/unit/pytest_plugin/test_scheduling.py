"""``scheduling``: pytest-xdist's unit of work, read from a node ID alone.

A launch case (a dot in its name: launch_testing_cases makes them) belongs to its file,
any other test is a unit of its own, so the scheduler splits everything else as xdist's
``load`` does. That a launch file's cases really run on one worker is
test_launch_testing_cases_xdist.py's, with real pytest-xdist.
"""

from __future__ import annotations

import pytest

from ros_isolated_test.pytest_plugin.scheduling import launch_scope


@pytest.mark.parametrize(
    ("nodeid", "scope"),
    [
        ("test/test_x_launch.py::TestWhileRunning.test_talks", "test/test_x_launch.py"),
        ("test/test_x_launch.py::TestWhileRunning.test_size[red, 1]", "test/test_x_launch.py"),
        ("test/test_x_launch.py::TestAfterShutdown.test_exit[a.b, 1.5]", "test/test_x_launch.py"),
        # The controls: pytest's own tests stay units of their own.
        ("test/test_plain.py::test_plain", None),
        ("test/test_plain.py::test_plain[1.5]", None),  # a dot among the parameters only
        ("test/test_plain.py::TestClass::test_method", None),
        ("test/test_plain.py", None),
    ],
)
def test_launch_scope_keeps_a_launch_files_cases_together_and_nothing_else(
    nodeid: str, scope: str | None
) -> None:
    """xdist's unit of work: a launch case (a dot in its name) is its file's, any other test
    its own, so the scheduler splits everything else as ``load`` does."""
    assert launch_scope(nodeid) == scope

"""``scheduling``: pytest-xdist's unit of work, read from a node ID (and a file's text).

A launch case (a dot in its name: launch_testing_cases makes them) belongs to its file,
and so does every test of a file that names launch_pytest or marks tests with
``pytest.mark.launch(...)``; any other test is a unit of its own, so the scheduler splits
everything else as xdist's ``load`` does. That a launch file's tests really run on one
worker is test_launch_testing_cases_xdist.py's and test_launch_pytest_tests.py's, with
real pytest-xdist.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from ros_isolated_test.pytest_plugin.scheduling import LaunchPytestFiles, launch_scope


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


#: Test files by name: what each says, and whether it is launch_pytest's.
FILES = {
    "test_fixture.py": ("import launch_pytest\n\n@launch_pytest.fixture\ndef ld(): ...\n", True),
    "test_marked.py": (
        "from x import ld\n\n@pytest.mark.launch( fixture=ld)\ndef test_a(): ...\n",
        True,
    ),
    "test_module_mark.py": ("pytestmark = pytest.mark.launch(fixture=ld)\n", True),
    # The controls: an ordinary test, launch_testing's mark, a word that only contains it.
    "test_plain.py": ("def test_launch_pytest_like():\n    assert 'launch'\n", False),
    "test_other_launch.py": (
        "@pytest.mark.launch_test\ndef generate_test_description(): ...\n",
        False,
    ),
    "test_lookalike.py": ("import my_launch_pytest_helpers\n", False),
}


def test_a_launch_pytest_file_is_one_unit_and_any_other_file_is_not(tmp_path: Path) -> None:
    (tmp_path / "test").mkdir()
    for name, (text, _launch) in FILES.items():
        (tmp_path / "test" / name).write_text(text)
    files = LaunchPytestFiles(tmp_path)
    for name, (_text, launch) in FILES.items():
        for test in ("test_a", "test_a[shutdown_test]", "TestClass::test_b[1]"):
            nodeid = f"test/{name}::{test}"
            assert files.scope(nodeid) == (f"test/{name}" if launch else None), nodeid
    # Files read once: a file that changes later keeps what was read.
    (tmp_path / "test" / "test_plain.py").write_text(FILES["test_fixture.py"][0])
    assert files.scope("test/test_plain.py::test_a") is None
    # A node ID without a test, or naming no file there: a unit of its own.
    assert files.scope("test/test_fixture.py") is None
    assert files.scope("test/test_missing.py::test_a") is None

"""What the tests of the command line (tests/unit/test_cli*.py) read of a run.

A command that leaves a file behind, so a test can tell whether it ran, and the one line
a usage error must be (helpers.commands.the_error_line also checks its prefix).
"""

from __future__ import annotations

#: A command leaving a file behind, so a test can tell whether it ran.
TOUCH = ("touch", "ran")


def one_error_line(stderr: str) -> str:
    """The one non-blank line of ``stderr`` (any other count fails the test)."""
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1, stderr
    return lines[0]

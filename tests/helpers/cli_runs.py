"""What the tests of the command line (tests/unit/cli/) read of a run.

A command that leaves a file behind, so a test can tell whether it ran. The one line a
usage error must be is helpers.commands.the_error_line.
"""

from __future__ import annotations

#: A command leaving a file behind, so a test can tell whether it ran.
TOUCH = ("touch", "ran")

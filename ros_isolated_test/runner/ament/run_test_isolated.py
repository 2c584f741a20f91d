"""The RUNNER's old path, kept so that a workspace configured before it moved still runs.

ctest runs what ``runner-path`` printed when the package was configured, and a CMake
cache or a colcon defaults file keeps it across builds. The script now lives in
``ros_isolated_test/ament/``: this file runs it, in this process, with the same
arguments, as if ctest had named it (so nothing more is started, and the import budget
of every test is unchanged but for ``runpy``).
"""

import os
import sys


def _forward() -> None:
    here = os.path.dirname(os.path.abspath(__file__))
    script = os.path.join(os.path.dirname(os.path.dirname(here)), "ament", "run_test_isolated.py")
    # Run by path, this folder is sys.path[0]: make it the script's, which drops its own.
    if sys.path and os.path.abspath(sys.path[0] or os.curdir) == here:
        sys.path[0] = os.path.dirname(script)
    sys.argv[0] = script
    import runpy

    runpy.run_path(script, run_name="__main__")


if __name__ == "__main__":
    _forward()

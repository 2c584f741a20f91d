"""ctest RUNNER of ros-isolated-test: ``python3 -u <this file> RESULT_FILE ... --command CMD``.

Print this file's path with ``ros-isolated-test runner-path`` and pass it as ``RUNNER``
to ``ament_add_test`` or ``add_launch_test``. It only finds the installed package and
hands its arguments over; all behaviour lives in ``ros_isolated_test``. It is kept this
short on purpose: a script run by path is compiled anew for every test. When no Python
can import the package, ``without_package.py`` beside it still leaves RESULT_FILE saying
why, importing nothing more.
"""

import gc
import os
import sys

TYPE_CHECKING = False  # typing is not imported: this file starts every test
if TYPE_CHECKING:
    from collections.abc import Callable
    from typing import NoReturn

_REEXEC_MARK = "_ROS_ISOLATED_TEST_REEXEC"


def _import_main() -> "Callable[[], int]":
    here = os.path.dirname(os.path.abspath(__file__))
    # Run by path, this folder is sys.path[0]: drop it so nothing here shadows a module.
    if sys.path and os.path.abspath(sys.path[0] or os.curdir) == here:
        del sys.path[0]
    # Imports make many objects and no garbage: the collector would only walk them again.
    gc.disable()
    try:
        from ros_isolated_test.ament.args import main
    except ImportError as error:
        import runpy

        fallback = runpy.run_path(os.path.join(here, "without_package.py"))
        fallback["not_importable"](error, os.path.abspath(__file__), _REEXEC_MARK)
    gc.enable()  # a test's output is read for as long as it runs
    os.environ.pop(_REEXEC_MARK, None)
    return main


def _exit(code: int) -> "NoReturn":
    """Exit at once, skipping the interpreter's teardown of every module.

    Every file is written and closed and the ID released by now: the teardown would
    only cost each test more time. A console that went away (or was closed at start:
    None) loses nothing: the result file holds everything.
    """
    for stream in (sys.stdout, sys.stderr):
        try:
            if stream is not None:
                stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(code)


if __name__ == "__main__":
    _exit(_import_main()())

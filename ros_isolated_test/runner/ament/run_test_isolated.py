"""ctest RUNNER of ros-isolated-test: ``python3 -u <this file> RESULT_FILE ... --command CMD``.

Print this file's path with ``ros-isolated-test runner-path`` and pass it as ``RUNNER``
to ``ament_add_test`` or ``add_launch_test``. It only finds the installed package and
hands its arguments over; all behaviour lives in ``ros_isolated_test``.
"""

import contextlib
import os
import sys

TYPE_CHECKING = False  # typing is not imported: this file starts every test
if TYPE_CHECKING:
    from collections.abc import Callable
    from typing import NoReturn

_REEXEC_MARK = "_ROS_ISOLATED_TEST_REEXEC"


def _interpreter_of_cli() -> "str | None":
    """The Python named in the ``ros-isolated-test`` script's shebang, if there is one."""
    import shutil

    script = shutil.which("ros-isolated-test")
    if script is None:
        return None
    try:
        with open(script, "rb") as handle:
            first = handle.readline(4096).decode("utf-8", "replace").strip()
    except OSError:
        return None
    if not first.startswith("#!"):
        return None
    words = first[2:].split()
    if words and os.path.basename(words[0]) == "env" and len(words) > 1:
        # "#!/usr/bin/env python3": the interpreter is the next word, found on PATH.
        words = [shutil.which(words[1]) or words[1]]
    interpreter = words[0] if words else ""
    return interpreter if interpreter and os.access(interpreter, os.X_OK) else None


def _import_main() -> "Callable[[], int]":
    here = os.path.dirname(os.path.abspath(__file__))
    # Run by path, this folder is sys.path[0]: drop it so nothing here shadows a module.
    if sys.path and os.path.abspath(sys.path[0] or os.curdir) == here:
        del sys.path[0]
    try:
        from ros_isolated_test.runner.ament.args import main
    except ImportError as error:
        # ctest runs us with the Python CMake found, which may not be the one we are
        # installed for: run again with the Python of the `ros-isolated-test` command.
        interpreter = _interpreter_of_cli()
        if interpreter and not os.environ.get(_REEXEC_MARK):
            os.environ[_REEXEC_MARK] = "1"
            os.execv(interpreter, [interpreter, "-u", os.path.abspath(__file__), *sys.argv[1:]])
        sys.stderr.write(
            f"run_test_isolated.py: error: cannot import ros-isolated-test with {sys.executable}"
            f" ({error}); install it for that Python (python3 -m pip install ros-isolated-test)"
            " or point CMake at the Python it is installed for (-DPython3_EXECUTABLE=...)\n"
        )
        sys.exit(2)
    os.environ.pop(_REEXEC_MARK, None)
    return main


def _exit(code: int) -> "NoReturn":
    """Exit at once, skipping the interpreter's teardown of every module.

    Every file is written and closed and the ID released by now: the teardown would
    only cost each test more time.
    """
    for stream in (sys.stdout, sys.stderr):
        # A console that went away (or was closed at start: None) loses nothing: the
        # result file holds everything.
        with contextlib.suppress(OSError, ValueError):
            if stream is not None:
                stream.flush()
    os._exit(code)


if __name__ == "__main__":
    _exit(_import_main()())

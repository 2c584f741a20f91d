"""What the RUNNER does when no Python can import the package: re-run, or say why.

``run_test_isolated.py`` runs this file by path, and only then: it is what every test
would otherwise compile at start (a script run by path has no cached bytecode). It
imports nothing of the package, which is what failed: only the standard library.
"""

import contextlib
import os
import stat  # loaded at start-up by os: free
import sys
import time  # built in and loaded at start-up: free

TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import NoReturn


def not_importable(error: ImportError, script: str, mark: str) -> "NoReturn":
    """Run ``script`` again with the CLI's Python, or leave RESULT_FILE saying why; exit 2.

    ctest runs the RUNNER with the Python CMake found, which may not be the one the
    package is installed for: the ``ros-isolated-test`` command's Python is tried once
    (``mark`` in the environment says it was).
    """
    interpreter = _interpreter_of_cli()
    if interpreter and not os.environ.get(mark):
        os.environ[mark] = "1"
        with contextlib.suppress(OSError):
            os.execv(interpreter, [interpreter, "-u", script, *sys.argv[1:]])
    message = (
        f"cannot import ros-isolated-test with {sys.executable} ({error}); install it for "
        "that Python (see Install it in its README) or point CMake at the "
        "Python it is installed for (-DPython3_EXECUTABLE=...)"
    )
    _write_not_run(sys.argv[1:], message)
    sys.stderr.write(f"run_test_isolated.py: error: {message}\n")
    sys.stderr.flush()
    os._exit(2)


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


def _write_not_run(argv: "list[str]", message: str) -> None:
    """Leave RESULT_FILE (ament passes it first) as a canonical file with one error case.

    The package that writes result files could not be imported, yet ctest and colcon must
    still find a result saying why the test did not run. Nothing is imported for it:
    whatever made the import fail must not make this fail too. Best effort: a path that
    cannot be written leaves only the error line, and so does a device node, FIFO or
    socket there (or a symlink to one), which is never replaced: /dev/null discards it.
    """
    if not argv or not argv[0] or argv[0].startswith("-"):
        return
    path = argv[0]
    if _never_replaced(path):
        return
    words = argv[: argv.index("--command")] if "--command" in argv else argv
    command = argv[len(words) + 1 :]
    package = ""
    if "--package-name" in words[:-1]:
        package = words[words.index("--package-name") + 1]
    test = os.path.basename(path) or "test"
    for suffix in (".gtest.xml", ".xunit.xml", ".xml"):
        if test.endswith(suffix) and len(test) > len(suffix):
            test = test[: -len(suffix)]
            break
    suite = f"{package}.{test}" if package else test
    temporary = f"{path}.{os.getpid()}.tmp"
    try:
        os.makedirs(os.path.dirname(path) or os.curdir, exist_ok=True)
        fd = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o666)
        try:
            # Local time, as every other result of the runner is stamped.
            stamp = time.strftime("%Y-%m-%dT%H:%M:%S", time.localtime())
            document = _not_run_document(suite, test, command, message, stamp)
            view = memoryview(document)
            while view:
                view = view[os.write(fd, view) :]
        finally:
            os.close(fd)
        if _never_replaced(path):  # again: one may have appeared meanwhile
            raise FileExistsError(path)
        os.replace(temporary, path)
    except OSError:
        with contextlib.suppress(OSError):
            os.unlink(temporary)


def _never_replaced(path: str) -> bool:
    """Whether ``path`` is a device node, FIFO or socket, or a symlink to one."""
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return False  # nothing there, or a dangling symlink: the symlink is replaced
    return not (stat.S_ISREG(mode) or stat.S_ISDIR(mode))


def _not_run_document(
    suite: str, test: str, command: "list[str]", message: str, stamp: str
) -> bytes:
    """What ResultFile writes for a test not run, as far as schemas/junit.xsd asks it."""
    # Names must not be blank (the schema says so); what is left of an odd one may be.
    suite, test, message = _xml(suite) or "test", _xml(test) or "test", _xml(message)
    host = _xml(os.uname().nodename) or "localhost"
    version = _own_version()
    counts = 'tests="1" failures="0" errors="1"'
    lines = [
        "<?xml version='1.0' encoding='UTF-8'?>",
        f'<testsuites name="{suite}" {counts} time="0.000">',
        f'  <testsuite name="{suite}" {counts} skipped="0" time="0.000" timestamp="{stamp}"'
        f' hostname="{host}">',
        "    <properties>",
        f'      <property name="command" value="{_xml(" ".join(command))}"/>',
        '      <property name="exit" value="not run"/>',
        # names.RUNNER_VERSION, spelt out: this file imports nothing of the package here.
        *([f'      <property name="runner_version" value="{_xml(version)}"/>'] if version else []),
        "    </properties>",
        f'    <testcase classname="{suite}" name="{test}" time="0.000">',
        f'      <error message="{message}" type="RunnerNotImportable">{message}</error>',
        "    </testcase>",
        "  </testsuite>",
        "</testsuites>",
        "",
    ]
    return "\n".join(lines).encode("utf-8")


def _own_version() -> str:
    """``__version__`` of the package this file belongs to, read from its text, not imported."""
    package = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))  # ament/ in it
    try:
        with open(os.path.join(package, "__init__.py"), encoding="utf-8") as handle:
            for line in handle:
                if line.startswith("__version__ = "):
                    return line.split("=", 1)[1].strip().strip("\"'")
    except (OSError, UnicodeError):
        pass
    return ""


def _xml(text: str) -> str:
    r"""``text`` fit for an attribute or element: markup escaped, what XML forbids as ``\xNN``.

    Surrogates (undecodable bytes of a path) and control characters are shown, never
    written, so the document always parses; blanks at the ends would break a name.
    Each as ``ros_isolated_test.text.shown_code`` shows it, in a copy kept here on purpose:
    this runs exactly when the package cannot be imported, so it cannot import that one.
    """
    shown: list[str] = []
    for char in text.strip():
        code = ord(char)
        if code < 0x20 or 0xD800 <= code <= 0xDFFF or code in (0xFFFE, 0xFFFF):
            shown.append(f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}")
        else:
            shown.append(char)
    escaped = "".join(shown).replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
    return escaped.replace('"', "&quot;")

"""launch_pytest files and the ament_python packages around them, for the plugin's tests.

The token file launches the crosstalk demo's talker (a token of its own, failing on any
other) from a module-scoped launch fixture and holds every kind of launch_pytest test: a
generator test whose first half listens while the talker talks (it fails on a foreign
token) and whose second half, after the launch ended, checks the talker's exit code; an
active test that passes, one that always fails, and a ``shutdown=True`` test. Every
launch and every test writes a line to ``$LAUNCH_CASES_LOG`` as the launch_testing files
do (helpers/launch_files.py): a test can count launches and see where each test ran. The
other files are for one failure each: a launch that cannot start, a launch fixture that
raises, a launch that fails after its tests began.
"""

from __future__ import annotations

from pathlib import Path

from helpers.launch_files import LISTENER, NOTE, PACKAGE_XML, SETUP_PY, TALKER

#: The tests of a token file as pytest names them, the failing one first.
TOKEN_TESTS = (
    "test_always_fails",
    "test_only_own_token",
    "test_passes",
    "test_only_own_token[shutdown_test]",
    "test_talker_ended",
)
ALWAYS_FAILS = TOKEN_TESTS[0]

#: Lines every file starts with: the log every launch and test writes to.
_PREAMBLE = (
    """\
import os
import sys
import time

import launch
import launch.actions
import launch.event_handlers
import launch.substitutions
import launch_pytest
import pytest
"""
    + NOTE
)

TOKEN_FILE = (
    _PREAMBLE
    + "\n"
    + LISTENER
    + """
TOKEN = {token!r}


@pytest.fixture(scope="module")
def talker():
    return launch.actions.ExecuteProcess(
        cmd=[sys.executable, str(TALKER), TOKEN], name=f"talker_{{TOKEN}}", output="screen"
    )


@launch_pytest.fixture(scope="module")
def tokens(talker):
    note("launch", TOKEN)
    return launch.LaunchDescription([talker, launch_pytest.actions.ReadyToTest()])


@pytest.mark.launch(fixture=tokens)
def test_always_fails():
    note("case", TOKEN, "test_always_fails")
    assert False, f"fails on purpose ({{TOKEN}})"


@pytest.mark.launch(fixture=tokens)
def test_only_own_token(talker):
    note("case", TOKEN, "test_only_own_token")
    heard = Counter()
    context = Context()
    rclpy.init(args=[], context=context)
    executor = SingleThreadedExecutor(context=context)
    node = rclpy.create_node(f"listener_{{TOKEN}}", context=context)
    try:
        node.create_subscription(
            String, token_talker.TOPIC, lambda m: heard.update([m.data]), token_talker.QOS
        )
        executor.add_node(node)
        token_talker.spin_until(
            executor,
            time.monotonic() + token_talker.OWN_TOKEN_DEADLINE_S,
            lambda: heard[TOKEN] > 0,
        )
        if heard[TOKEN]:
            token_talker.spin_until(executor, time.monotonic() + token_talker.LISTEN_S)
    finally:
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()
    deadline = time.monotonic() + 60  # the talker ends on its own once it heard enough
    while talker.return_code is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert talker.return_code is not None, "the talker never ended"
    assert heard[TOKEN] > 0, f"never heard its own token {{TOKEN}}"
    foreign = {{token: count for token, count in heard.items() if token != TOKEN}}
    assert foreign == {{}}, f"crosstalk: heard tokens not its own: {{foreign}}"
    yield
    note("case", TOKEN, "test_only_own_token[shutdown_test]")
    assert talker.return_code == 0, "the talker heard a token not its own"


@pytest.mark.launch(fixture=tokens)
def test_passes():
    note("case", TOKEN, "test_passes")


@pytest.mark.launch(fixture=tokens, shutdown=True)
def test_talker_ended(talker):
    note("case", TOKEN, "test_talker_ended")
    assert talker.return_code is not None
"""
)

#: Its one process cannot be started, and ReadyToTest waits for that start: the launch
#: ends before it is ready (launch_pytest alone waits for ever).
CANNOT_START_FILE = (
    _PREAMBLE
    + """

@pytest.fixture(scope="module")
def missing():
    return launch.actions.ExecuteProcess(cmd=["/nonexistent/no-such-program"], name="missing")


@launch_pytest.fixture(scope="module")
def cannot_start(missing):
    note("launch", "cannot-start")
    ready = launch.actions.RegisterEventHandler(launch.event_handlers.OnProcessStart(
        target_action=missing, on_start=[launch_pytest.actions.ReadyToTest()]))
    return launch.LaunchDescription([ready, missing])


@pytest.mark.launch(fixture=cannot_start)
def test_first():
    note("case", "cannot-start", "test_first")


@pytest.mark.launch(fixture=cannot_start)
def test_second():
    note("case", "cannot-start", "test_second")


@pytest.mark.launch(fixture=cannot_start, shutdown=True)
def test_after():
    note("case", "cannot-start", "test_after")
"""
)

#: The launch fixture itself fails (a file it needs is not there).
BROKEN_FILE = (
    _PREAMBLE
    + """

@launch_pytest.fixture(scope="module")
def broken():
    note("launch", "broken")
    raise FileNotFoundError("no such map: /maps/missing.yaml")


@pytest.mark.launch(fixture=broken)
def test_first():
    note("case", "broken", "test_first")


@pytest.mark.launch(fixture=broken)
def test_second():
    note("case", "broken", "test_second")


@pytest.mark.launch(fixture=broken, shutdown=True)
def test_after():
    note("case", "broken", "test_after")
"""
)

#: Ready at once, then the launch fails (a program not on the PATH): its service returns
#: 1 before its end, which launch_pytest alone never checks then.
FAILS_LATER_FILE = (
    _PREAMBLE
    + """

@launch_pytest.fixture(scope="module")
def fails_later():
    note("launch", "fails-later")
    missing = launch.actions.ExecuteProcess(
        cmd=[launch.substitutions.FindExecutable(name="no-such-program-on-the-path")]
    )
    return launch.LaunchDescription([launch_pytest.actions.ReadyToTest(), missing])


@pytest.mark.launch(fixture=fails_later)
def test_first():
    note("case", "fails-later", "test_first")


@pytest.mark.launch(fixture=fails_later)
def test_second():
    note("case", "fails-later", "test_second")
"""
)


def token_file(token: str) -> str:
    """The token file with ``token``."""
    return TOKEN_FILE.format(talker=str(TALKER), token=token)


def python_package(root: Path, name: str, token: str) -> Path:
    """An ament_python package whose one test is the token file, as colcon tests it."""
    package = root / name
    (package / "resource").mkdir(parents=True)
    (package / "resource" / name).write_text("")
    (package / "test").mkdir()
    depends = "  <test_depend>launch_pytest</test_depend>\n  <test_depend>rclpy</test_depend>\n"
    (package / "package.xml").write_text(
        PACKAGE_XML.format(name=name, depends=depends, build_type="ament_python")
    )
    (package / "setup.py").write_text(SETUP_PY.format(name=name))
    (package / "test" / f"test_{token}_launch.py").write_text(token_file(token))
    return package

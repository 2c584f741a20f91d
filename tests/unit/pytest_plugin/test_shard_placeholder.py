"""``pytest_plugin.shard``: each session of a share leaves a placeholder --junit-xml until
pytest writes its own, so a killed session fails the merge even beside another session's
results in the same folder (one record for both). Real sessions, real SIGKILL; each
beside its control.
"""

from __future__ import annotations

import signal
from pathlib import Path

from helpers.commands import run_cli
from helpers.pytest_sessions import project, run_pytest
from lxml import etree

from ros_isolated_test.report.shard import SESSION_ENDED_TYPE
from ros_isolated_test.shard.selection import select
from ros_isolated_test.shard.spec import SHARD_ENV

#: Four tests that pass.
PASSING = "".join(f"def test_{n}():\n    pass\n\n" for n in range(4))
#: Four tests, each killing its session when $KILL is set.
KILLING = "import os, signal\n\n" + "".join(
    f"def test_{n}():\n"
    "    if os.environ.get('KILL'):\n"
    "        os.kill(os.getpid(), signal.SIGKILL)\n\n"
    for n in range(4)
)


def _placeholder_cases(junit: Path) -> list[str]:
    """The messages of the placeholder's cases in ``junit`` (none: pytest's own file)."""
    root = etree.parse(str(junit)).getroot()
    return [
        str(error.get("message"))
        for error in root.iterfind(".//testcase/error")
        if error.get("type") == SESSION_ENDED_TYPE
    ]


def test_a_killed_session_beside_a_complete_one_fails_the_merge(
    tmp_path: Path, env: dict[str, str]
) -> None:
    """Two sessions of each share write into one folder (a.xml, b.xml); share K's b
    session is killed after its a session passed: the merge counts b's placeholder and
    fails, naming it. The control: every session completes, the merge has all 8, exit 0."""
    root = project(tmp_path / "pkg", PASSING)
    (root / "test" / "test_b.py").write_text(KILLING)
    here = select({SHARD_ENV: "1/2"})
    assert here is not None
    killed = here.share_of("pkg", "test/test_b.py::test_0")  # it has a test to die in
    res = {index: tmp_path / f"res{index}" for index in (1, 2)}

    def session(index: int, name: str, path: str, **extra: str) -> int:
        done = run_pytest(root, {**env, SHARD_ENV: f"{index}/2", **extra},
                          f"--junit-xml={res[index] / name}", path)  # fmt: skip
        return done.returncode

    for index in (1, 2):
        assert session(index, "a.xml", "test/test_it.py") == 0
        assert session(index, "b.xml", "test/test_b.py") == 0
        for name in ("a.xml", "b.xml"):
            assert _placeholder_cases(res[index] / name) == []  # replaced whole by pytest's
    merged = run_cli(["report", str(res[1]), str(res[2])], env)
    assert merged.returncode == 0, merged.stdout + merged.stderr
    assert "Summary: 8 tests, 0 errors" in merged.stdout

    assert session(killed, "b.xml", "test/test_b.py", KILL="1") == -signal.SIGKILL
    b_file = res[killed] / "b.xml"
    assert _placeholder_cases(b_file) == [
        f"the pytest session of shard {killed}/2 ended before writing its results (killed "
        "or crashed); run that share again"
    ]
    merged = run_cli(["report", str(res[1]), str(res[2])], env)
    assert merged.returncode == 1, merged.stdout + merged.stderr
    assert f"- shard {killed} of 2: a pytest session started and left no results ({b_file} " in (
        merged.stdout
    )
    lost = sum(here.share_of("pkg", f"test/test_b.py::test_{n}") == killed for n in range(4))
    assert f"Summary: {8 - lost + 1} tests, 1 errors" in merged.stdout


def test_no_placeholder_without_a_split(tmp_path: Path, env: dict[str, str]) -> None:
    """Not split, a session killed leaves no --junit-xml at all (nothing to merge); the
    control: the same session under a split leaves its placeholder."""
    root = project(tmp_path / "pkg", KILLING)
    junit = tmp_path / "out" / "pytest.xml"
    alone = run_pytest(root, {**env, "KILL": "1"}, f"--junit-xml={junit}", "test")
    assert alone.returncode == -signal.SIGKILL, alone.stdout + alone.stderr
    assert not junit.exists()
    split = run_pytest(root, {**env, "KILL": "1", SHARD_ENV: "1/1"}, f"--junit-xml={junit}",
                       "test")  # fmt: skip
    assert split.returncode == -signal.SIGKILL, split.stdout + split.stderr
    assert len(_placeholder_cases(junit)) == 1

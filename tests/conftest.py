"""Shared fixtures: every test gets its own lock directory and a clean ROS environment."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from types import ModuleType

import pytest

REPO = Path(__file__).resolve().parent.parent
BIN = Path(sys.executable).parent
CLI = str(BIN / "ros-isolated-test")
#: Variables that would change what the runner decides; tests set them explicitly.
_POLICY_VARS = (
    "ROS_DOMAIN_ID",
    "DISABLE_ROS_ISOLATION",
    "ROS_ISOLATED_TEST_DOMAINS",
    "ROS_ISOLATED_TEST_LOCK_DIR",
)


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--no-skips",
        action="store_true",
        help="strict mode (CI): a skipped test fails, with its reason; CI has every capability",
    )


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(
    item: pytest.Item, call: pytest.CallInfo[None]
) -> Iterator[None]:
    """In strict mode a skip is a failure: CI has root, unshare and the outside tier."""
    outcome = yield
    report: pytest.TestReport = outcome.get_result()  # type: ignore[attr-defined]
    if report.skipped and item.config.getoption("--no-skips") and not hasattr(report, "wasxfail"):
        longrepr = report.longrepr
        reason = longrepr[2] if isinstance(longrepr, tuple) else str(longrepr)
        report.outcome = "failed"
        report.longrepr = f"strict mode (--no-skips): this test was skipped: {reason}"


@pytest.fixture
def lock_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A lock directory of the test's own, so tests never contend with other runs."""
    return tmp_path_factory.mktemp("locks")


@pytest.fixture
def env(lock_dir: Path) -> dict[str, str]:
    """The environment for runner processes: no ROS_DOMAIN_ID, our own lock dir."""
    clean = {key: value for key, value in os.environ.items() if key not in _POLICY_VARS}
    clean["ROS_ISOLATED_TEST_LOCK_DIR"] = str(lock_dir)
    clean["PATH"] = f"{BIN}{os.pathsep}{clean.get('PATH', '')}"
    return clean


@pytest.fixture(autouse=True)
def _isolated_process_env(lock_dir: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """In-process calls see the same clean environment as subprocesses."""
    for name in _POLICY_VARS:
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("ROS_ISOLATED_TEST_LOCK_DIR", str(lock_dir))
    yield


@pytest.fixture(scope="session")
def runner_script() -> str:
    """The ctest RUNNER script, as ``ros-isolated-test runner-path`` prints it."""
    return subprocess.run(
        [CLI, "runner-path"], check=True, capture_output=True, text=True
    ).stdout.strip()


def run_cli(
    args: Sequence[str], env: Mapping[str, str], **kwargs: object
) -> subprocess.CompletedProcess[str]:
    """``ros-isolated-test ARGS`` as a real process, output captured as text."""
    return subprocess.run(  # type: ignore[call-overload, no-any-return]
        [CLI, *args],
        check=False,
        env=dict(env),
        capture_output=True,
        text=True,
        timeout=120,
        **kwargs,
    )


def run_runner(
    runner_script: str, args: Sequence[str], env: Mapping[str, str], **kwargs: object
) -> subprocess.CompletedProcess[str]:
    """The RUNNER script exactly as ctest calls it: ``python3 -u <script> ARGS``."""
    return subprocess.run(  # type: ignore[call-overload, no-any-return]
        [sys.executable, "-u", runner_script, *args],
        check=False,
        env=dict(env),
        capture_output=True,
        text=True,
        timeout=120,
        **kwargs,
    )


def crosstalk_workspace() -> ModuleType:
    """``examples/crosstalk_workspace.py`` (examples/ is no package), loaded once by path."""
    loaded = sys.modules.get("crosstalk_workspace")
    if loaded is not None:
        return loaded
    path = REPO / "examples" / "crosstalk_workspace.py"
    spec = importlib.util.spec_from_file_location("crosstalk_workspace", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while being created
    spec.loader.exec_module(module)
    return module

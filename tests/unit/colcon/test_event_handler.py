from __future__ import annotations

import argparse
from pathlib import Path
from types import SimpleNamespace

import pytest
from colcon_core.event.job import JobEnded  # type: ignore[import-untyped]
from colcon_core.event_reactor import EventReactorShutdown  # type: ignore[import-untyped]

from ros_isolated_test.colcon.event_handler import SummaryEventHandler

from .test_summary import _results


def _handler(verb: str) -> SummaryEventHandler:
    handler = SummaryEventHandler()
    handler.context = SimpleNamespace(args=argparse.Namespace(verb_name=verb))
    return handler


def _job(build_base: Path) -> SimpleNamespace:
    args = SimpleNamespace(build_base=str(build_base), test_result_base=None)
    return SimpleNamespace(task_context=SimpleNamespace(args=args))


def _run(handler: SummaryEventHandler, base: Path) -> None:
    handler((JobEnded("pkg", 0), _job(base)))
    handler((EventReactorShutdown(), None))


def test_colcon_test_ends_with_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv("ROS_ISOLATED_TEST_COLCON", raising=False)
    monkeypatch.setattr(
        "ros_isolated_test.colcon.event_handler.get_log_path", lambda: tmp_path / "log"
    )
    monkeypatch.chdir(tmp_path)  # colcon's folder: the workspace, where its history is kept
    _run(_handler("test"), _results(tmp_path / "build" / "pkg", ("one", 5, False)))
    out = capsys.readouterr().out
    assert out.startswith("ros-isolated-test: 1 tests run, 0 failed, 0 flaky, on 1 domain IDs")
    assert (tmp_path / "log" / "ros_isolated_test.html").is_file()
    assert (tmp_path / "ros_isolated_test_history.sqlite3").is_file()


@pytest.mark.parametrize(("verb", "switch"), [("build", None), ("test", "off")])
def test_silent_for_other_verbs_and_when_off(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    verb: str,
    switch: str | None,
) -> None:
    monkeypatch.delenv("ROS_ISOLATED_TEST_COLCON", raising=False)
    if switch is not None:
        monkeypatch.setenv("ROS_ISOLATED_TEST_COLCON", switch)
    _run(_handler(verb), _results(tmp_path / "build" / "pkg", ("one", 5, False)))
    assert capsys.readouterr().out == ""

"""``benches/``: the header of a run says what was measured under which interpreter.

The benchmarks import each other by plain name (they run as ``python benches/run.py``),
so they are imported here with ``benches/`` on the path, as that command has it.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import pytest
from helpers.commands import REPO


@pytest.fixture(scope="module")
def bench_run() -> Iterator[ModuleType]:
    """``benches/run.py`` as a module, ``benches/`` on the path while it is used."""
    sys.path.insert(0, str(REPO / "benches"))
    try:
        import run  # type: ignore[import-not-found]

        yield run
    finally:
        sys.path.remove(str(REPO / "benches"))


def test_the_header_says_the_kilted_pair_is_not_measured_without_its_venv(
    bench_run: ModuleType, tmp_path: Path
) -> None:
    """A missing ``.venv-kilted`` once showed as the Kilted pair run under Jazzy's Python."""
    common = sys.modules["common"]
    why = common.kilted_missing(tmp_path / ".venv-kilted")  # a venv that is not there
    assert why is not None and "no Kilted venv" in why
    absent = common.Context(
        python=sys.executable,
        runners={common.OURS: Path("ours"), common.UPSTREAM: Path("upstream")},
        work=tmp_path,
        env={},
        quick=True,
        missing={common.OURS_KILTED: why, common.KILTED: why},
    )
    line = bench_run.python_line(absent)
    assert f"ours vs Kilted upstream: not measured ({why})" in line
    assert "Kilted venv's" not in line
    assert f"Jazzy venv's `{sys.executable}`" in line
    # The control: with the Kilted pair set up, its own interpreter is named.
    kilted_python = str(tmp_path / ".venv-kilted" / "bin" / "python")
    present = common.Context(
        python=sys.executable,
        runners={
            **absent.runners,
            common.OURS_KILTED: Path("ours-kilted"),
            common.KILTED: Path("kilted"),
        },
        work=tmp_path,
        env={},
        quick=True,
        pythons={common.OURS_KILTED: kilted_python, common.KILTED: kilted_python},
    )
    line = bench_run.python_line(present)
    assert f"ours vs Kilted upstream both under the Kilted venv's `{kilted_python}`" in line
    assert "not measured" not in line

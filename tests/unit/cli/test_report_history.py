"""``report --html --history DB``: the history's words on the page; its mistakes one line.

The page itself is read in real Chromium in tests/e2e/test_history_page.py.
"""

from __future__ import annotations

from pathlib import Path

from helpers.commands import run_cli, the_error_line
from helpers.report_page import parsed
from helpers.split_trees import pytest_file, runner_file


def test_history_needs_the_page_and_a_usable_database(tmp_path: Path, env: dict[str, str]) -> None:
    runner_file(tmp_path / "run", "pkg/t", 1.0)
    page = tmp_path / "page.html"
    alone = run_cli(["report", "--history", str(tmp_path / "h.sqlite3"), str(tmp_path)], env)
    assert alone.returncode == 2
    assert "--history is shown on the page: give --html FILE too" in alone.stderr
    corrupt = tmp_path / "corrupt.sqlite3"
    corrupt.write_bytes(b"SQLite format 3\0" + b"\xff" * 4000)
    bad = run_cli(["report", "--html", str(page), "--history", str(corrupt), str(tmp_path)], env)
    assert bad.returncode == 2
    line = the_error_line(bad)
    assert line.startswith("ros-isolated-test: error: --history: history database ")
    assert str(corrupt) in line
    # Control: a database not there yet is an empty history, every test new.
    fine = run_cli(
        ["report", "--html", str(page), "--history", str(tmp_path / "none.sqlite3"),
         str(tmp_path / "run")],
        env,
    )  # fmt: skip
    assert fine.returncode == 0, fine.stderr
    dom = parsed(page.read_text())
    assert [strip.text_content() for strip in dom.xpath("//span[@class='strip']")] == ["P"]


#: pytest items the page must find in the history as it shows them: bidi controls, 10 kB,
#: SQL metacharacters.
HOSTILE = [
    "test_\u202eevil\u202c_name",
    "test_" + "x" * 10_000,
    "test_t'; DROP TABLE tests; --",
    'test_q" OR 1=1 /* %_ */',
]


def test_each_pytest_item_shows_its_strip_hostile_names_too(
    tmp_path: Path, env: dict[str, str]
) -> None:
    items = {f"test/test_it.py::{name}": 0.5 for name in HOSTILE}
    first = pytest_file(tmp_path / "run1", "pkg", items)
    second = pytest_file(tmp_path / "run2", "pkg", items)
    second.write_text(second.read_text().replace("2026-09-21T10", "2026-09-22T10"))
    db = tmp_path / "h.sqlite3"
    recorded = run_cli(["history", "record", "--db", str(db), str(first.parent)], env)
    assert recorded.returncode == 0 and recorded.stderr == ""
    page = tmp_path / "page.html"
    argv = ["report", "--html", str(page), "--history", str(db), str(second.parent)]
    assert run_cli(argv, env).returncode == 0
    dom = parsed(page.read_text())
    rows = dom.xpath("//table[@class='cases']//tr[contains(@class, 'c ')]")
    assert len(rows) == len(HOSTILE)
    for row in rows:
        assert row.xpath(".//span[@class='strip']")[0].text_content() == "PP"
    shown = " ".join(row.text_content() for row in rows)
    assert "\\u202e" in shown and "\u202e" not in shown and "DROP TABLE" in shown
    # Control: the first run's own page knows nothing before it.
    argv = ["report", "--html", str(page), "--history", str(db), str(first.parent)]
    assert run_cli(argv, env).returncode == 0
    strips = parsed(page.read_text()).xpath("//span[@class='strip']")
    assert [strip.text_content() for strip in strips] == ["P"] * len(HOSTILE)

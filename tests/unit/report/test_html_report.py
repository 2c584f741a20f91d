"""``report.html_report``: ``report --html`` writes one page for a tree, read here as HTML.

The writer reads each result file once, into the page, as ``report`` reads it, and
returns each file's report for the text report and the exit code, which stay as they
are without ``--html``. The page replaces its destination whole in one rename; the null
device discards it; a directory, FIFO or device is never replaced; memory stays bounded
as the tree grows. ``tests/e2e`` opens the page in Chromium.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from pathlib import Path

import pytest
from helpers import result_tree
from helpers.commands import CLI, run_cli
from helpers.peak_rss import measure
from helpers.report_page import parsed
from helpers.xunit import SAMPLES

from ros_isolated_test.atomic_file import NotReplaceableError
from ros_isolated_test.report import html_report
from ros_isolated_test.report.tree import read_tree
from ros_isolated_test.xunit import serialise
from ros_isolated_test.xunit.model import Case, Suite


def test_the_page_replaces_its_destination_whole_and_hands_on_each_file_as_read(
    tmp_path: Path,
) -> None:
    tree = tmp_path / "tree"
    result_tree.write_tree(tree, 60, 2)
    (tree / "Test.xml").write_text('<Site Name="vm"><Testing/></Site>')  # no result: skipped
    destination = tmp_path / "out" / "page.html"
    destination.parent.mkdir()
    destination.write_text("an old page")
    handed: list[tuple[Path, int, int]] = []
    total = html_report.write(
        [tree],
        destination,
        lambda item: handed.append((item.path, item.report.tests, item.report.failures)),
    )
    expected = [(item.path, item.report.tests, item.report.failures) for item in read_tree([tree])]
    assert handed == expected and len(handed) == 60
    assert (total.tests, total.failures) == (120, sum(failures for _, _, failures in handed))
    assert total.failures > 0  # the made-up tree has failures: they are counted
    page = parsed(destination.read_text(encoding="utf-8"))
    assert len(page.xpath("//details[@class='suite']")) == 60
    assert os.listdir(destination.parent) == ["page.html"]  # no temporary file left
    assert oct(destination.stat().st_mode & 0o777) == oct(0o644)


def test_a_files_package_is_colcons_folder_else_its_suites_prefix(tmp_path: Path) -> None:
    colcon = tmp_path / "build" / "talker_pkg" / "test_results" / "talker_pkg"
    colcon.mkdir(parents=True)
    # Ours, and named for another package: colcon's folder says where it belongs.
    elsewhere = Suite("other.t", [Case("other.C", "a")], 0.1, "2026-01-01T00:00:00", "h")
    (colcon / "a.xml").write_bytes(serialise.serialize(elsewhere))
    loose = tmp_path / "loose"
    loose.mkdir()
    ours = Suite("mine.t", [Case("mine.C", "a")], 0.1, "2026-01-01T00:00:00", "h")
    (loose / "ours.xml").write_bytes(serialise.serialize(ours))
    shutil.copy(SAMPLES / "ament_run_test_success_result.xml", loose / "theirs.xml")
    destination = tmp_path / "page.html"
    html_report.write([tmp_path / "build", loose], destination)
    page = parsed(destination.read_text(encoding="utf-8"))
    packages = page.xpath("//details[contains(@class, 'pkg')]/@data-package")
    assert sorted(packages) == ["loose", "mine", "talker_pkg"]


def test_a_destination_a_write_would_replace_is_refused_before_anything_is_read(
    tmp_path: Path,
) -> None:
    tree = tmp_path / "tree"
    result_tree.write_tree(tree, 2, 1)
    read: list[Path] = []

    def paths() -> Iterator[Path]:
        read.append(tree)
        yield tree

    fifo = tmp_path / "page.fifo"
    os.mkfifo(fifo)
    with pytest.raises(NotReplaceableError):
        html_report.write(paths(), fifo)
    with pytest.raises(IsADirectoryError):
        html_report.write(paths(), tmp_path)
    assert read == [] and fifo.exists() and not fifo.is_file()
    # The null device discards the page; the files are read all the same (the control).
    assert html_report.write(paths(), Path(os.devnull)).tests == 2
    assert read == [tree]


def test_the_text_report_and_its_exit_code_stay_with_html(
    env: dict[str, str], tmp_path: Path
) -> None:
    failing, passing = tmp_path / "failing", tmp_path / "passing"
    for sample in ("gtest-1.17.0_mixed.gtest.xml", "xmlrunner-4.0_per_class_file.xml"):
        (failing if "gtest" in sample else passing).mkdir()
        shutil.copy(SAMPLES / sample, (failing if "gtest" in sample else passing) / sample)
    for tree, code in ((failing, 1), (passing, 0)):
        plain = run_cli(["report", "-v", str(tree)], env)
        page = tmp_path / f"{tree.name}.html"
        with_page = run_cli(["report", "-v", "--html", str(page), str(tree)], env)
        assert (plain.returncode, with_page.returncode) == (code, code)
        assert with_page.stdout == plain.stdout
        assert page.is_file()


def test_a_page_that_cannot_be_written_is_one_line_and_exit_2(
    env: dict[str, str], tmp_path: Path
) -> None:
    tree = tmp_path / "tree"
    result_tree.write_tree(tree, 3, 1)
    folder = tmp_path / "a_folder"
    folder.mkdir()
    fifo = tmp_path / "a_fifo"
    os.mkfifo(fifo)
    for target, said in ((folder, "it is a directory"), (fifo, "it is a FIFO")):
        proc = run_cli(["report", "--html", str(target), str(tree)], env)
        assert proc.returncode == 2, proc.stderr
        (line,) = proc.stderr.splitlines()
        assert line.startswith(f"ros-isolated-test: error: cannot write --html {target}: {said}")
    assert fifo.exists() and not fifo.is_file()  # never replaced
    # The null device discards the page; the report is as without it.
    proc = run_cli(["report", "--html", os.devnull, str(tree)], env)
    assert proc.returncode == 0, proc.stderr
    # Control: a regular path is written.
    proc = run_cli(["report", "--html", str(tmp_path / "ok.html"), str(tree)], env)
    assert proc.returncode == 0 and (tmp_path / "ok.html").is_file()


def test_memory_stays_bounded_as_the_tree_grows(env: dict[str, str], tmp_path: Path) -> None:
    """Ten times the files and cases: the page grows ten times, the writer's memory does not."""
    peaks = {}
    for files in (150, 1500):
        tree = tmp_path / f"tree{files}"
        result_tree.write_tree(tree, files, 20)
        page = tmp_path / f"page{files}.html"
        peak = measure([CLI, "report", "--html", str(page), str(tree)], env=env)
        assert peak.returncode == 1 and not peak.timed_out
        peaks[files] = (peak.max_rss, page.stat().st_size)
    (small_rss, small_page), (big_rss, big_page) = peaks[150], peaks[1500]
    assert big_page > 8 * small_page  # the control: ten times the content was written
    assert big_rss < small_rss + 16 * 1024 * 1024, peaks


def test_memory_stays_bounded_however_many_cases_fail(env: dict[str, str], tmp_path: Path) -> None:
    """Ten times the failures, each with 60 KB of message, text and output: the page, the
    text and the JSON grow ten times, the memory of writing them does not (issue 35, 3)."""
    peaks: dict[int, dict[str, tuple[int, int]]] = {}
    for files in (100, 1000):
        tree = tmp_path / f"tree{files}"
        result_tree.write_failing_tree(tree, files)
        page, printed = tmp_path / f"page{files}.html", tmp_path / f"out{files}.txt"
        peaks[files] = {}
        for label, args in (
            ("page", ["--html", str(page)]),
            ("json", ["--json"]),
            ("text", ["-v"]),
        ):
            peak = measure([CLI, "report", *args, str(tree)], env=env, stdout=printed)
            assert peak.returncode == 1 and not peak.timed_out
            written = page.stat().st_size if label == "page" else printed.stat().st_size
            peaks[files][label] = (peak.max_rss, written)
    for label in ("page", "json", "text"):
        (small_rss, small_out), (big_rss, big_out) = peaks[100][label], peaks[1000][label]
        assert big_out > 8 * small_out, label  # the control: ten times the failures written
        assert big_rss < small_rss + 16 * 1024 * 1024, (label, peaks)

"""``xunit.kept_files``: the names beside a result path, and keeping the test's own file.

No name the runner writes beside a result path ends in ``.xml``, so no glob of results
reads the test's own file (perhaps a pass the runner never concluded) as a result; the
result path's own name is the control. Keeping a file aside links it (the original stays
at the path) and moves a directory whole; what was at the kept name gives way.
"""

from __future__ import annotations

import os
from pathlib import Path

from ros_isolated_test.xunit.kept_files import (
    attempt_original_of,
    keep_aside,
    original_of,
    remove,
)


def test_no_name_beside_a_result_path_is_read_by_a_glob_of_results(tmp_path: Path) -> None:
    result = tmp_path / "test_talker.gtest.xml"
    beside = [original_of(result), *(attempt_original_of(result, k) for k in (1, 2, 10))]
    for path in beside:
        path.touch()
    assert [path.name for path in beside] == [
        "test_talker.gtest.xml.orig",
        "test_talker.gtest.xml.attempt1.orig",
        "test_talker.gtest.xml.attempt2.orig",
        "test_talker.gtest.xml.attempt10.orig",
    ]
    result.touch()  # the control: the result path itself is found
    assert sorted(tmp_path.glob("*.xml")) == [result]


def test_a_file_is_kept_aside_by_a_link_and_a_directory_moved_whole(tmp_path: Path) -> None:
    path, original = tmp_path / "t.xml", tmp_path / "t.xml.orig"
    path.write_text("own")
    original.mkdir()  # whatever the test left at the kept name gives way
    (original / "inside").touch()
    keep_aside(path, original)
    assert path.read_text() == original.read_text() == "own"
    assert os.path.samefile(path, original)
    remove(path)
    path.mkdir()
    (path / "inside").touch()
    keep_aside(path, original)
    assert not path.exists() and (original / "inside").exists()
    remove(original)
    remove(original)  # nothing there: nothing to do
    assert not original.exists()

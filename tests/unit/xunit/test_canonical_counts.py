"""``xunit.canonical``: counts no integer can hold are read, never fatal to making a file canonical.

A producer's (or an attacker's) ``failures="inf"`` or ``errors="1e400"`` once ended a run
with a traceback; the counts are recomputed from the cases, so such a file is made
canonical from its cases like any other.
"""

from __future__ import annotations

from pathlib import Path

from ros_isolated_test.xunit.canonical import normalise_file


def test_counts_too_large_for_an_integer_are_read_not_fatal(tmp_path: Path) -> None:
    source = tmp_path / "t.xml"
    source.write_text(
        '<testsuite name="s" tests="1" failures="inf" errors="1e400">'
        '<testcase classname="C" name="a"/></testsuite>'
    )
    data, failed = normalise_file(source, "pkg", "t")
    assert b'name="a"' in data
    assert not failed

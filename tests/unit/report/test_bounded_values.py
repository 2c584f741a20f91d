"""``report.bounded_values``: one odd result file never loses the page, nor hangs it.

Each value the page draws is read within bounds where it is read; one that cannot be
drawn is drawn as unknown and named on the page. The files below are the ones that
crashed or hung ``report --html`` (issue 35, item 2): a year-1 start, waits of 1e308 s,
an attempt count of 4301 digits and one of 10^18 (a loop of 10^18 turns), and a suite
``time`` in milliseconds as another producer wrote it. Each gives a page that opens in
Chromium, the same exit code as the tree without it, and the value named; the text
report reads them too. A fuzz test over the timeline's properties (random, huge,
negative, not finite, far past and future) writes a page every time.
"""

from __future__ import annotations

import math
import random
from pathlib import Path

import pytest
from helpers import capabilities, chromium
from helpers.commands import run_cli
from helpers.report_page import parsed, timeline_bars

from ros_isolated_test.report import html_report
from ros_isolated_test.report.bounded_values import (
    LONGEST,
    MOST_ATTEMPTS,
    Reading,
    local,
    seconds_shown,
)
from ros_isolated_test.report.text_report import TextReport
from ros_isolated_test.report.tree import read_tree
from ros_isolated_test.xunit import serialise
from ros_isolated_test.xunit.model import Case, Outcome, Suite
from ros_isolated_test.xunit.timeline import timeline_properties

START = 1_790_000_000.0


def ours(properties: dict[str, str], name: str = "pkg.odd") -> bytes:
    """A canonical file of one passing case, with the runner's timeline properties."""
    found = {
        **timeline_properties(START, START + 2.0, 0.5, 0.25, "1-8"),
        "runner_version": "0.1.0",
        "ros_domain_id": "3",
        **properties,
    }
    suite = Suite(name, [Case(f"{name}.C", "a")], 2.0, "2026-09-21T14:13:20", "h", found)
    return serialise.serialize(suite)


#: The odd files, as found: what each holds, and the value the page must name.
ODD_FILES: dict[str, tuple[bytes, str]] = {
    "year 1": (ours({"started_at": "0001-01-01T00:00:00+00:00"}), "0001-01-01T00:00:00+00:00"),
    "wait for an ID 1e308": (ours({"wait_domain_seconds": "1e308"}), "wait_domain_seconds"),
    "wait for resources 1e308": (
        ours({"wait_resources_seconds": "1e308"}),
        "wait_resources_seconds",
    ),
    "attempts of 4301 digits": (ours({"attempts": "9" * 4301}), "attempts = '9999"),
    "attempts 10^18": (ours({"attempts": "1000000000000000000"}), "1000000000000000000"),
    "a suite time in milliseconds": (
        b'<testsuite name="producer" tests="1" time="1764288780000" '
        b'timestamp="2025-11-28T00:13:00"><testcase classname="C" name="a" '
        b'time="1764288780000"/></testsuite>',
        "1764288780000",
    ),
}


def test_each_reading_is_bounded_and_names_what_it_cannot_draw() -> None:
    reading = Reading()
    assert reading.instant("started_at", "2026-09-21T14:13:20Z") == 1_790_000_000.0
    assert reading.seconds("wait", "1,234.5") == 1234.5
    assert reading.count("attempts", "3") == 3
    assert (reading.instant("a", ""), reading.seconds("b", ""), reading.count("c", "")) == (
        None,
        0.0,
        None,
    )
    assert reading.odd == []  # the control: usable or unrecorded values are not named
    odd = {
        "year 1": reading.instant("s", "0001-01-01T00:00:00+00:00"),
        "year 2500": reading.instant("s", "2500-01-01T00:00:00+00:00"),
        "not a date": reading.instant("s", "yesterday"),
        "long": reading.instant("s", "2" * 5000),
        "1e308": reading.seconds("w", "1e308"),
        "negative": reading.seconds("w", "-1"),
        "nan": reading.seconds("w", "nan"),
        "inf": reading.seconds("w", "inf"),
        "over a week": reading.seconds("w", str(LONGEST + 1)),
        "digits": reading.seconds("w", "9" * 4301),
        "0 attempts": reading.count("n", "0"),
        "too many": reading.count("n", str(MOST_ATTEMPTS + 1)),
        "10^18": reading.count("n", "1000000000000000000"),
        "4301 digits": reading.count("n", "9" * 4301),
        "text": reading.count("n", "three"),
    }
    assert {name: value for name, value in odd.items() if value is not None} == {}
    assert len(reading.odd) == len(odd)
    assert max(len(line) for line in reading.odd) < 300  # a huge value is named, cut
    assert reading.odd[0] == (
        "s = '0001-01-01T00:00:00+00:00': before 2000 or after 2200: not drawn"
    )
    assert (seconds_shown(1.25), seconds_shown(1e308), seconds_shown(math.nan)) == (
        "1.250 s",
        "unknown",
        "unknown",
    )
    assert (local(1e308), local(-1e308), local(math.nan)) == ("unknown",) * 3


def _trees(root: Path, odd: bytes | None) -> Path:
    """A tree of one plain passing and one failing file of ours, and the odd file if any."""
    tree = root / ("with" if odd is not None else "without")
    tree.mkdir()
    (tree / "plain.xml").write_bytes(ours({}, "pkg.plain"))
    failing = Suite(
        "pkg.bad", [Case.saying("pkg.bad.C", "b", Outcome.FAILURE, "m")], 1.0, "", "h", {}
    )
    (tree / "bad.xml").write_bytes(serialise.serialize(failing))
    if odd is not None:
        (tree / "odd.xml").write_bytes(odd)
    return tree


@pytest.mark.parametrize("name", ODD_FILES)
def test_an_odd_file_gives_the_page_and_the_exit_code_of_the_tree_without_it(
    name: str, env: dict[str, str], tmp_path: Path
) -> None:
    data, named = ODD_FILES[name]
    without, tree = _trees(tmp_path, None), _trees(tmp_path, data)
    codes = {}
    for label, folder in (("without", without), ("with", tree)):
        page = tmp_path / f"{label}.html"
        text = run_cli(["report", str(folder)], env)
        drawn = run_cli(["report", "--html", str(page), str(folder)], env)
        assert "Traceback" not in text.stderr + drawn.stderr, text.stderr + drawn.stderr
        assert drawn.stdout == text.stdout
        codes[label] = (text.returncode, drawn.returncode)
        assert page.is_file(), drawn.stderr
    assert codes["with"] == codes["without"] == (1, 1)
    page = parsed((tmp_path / "with.html").read_text(encoding="utf-8"))
    [cell] = page.xpath("//*[@id='odd-values']")
    assert named in cell.text_content() and "odd.xml" in cell.text_content()
    assert parsed((tmp_path / "without.html").read_text()).xpath("//*[@id='odd-values']") == []


@capabilities.CHROMIUM.mark
def test_a_page_of_every_odd_file_and_of_random_values_opens_in_chromium(
    env: dict[str, str], tmp_path: Path
) -> None:
    """One page with each odd file beside the plain ones, one of fuzzed values: a few pages."""
    tree = _trees(tmp_path, None)
    for number, (data, _) in enumerate(ODD_FILES.values()):
        (tree / f"odd{number}.xml").write_bytes(data)
    page = tmp_path / "odd.html"
    proc = run_cli(["report", "--html", str(page), str(tree)], env)
    assert proc.returncode == 1, proc.stderr
    dom = chromium.dump_dom(page)
    said = dom.xpath("//*[@id='odd-values']")[0].text_content()
    assert [name for name, (_, named) in ODD_FILES.items() if named not in said] == []
    assert dom.xpath("//*[@id='total-tests']/b")[0].text == str(2 + len(ODD_FILES))
    fuzzed = _fuzzed_tree(tmp_path, 101, 40)
    html_report.write([fuzzed], page)
    dom = chromium.dump_dom(page)
    assert dom.xpath("//*[@id='total-tests']/b")[0].text == "40"
    assert dom.xpath("//*[@id='odd-values']"), "the fuzzed values are named"


# --- fuzzing the timeline's properties ---------------------------------------------------------


def _odd_number(rng: random.Random) -> str:
    return rng.choice(
        [
            repr(rng.uniform(-1e6, 1e6)),
            f"1e{rng.randint(-400, 400)}",
            str(rng.randint(-(10**30), 10**30)),
            "9" * rng.choice([1, 19, 4300, 4301, 5000]),
            rng.choice(["nan", "inf", "-inf", "NaN", "1e308", "-1e308", "1e-320", "", " "]),
            rng.choice(["0", "-0", "1,000.5", "0x10", "1_000", "½", "٣", "1e", "e5"]),
        ]
    )


def _odd_instant(rng: random.Random) -> str:
    year = rng.choice([1, 1969, 1970, 2000, 2026, 2199, 2200, 9999, rng.randint(1, 9999)])
    zone = rng.choice(["", "Z", "+00:00", "-23:59", "+14:00", "+99:00"])
    micro = rng.choice(["", ".5", ".123456", ".1234567"])
    return rng.choice(
        [
            f"{year:04d}-{rng.randint(1, 12):02d}-{rng.randint(1, 28):02d}T"
            f"{rng.randint(0, 23):02d}:{rng.randint(0, 59):02d}:00{micro}{zone}",
            _odd_number(rng),
            "".join(chr(rng.randint(32, 0x2FFF)) for _ in range(rng.randint(0, 40))),
        ]
    )


def _fuzzed_tree(root: Path, seed: int, files: int) -> Path:
    """``files`` files of ours whose timeline properties are random, odd or missing."""
    rng = random.Random(seed)
    tree = root / f"fuzz{seed}"
    tree.mkdir()
    for number in range(files):
        properties = timeline_properties(
            START + rng.uniform(-1e5, 1e5), START + rng.uniform(-1e5, 1e5), 1.0, 0.5, "1-8"
        )
        for name in list(properties):
            if rng.random() < 0.5:
                odd = _odd_instant(rng) if name.endswith("_at") else _odd_number(rng)
                properties[name] = odd
            if rng.random() < 0.1:
                del properties[name]
        if rng.random() < 0.5:
            properties["attempts"] = rng.choice([_odd_number(rng), str(rng.randint(1, 5))])
            for attempt in range(1, rng.randint(1, 4)):
                properties[f"attempt_{attempt}.started_at"] = _odd_instant(rng)
                properties[f"attempt_{attempt}.ended_at"] = _odd_instant(rng)
                properties[f"attempt_{attempt}.ros_domain_id"] = _odd_number(rng)
        properties["ros_domain_id"] = rng.choice(["3", "232", "233", _odd_number(rng)])
        case = Case(f"pkg.t{number}.C", "a", time=abs(float(rng.choice(["1", "1e12", "0"]))))
        suite = Suite(
            f"pkg.t{number}",
            [case],
            1.0,
            "2026-09-21T14:13:20",
            "h",
            {**properties, "runner_version": "0.1.0"},
        )
        (tree / f"t{number:03d}.xml").write_bytes(serialise.serialize(suite))
    return tree


@pytest.mark.parametrize("seed", range(8))
def test_random_timeline_values_always_give_a_page_and_a_text_report(
    seed: int, tmp_path: Path
) -> None:
    tree = _fuzzed_tree(tmp_path, seed, 60)
    page = tmp_path / "page.html"
    with TextReport(verbose=True) as printed:
        total = html_report.write([tree], page, printed.add)
        pieces: list[str] = []
        printed.write(pieces.append)
    assert total.tests == 60 and "Summary: 60 tests" in "".join(pieces)
    drawn = parsed(page.read_text(encoding="utf-8"))
    assert len(drawn.xpath("//details[@class='suite']")) == 60
    bars = timeline_bars(drawn)
    for bar in bars:  # every bar drawn is within the page's bounds
        start, end = float(bar.get("data-start")), float(bar.get("data-end"))
        assert 0 <= end - start <= LONGEST
    assert [item.path.name for item in read_tree([tree])][:1] == ["t000.xml"]

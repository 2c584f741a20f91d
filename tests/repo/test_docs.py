"""The documentation holds together: README.md is a front page, docs/ one page per topic.

Every relative link of README.md and docs/*.md must reach an existing file, and an
``#anchor`` a heading of that page by GitHub's slug rules, where the pages are read; a
tmp copy of the tree with links planted that break shows the check finds each kind. The
front page stays short and opens with the two set-up commands exactly as ``.ci/run`` and
a newcomer use them, every topic page is reachable from it, every test a page names as
the proof of a claim exists, and every page that gives the benchmarks' run time gives the
same one.
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest
from helpers import docs
from helpers.commands import REPO

#: The front page opens with these, exactly (the first code block, before any section).
SET_UP_COMMANDS = (
    "./scripts/demo.sh     # installs only what the demo runs into .venv, then runs it\n"
    "./scripts/test.sh     # installs what is missing, then runs the whole test suite"
)
FRONT_PAGE_LINES = 200
#: Each ``benches/run.py`` command line with its comment, in any page that shows one.
_BENCH_LINE = re.compile(
    r"benches/run\.py(?P<quick>\s+--quick)?\s+#.*?"
    r"(?P<time>about (?:an?|[0-9.]+) (?:second|minute|hour)s?)"
)


def run_times(text: str) -> dict[str, set[str]]:
    """What each page's ``benches/run.py`` lines say the full and the quick run take."""
    found: dict[str, set[str]] = {"full": set(), "quick": set()}
    for match in _BENCH_LINE.finditer(text):
        found["quick" if match["quick"] else "full"].add(match["time"])
    return found


def copy_of_the_docs(root: Path) -> Path:
    """README and docs/ copied under ``root``, everything else of the checkout linked beside
    them, so links out of the pages resolve as in the checkout."""
    root.mkdir()
    for entry in REPO.iterdir():
        if entry.name == "README.md":
            shutil.copy(entry, root / entry.name)
        elif entry.name == docs.DOCS:
            shutil.copytree(entry, root / entry.name)
        else:
            (root / entry.name).symlink_to(entry)
    return root


def plant(path: Path, text: str) -> None:
    path.write_text(path.read_text(encoding="utf-8") + text, encoding="utf-8")


def test_every_relative_link_and_anchor_in_readme_and_docs_resolves() -> None:
    links = [link for path in docs.pages() for link in docs.relative_links(path)]
    assert any("#" in link.target for link in links)  # anchors are there to check
    assert any(link.page.name == "README.md" for link in links)
    assert docs.broken_links() == [], "\n".join(map(str, docs.broken_links()))


def test_control_planted_broken_links_are_found(tmp_path: Path) -> None:
    root = copy_of_the_docs(tmp_path / "checkout")
    assert docs.broken_links(root) == []  # the copy is faithful
    plant(root / "README.md", "\nSee [the missing page](docs/no-such-page.md).\n")
    plant(root / "docs" / "install.md", "\nSee [a heading](adopting.md#no-such-heading).\n")
    plant(root / "docs" / "faults.md", "\n![a picture](images/no-such.png)\n")
    plant(root / "docs" / "reference.md", "\nA [same-page anchor](#no-such-section).\n")
    plant(root / "docs" / "reuse.md", "\nOutside: [a file](../../outside.md).\n")
    # Not links: code and a link to the web are left alone.
    plant(root / "docs" / "reuse.md", "\n`[code](nowhere.md)`\n\n```\n[x](nowhere.md)\n```\n")
    plant(root / "docs" / "reuse.md", "\n[the web](https://example.org/nowhere.md)\n")
    found = {(link.page.name, link.target) for link in docs.broken_links(root)}
    assert found == {
        ("README.md", "docs/no-such-page.md"),
        ("install.md", "adopting.md#no-such-heading"),
        ("faults.md", "images/no-such.png"),
        ("reference.md", "#no-such-section"),
        ("reuse.md", "../../outside.md"),
    }


def test_every_test_a_page_names_as_proof_exists() -> None:
    text = docs.all_text()
    assert "tests/unit/" in text and "tests/e2e/" in text and "::test_" in text  # they name tests
    assert docs.missing_tests(text) == []


def test_control_a_page_naming_a_test_that_is_gone_is_seen() -> None:
    real = (
        "`tests/unit/report/test_text_report.py::"
        "test_a_file_name_cannot_forge_a_line_of_the_report`"
    )
    assert docs.missing_tests(real) == []
    planted = f"{real}, `::test_gone` and `tests/test_report.py`"
    assert docs.missing_tests(planted) == [
        "tests/unit/report/test_text_report.py::test_gone",
        "tests/test_report.py",
    ]


@pytest.mark.parametrize(
    ("heading", "slug"),
    [
        ("Isolation modes: a domain ID, or namespaces of the test's own",
         "isolation-modes-a-domain-id-or-namespaces-of-the-tests-own"),
        ("The HTML page: `report --html`", "the-html-page-report---html"),
        ("launch_testing files, case by case", "launch_testing-files-case-by-case"),
        ("A preset partition is refused like a preset `ROS_DOMAIN_ID`",
         "a-preset-partition-is-refused-like-a-preset-ros_domain_id"),
    ],
)  # fmt: skip
def test_anchors_follow_githubs_slug_rules(heading: str, slug: str) -> None:
    assert docs.github_slug(heading) == slug


def test_a_repeated_heading_gets_a_numbered_anchor_and_code_is_no_heading() -> None:
    text = "# Top\n\n## Notes\n\n```bash\n# Notes\n```\n\n## Notes\n"
    assert docs.anchors(text) == {"top", "notes", "notes-1"}


def test_the_readme_is_a_front_page_of_at_most_200_lines() -> None:
    lines = docs.readme().splitlines()
    assert len(lines) <= FRONT_PAGE_LINES, f"README.md has {len(lines)} lines"


def test_the_readme_opens_with_the_two_set_up_commands_exactly() -> None:
    text = docs.readme()
    assert docs.code_blocks(text)[0] == SET_UP_COMMANDS
    first_block = text.index("```")
    assert "\n## " not in text[:first_block], "a section comes before the set-up commands"
    assert "./scripts/test.sh" in (REPO / ".ci" / "run").read_text(encoding="utf-8")


def test_every_docs_page_is_linked_from_the_readme() -> None:
    linked = {
        (link.page.parent / link.target.partition("#")[0]).resolve()
        for link in docs.relative_links(REPO / "README.md")
    }
    unlinked = [path.name for path in docs.pages()[1:] if path.resolve() not in linked]
    assert unlinked == []


def test_every_page_gives_the_benchmarks_the_same_run_time() -> None:
    texts = {path: path.read_text(encoding="utf-8") for path in docs.pages()}
    texts[REPO / "benches" / "README.md"] = (REPO / "benches" / "README.md").read_text(
        encoding="utf-8"
    )
    said = {path.relative_to(REPO): run_times(text) for path, text in texts.items()}
    for kind in ("full", "quick"):
        times = {path: found[kind] for path, found in said.items() if found[kind]}
        assert len(times) >= 2, (kind, times)  # benches/README.md and a docs page at least
        assert len(set().union(*times.values())) == 1, (kind, times)


def test_control_a_page_that_disagrees_on_the_run_time_is_seen() -> None:
    agreeing = run_times(
        ".venv/bin/python benches/run.py            # the full run, about 15 minutes\n"
        ".venv/bin/python benches/run.py --quick    # about 2 minutes (CI runs this)\n"
    )
    drifted = run_times(".venv/bin/python benches/run.py            # about 20 minutes\n")
    assert agreeing == {"full": {"about 15 minutes"}, "quick": {"about 2 minutes"}}
    assert drifted["full"] != agreeing["full"]

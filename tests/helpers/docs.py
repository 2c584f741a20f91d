"""The project's documentation as tests read it: the README front page and the docs/ pages.

Tests that check a command or a table the documentation shows read it through here, so
they follow the text when it moves between the front page and a topic page. The link
check resolves links as GitHub renders them (relative to the page, anchors by GitHub's
heading slugs), since that is where the pages are read.
"""

from __future__ import annotations

import os
import re
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

from helpers.commands import REPO

#: The page names of docs/ (the file name without ``.md``) are the topics.
DOCS = "docs"

_FENCE = re.compile(r"^\s{0,3}(```|~~~)")
_HEADING = re.compile(r"^\s{0,3}(#{1,6})\s+(.*?)\s*#*\s*$")
#: ``[text](target)`` and ``![alt](target)``; the text may wrap onto the next line.
_LINK = re.compile(r"!?\[(?:[^\]\\]|\\.)*\]\(\s*<?([^)\s>]*)>?(?:\s+\"[^\"]*\")?\s*\)")
_CODE_SPAN = re.compile(r"(`+)(.+?)\1", re.S)
_SCHEME = re.compile(r"^[a-zA-Z][a-zA-Z0-9+.-]*:")


def pages(root: Path = REPO) -> list[Path]:
    """README.md and every docs/*.md, the front page first."""
    return [root / "README.md", *sorted((root / DOCS).glob("*.md"))]


def readme(root: Path = REPO) -> str:
    return (root / "README.md").read_text(encoding="utf-8")


def page(name: str, root: Path = REPO) -> str:
    """The text of docs/<name>.md."""
    return (root / DOCS / f"{name}.md").read_text(encoding="utf-8")


def all_text(root: Path = REPO) -> str:
    """README and docs pages together: where a fact is, not which page holds it."""
    return "\n".join(path.read_text(encoding="utf-8") for path in pages(root))


def prose(text: str) -> list[str]:
    """The lines outside fenced code blocks, code blocks blanked (line numbers kept)."""
    lines, fenced = [], False
    for line in text.splitlines():
        if _FENCE.match(line):
            fenced = not fenced
            lines.append("")
        else:
            lines.append("" if fenced else line)
    return lines


def code_blocks(text: str) -> list[str]:
    """The contents of every fenced code block, in order."""
    blocks: list[str] = []
    current: list[str] | None = None
    for line in text.splitlines():
        if _FENCE.match(line):
            if current is None:
                current = []
            else:
                blocks.append("\n".join(current))
                current = None
        elif current is not None:
            current.append(line)
    return blocks


def github_slug(heading: str) -> str:
    """The anchor GitHub gives a heading: its text lower-cased, punctuation dropped, each
    space a hyphen (github-slugger's rule; markup is not part of the text)."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)  # a link counts by its text
    text = text.replace("`", "").replace("*", "")
    return re.sub(r"[^\w\- ]", "", text.lower()).replace(" ", "-")


def anchors(text: str) -> set[str]:
    """Every heading anchor of a page; a repeated slug gets ``-1``, ``-2``, ... as on GitHub."""
    seen: Counter[str] = Counter()
    found = set()
    for line in prose(text):
        match = _HEADING.match(line)
        if match:
            slug = github_slug(match.group(2))
            found.add(f"{slug}-{seen[slug]}" if seen[slug] else slug)
            seen[slug] += 1
    return found


@dataclass(frozen=True)
class Link:
    page: Path
    line: int
    target: str

    def __str__(self) -> str:
        return f"{self.page.name}:{self.line}: {self.target}"


def relative_links(path: Path) -> list[Link]:
    """The links of a page that point into the repository (no scheme, not code)."""
    lines = prose(path.read_text(encoding="utf-8"))
    text = _CODE_SPAN.sub(lambda m: re.sub(r"[^\n]", " ", m.group(0)), "\n".join(lines))
    links = []
    for match in _LINK.finditer(text):
        target = match.group(1)
        if target and not _SCHEME.match(target) and not target.startswith("//"):
            links.append(Link(path, text.count("\n", 0, match.start()) + 1, target))
    return links


def resolves(link: Link, root: Path = REPO) -> bool:
    """Whether a relative link reaches a file of the checkout, and its anchor a heading there.

    Lexically, as a browser does: a link may not climb out of the checkout.
    """
    file_part, _, anchor = link.target.partition("#")
    target = Path(os.path.abspath(link.page.parent / file_part)) if file_part else link.page
    if not target.exists() or not target.is_relative_to(os.path.abspath(root)):
        return False
    if not anchor:
        return True
    return target.suffix == ".md" and anchor in anchors(target.read_text(encoding="utf-8"))


def broken_links(root: Path = REPO) -> list[Link]:
    """Every relative link of README and docs/ whose file, or heading anchor, is missing."""
    return [
        link for path in pages(root) for link in relative_links(path) if not resolves(link, root)
    ]


_TEST_REFERENCE = re.compile(
    r"(?P<file>tests/[\w/.-]+\.py)(?:::(?P<test>\w+))?|(?<![\w/.])::(?P<short>\w+)"
)


def missing_tests(text: str, root: Path = REPO) -> list[str]:
    """The tests a page names as proof (``tests/x.py``, ``tests/x.py::name``, and ``::name``
    for another test of the file named last) that do not exist."""
    missing, last = [], ""
    for match in _TEST_REFERENCE.finditer(text):
        last = match["file"] or last
        name = match["test"] or match["short"]
        path = root / last
        if not path.is_file():
            missing.append(match[0])
        elif name and not re.search(rf"^\s*def {name}\(", path.read_text("utf-8"), re.M):
            missing.append(f"{last}::{name}")
    return missing

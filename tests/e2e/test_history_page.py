"""``report --html --history DB``: the page says what each failure is, read in real Chromium.

Five real runs (``ros-isolated-test run --junit-xml``) of a package: a test that always
passes, one that always fails (a hostile name: a bidi override and SQL metacharacters),
one failing on odd runs, one passing on a rerun every run, and one that passed four runs
and fails the fifth. Runs 1 to 4 are recorded; the page of run 5, opened in headless
Chromium, must say "broken since run 1", "known flaky (2 of the last 4 runs failed)" and
"new", and show each test's outcome strip (the runs before, then this one). Recording
run 5 first changes none of it: the page judges a run by the runs before it. Without
--history (the control) the page says none of it. A screenshot is kept as a CI artifact
(tests/artifacts/history_page/page.png).
"""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers import capabilities, chromium
from helpers.chromium import with_class as cls
from helpers.commands import run_cli
from lxml import html

pytestmark = [capabilities.CHROMIUM.mark]

HOSTILE = "fails_t'; DROP TABLE tests; --\u202eevil"
#: Each test's shell command; $RUN is the run's number, $MARK a file of the run's own.
SCRIPTS = {
    "always_passes": "exit 0",
    HOSTILE: "echo broken; exit 1",
    "odd_runs_fail": "if [ $((RUN % 2)) = 1 ]; then echo odd; exit 1; fi",
    "passes_on_rerun": 'if [ -e "$MARK" ]; then exit 0; fi; touch "$MARK"; echo first; exit 1',
    "fails_at_last": 'if [ "$RUN" = 5 ]; then echo now; exit 1; fi',
}
ARTIFACT = chromium.ARTIFACTS / "history_page" / "page.png"


def _run_tree(root: Path, number: int, env: dict[str, str]) -> Path:
    tree = root / f"run{number}"
    for name, script in SCRIPTS.items():
        proc = run_cli(
            [
                "run", "--junit-xml", str(tree / "pkg" / f"{name}.xml"), "--package-name", "pkg",
                "--rerun-failures", "1" if name == "passes_on_rerun" else "0",
                "--", "sh", "-c", script,
            ],
            {**env, "RUN": str(number), "MARK": str(root / f"mark-{number}-{name}")},
            cwd=root,
        )  # fmt: skip
        assert proc.returncode in (0, 1), proc.stderr
    return tree


def _page(env: dict[str, str], out: Path, tree: Path, *history: str) -> html.HtmlElement:
    proc = run_cli(["report", "--html", str(out), *history, str(tree)], env)
    assert proc.returncode == 1, proc.stdout + proc.stderr  # run 5 has failures
    assert proc.stderr == ""
    return chromium.dump_dom(out)


def _failure(dom: html.HtmlElement, name: str) -> html.HtmlElement:
    (article,) = [
        node
        for node in dom.xpath(f"//section[@id='failures']//article[{cls('case')}]")
        if name in (node.get("data-test") or "")
    ]
    return article


def _said(article: html.HtmlElement) -> tuple[str, str]:
    known = article.xpath(f".//span[{cls('known')}]")
    strip = article.xpath(f".//span[{cls('strip')}]")
    return (
        known[0].text_content() if known else "",
        strip[0].text_content() if strip else "",
    )


@pytest.mark.parametrize("recorded_first", [False, True], ids=["before", "after-recording"])
def test_the_page_says_new_known_flaky_and_broken_since(
    tmp_path: Path, env: dict[str, str], recorded_first: bool
) -> None:
    db = tmp_path / "history.sqlite3"
    trees = [_run_tree(tmp_path, number, env) for number in range(1, 6)]
    for tree in trees[:4]:
        proc = run_cli(["history", "record", "--db", str(db), str(tree)], env)
        assert proc.returncode == 0 and proc.stderr == "", proc.stderr
    if recorded_first:
        run_cli(["history", "record", "--db", str(db), str(trees[4])], env)
    page = tmp_path / "page.html"
    dom = _page(env, page, trees[4], "--history", str(db))

    broken, broken_strip = _said(_failure(dom, "evil"))
    assert broken.startswith("broken since run 1 (")
    assert broken_strip == "FFFFF"
    assert _said(_failure(dom, "odd_runs_fail")) == (
        "known flaky (2 of the last 4 runs failed)",
        "FPFPF",
    )
    assert _said(_failure(dom, "fails_at_last")) == ("new: passed its last 4 run(s)", "PPPPF")
    # The flaky test (a pass on its rerun) shows its strip, all five runs flaky.
    (flaky,) = dom.xpath(f"//section[@id='flaky']//article[{cls('case')}]")
    assert _said(flaky) == ("", "fffff")
    # Every test's block shows its strip; the one that always passed, all passes.
    (passes,) = [
        node
        for node in dom.xpath(f"//details[{cls('suite')}]")
        if "always_passes" in (node.get("data-test") or "")
    ]
    assert passes.xpath(f".//span[{cls('strip')}]")[0].text_content() == "PPPPP"
    assert len(dom.xpath(f"//details[{cls('suite')}]//span[{cls('strip')}]")) == len(SCRIPTS)
    # The hostile name is shown as the report shows it: the override as its code.
    heading = _failure(dom, "evil").xpath(".//h3")[0].text_content()
    assert "\\u202e" in heading and "\u202e" not in heading
    assert "DROP TABLE" in heading
    assert dom.xpath("//*[@id='fact-history']")

    if recorded_first:
        chromium.screenshot(page, ARTIFACT)
    else:
        # Control: without --history the page says none of it.
        plain = _page(env, tmp_path / "plain.html", trees[4])
        assert not plain.xpath(f"//span[{cls('known')}]")
        assert not plain.xpath(f"//span[{cls('strip')}]")

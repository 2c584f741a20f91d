"""The demo as a user meets it: ``examples/demo.py`` (what ``scripts/demo.sh`` runs), run whole.

The example package as written (it names no test runner), a plain ``colcon build`` and
``colcon test --ctest-args -j6`` with no flag: the colcon extension, on because the
project is installed in the suite's venv, puts each of the six tests on a domain ID of
its own and all pass; the control, the same with ``ROS_ISOLATED_TEST_COLCON=off``, runs
them all on domain 0 with ament's run_test.py, where they hear each other and fail. The
demo ends naming the page the extension wrote, which exists and shows the six tests.
``scripts/demo.sh`` installs only what this runs (``scripts/setup.sh --demo``): checked
here by reading what setup.sh skips in that mode, since a fresh install is the lead's
``.ci/run``, not a test's.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import REPO
from helpers.domains import free_ids
from helpers.report_page import page_totals, parsed

pytestmark = [pytest.mark.colcon, capabilities.COLCON.mark]

DEMO = REPO / "examples" / "demo.py"
ROW = re.compile(r"^  token_talker_\d\s+\w+\s+ROS_DOMAIN_ID=(\S+(?: \(0\))?)\s+(PASS|FAIL)", re.M)
PAGE = re.compile(r"^The page ros-isolated-test wrote for the isolated run: (.+)$", re.M)
KEPT = re.compile(r"^workspace kept: (.+)$", re.M)


@pytest.fixture(scope="module")
def demo(module_env: dict[str, str]) -> str:
    """The demo's output, run as ``scripts/demo.sh`` runs it once set up (its own pool)."""
    env = {**module_env, "ROS_ISOLATED_TEST_DOMAINS": ",".join(map(str, free_ids(8)))}
    env.pop("ROS_ISOLATED_TEST_COLCON", None)  # a user's shell: the extension as installed
    done = subprocess.run(
        [sys.executable, str(DEMO)], env=env, capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-4000:]
    assert KEPT.search(done.stdout) is not None, done.stdout[-2000:]
    return done.stdout


def _runs(output: str) -> tuple[str, str]:
    first, _, second = output.partition("\n[2/2] ")
    return first, second


def test_plain_colcon_with_the_extension_isolates_all_six(demo: str) -> None:
    isolated, _ = _runs(demo)
    assert "[1/2] extension: plain colcon build and colcon test" in isolated
    rows = ROW.findall(isolated)
    assert [verdict for _, verdict in rows] == ["PASS"] * 6, isolated
    assert len({domain for domain, _ in rows}) == 6 and all(d.isdigit() for d, _ in rows)
    assert "run_test_isolated.py" in isolated  # the runner the extension put them on
    assert "colcon test ended with: ros-isolated-test: 6 tests run, 0 failed" in isolated


def test_the_control_with_the_extension_off_hears_crosstalk(demo: str) -> None:
    _, control = _runs(demo)
    assert control.startswith("off: the same with ROS_ISOLATED_TEST_COLCON=off"), control
    rows = ROW.findall(control)
    assert len(rows) == 6 and all(domain == "unset (0)" for domain, _ in rows), control
    assert sum(verdict == "FAIL" for _, verdict in rows) >= 4, control
    assert "run_test.py" in control and "ros-isolated-test:" not in control


def test_it_ends_naming_the_page_the_extension_wrote(demo: str) -> None:
    assert demo.rstrip().splitlines()[-1].startswith("The page ros-isolated-test wrote")
    found = PAGE.search(demo)
    assert found is not None, demo[-2000:]
    page = Path(found[1])
    try:
        assert page.is_file() and page.name == "ros_isolated_test.html"
        totals = page_totals(parsed(page.read_text(encoding="utf-8")))
        assert totals == {"tests": 6, "passed": 6}, totals
    finally:
        kept = KEPT.search(demo)
        assert kept is not None
        shutil.rmtree(kept[1], ignore_errors=True)


def test_demo_sh_installs_only_what_the_demo_runs() -> None:
    """demo.sh asks setup.sh for the demo's part; that part skips the suite's venvs and tools."""
    demo_sh = (REPO / "scripts" / "demo.sh").read_text()
    assert "scripts/setup.sh --demo\n" in demo_sh
    assert "scripts/setup.sh\n" in (REPO / "scripts" / "test.sh").read_text()  # everything
    setup = (REPO / "scripts" / "setup.sh").read_text()
    everything = setup.split('else  # everything the test suite needs, to "fi  # mode"')[1]
    suite_only = everything.split("fi  # mode")[0]
    assert "docker.io" in suite_only and "npm ci" in suite_only and "chromium" in suite_only
    later = setup.split("if [[ $mode == all ]]; then\n", 1)[1].split("fi  # mode")[0]
    for venv in (".venv-kilted", ".venv-distro", "colcon-coordinator"):
        assert venv in later, venv

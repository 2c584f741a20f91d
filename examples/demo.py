"""Show ROS 2 crosstalk between parallel tests, and ros-isolated-test removing it.

Builds examples/crosstalk_demo twice in a temporary colcon workspace and runs its six tests
at once (`colcon test --ctest-args -j6`). By default as a user meets it: the package as
written (it names no test runner) in the workspace's src/, a plain `colcon build` and
`colcon test`, with ros-isolated-test's colcon extension on because it is installed where
colcon runs: each test gets a ROS_DOMAIN_ID of its own and all pass, and colcon test ends
naming the page it wrote. Then the control, the same with ROS_ISOLATED_TEST_COLCON=off:
ament's plain run_test.py, all on domain 0, the tests hear each other's tokens and fail.
The control run is what makes the first one mean something. ``--runner isolated`` (the
runner named in CMakeLists.txt) or ``upstream`` (ament_cmake_ros's) compare the explicit
routes, with a RUNNER of ament's run_test.py as their control.

Exit status 0 when the demo made its point (isolated: all pass on distinct domain IDs;
control: failures with foreign tokens), 1 otherwise. The extension's workspace is kept
when it wrote a page, so the page can be opened.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import crosstalk_workspace as ws

TITLES = {
    "extension": "plain colcon build and colcon test: ros-isolated-test's colcon extension",
    "off": "the same with ROS_ISOLATED_TEST_COLCON=off (no isolation: the control)",
    "isolated": "ros-isolated-test's runner (a ROS_DOMAIN_ID per test)",
    "upstream": "ament_cmake_ros's run_test_isolated.py (upstream isolation, for comparison)",
    "plain": "ament's run_test.py (no isolation: the control)",
}


def describe_domain(domain_id: str | None) -> str:
    return "unset (0)" if domain_id is None else domain_id


def report(step: str, run: ws.Run) -> None:
    """Print one line per test (domain, verdict, what it heard) and colcon's own totals."""
    print(f"\n[{step}] {run.runner}: {TITLES[run.runner]}")
    print(f"  runner: {run.runner_path}")
    print(f"  build {run.build_seconds:.1f} s, colcon test {run.test_seconds:.1f} s")
    for case in run.cases:
        record = case.record
        if record is None:
            print(f"  {case.name:<15} {case.token:<7} no record: the test did not get to the end")
            continue
        verdict = "PASS" if record.passed else "FAIL"
        if record.foreign:
            heard = "heard " + ", ".join(f"{t} x{n}" for t, n in sorted(record.foreign.items()))
        elif record.own_received:
            heard = f"heard only itself (x{record.own_received})"
        else:
            heard = "never heard itself"
        domain = describe_domain(record.domain_id)
        print(f"  {case.name:<15} {case.token:<7} ROS_DOMAIN_ID={domain:<9} {verdict}  {heard}")
    print(f"  colcon test-result --all: {run.result.line} (exit {run.result.returncode})")
    for line in run.test_output.splitlines():
        if line.startswith("ros-isolated-test:"):  # the colcon extension's last line
            print(f"  colcon test ended with: {line}")


def isolated_ok(run: ws.Run) -> list[str]:
    """Return what is wrong with the isolated run; empty when it proved isolation."""
    problems = []
    if not run.all_passed:
        problems.append("not every test passed")
    ids = run.domain_ids
    if None in ids or len(set(ids)) != len(ids):
        problems.append(f"domain IDs are not distinct and set: {ids}")
    if run.result.returncode != 0 or run.result.failures or run.result.errors:
        problems.append("colcon test-result reported failures")
    if run.runner == "extension" and (run.page is None or not run.page.is_file()):
        problems.append("colcon test named no page that exists")
    return problems


def control_ok(run: ws.Run) -> list[str]:
    """Return what is wrong with the control run; empty when it showed crosstalk."""
    problems = []
    if not any(c.record and c.record.foreign for c in run.cases):
        problems.append("no test heard a foreign token")
    if run.result.returncode == 0 or not (run.result.failures or run.result.errors):
        problems.append("colcon test-result reported no failures")
    return problems


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--runner",
        choices=("extension", "isolated", "upstream"),
        default="extension",
        help="what isolates: ros-isolated-test's colcon extension (default, no flag), its "
        "runner named as RUNNER, or upstream's",
    )
    parser.add_argument("--jobs", type=int, default=ws.DEFAULT_JOBS, help="ctest -j (default 6)")
    parser.add_argument("--keep", action="store_true", help="keep the temporary workspace")
    args = parser.parse_args(argv)

    if args.runner == "isolated" and (problem := ws.isolated_runner_problem()):
        print(f"demo: cannot use ros-isolated-test's runner: {problem}", file=sys.stderr)
        return 1
    if args.runner == "extension" and (problem := ws.extension_problem()):
        print(f"demo: colcon does not load ros-isolated-test's extension: {problem}",
              file=sys.stderr)  # fmt: skip
        return 1
    control = "off" if args.runner == "extension" else "plain"

    print(
        f"Six ROS 2 tests each publish a token on /crosstalk and fail if they hear a token\n"
        f"not their own. colcon runs them all at once (ctest -j{args.jobs})."
    )
    workspace = Path(tempfile.mkdtemp(prefix="crosstalk-demo-"))
    isolated: ws.Run | None = None
    try:
        isolated = ws.run(workspace, args.runner, args.jobs)
        report("1/2", isolated)
        plain = ws.run(workspace, control, args.jobs)
        report("2/2", plain)
    except ws.WorkspaceError as error:
        print(f"demo: {error}", file=sys.stderr)
        return 1
    finally:
        page = isolated.page if isolated is not None else None
        if args.keep or (page is not None and page.is_file()):
            print(f"\nworkspace kept: {workspace}")
        else:
            shutil.rmtree(workspace, ignore_errors=True)

    problems = [f"isolated run: {p}" for p in isolated_ok(isolated)]
    problems += [f"control run: {p}" for p in control_ok(plain)]
    if problems:
        print("\nThe demo did not show what it should:")
        for problem in problems:
            print(f"  - {problem}")
        if not isolated.all_passed:
            print("\ncolcon test output of the isolated run:\n" + isolated.test_output)
        return 1
    failed = sum(1 for c in plain.cases if not (c.record and c.record.passed))
    heard = sum(1 for c in plain.cases if c.record and c.record.foreign)
    print(
        f"\nWith isolation: {len(isolated.cases)} of {len(isolated.cases)} passed, "
        f"on ROS_DOMAIN_IDs {', '.join(str(d) for d in isolated.domain_ids)}.\n"
        f"Without: {failed} of {len(plain.cases)} failed; {heard} heard other tests' tokens."
    )
    if isolated.page is not None:
        print(f"The page ros-isolated-test wrote for the isolated run: {isolated.page}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

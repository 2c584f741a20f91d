"""Run every benchmark against the upstream runners and print the tables: ``python benches/run.py``.

Ours (``ros-isolated-test runner-path``) runs side by side, interleaved, with Jazzy's
upstream (ament_cmake_ros's run_test_isolated.py with ``domain_coordinator``) under the
interpreter running this script, which must be the venv that has both (the ``ros``
extra), and with Kilted's upstream (the same script name, putting rmw_test_fixture's
``run_rmw_isolated`` before the command) under the Kilted venv (``.venv-kilted``, the
``kilted`` extra), where scripts/setup.sh made one; like with like, each pair shares an
interpreter and an environment. Results are ratios of medians; absolute times are
context only, as they move with the machine's load. ``--quick`` runs each benchmark
briefly (CI runs it so the benchmarks never rot; it asserts no threshold). The output
is Markdown: docs/performance.md holds one run's output pasted as it is.

The coordinators bind upstream's TCP ports 32769-32869, and the benchmarks take all of
them at once: so that other runners on the machine are neither disturbed nor disturbing,
the benchmarks run in a private network namespace (``unshare --net``, loopback only)
where the system allows it, else on the host network (``--host-network`` forces that).
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
import traceback
from collections.abc import Callable, Sequence
from pathlib import Path

import contention
import cpu_load
import exhaustion
import gain
import history
import html_report
import import_costs
import namespace_mode
import output_volume
import overhead
import preset
import pytest_session
import shard_cost
import split
import suite
import wave_of_tests
from common import (
    KILTED,
    KILTED_VENV,
    LABELS,
    OURS,
    OURS_KILTED,
    REPO,
    UPSTREAM,
    Context,
    Section,
    base_environment,
    kilted_missing,
    kilted_runner_path,
    ms,
    ours_runner_path,
    progress,
    startup_seconds,
    upstream_runner_path,
    venv_environment,
)

BENCHMARKS: dict[str, Callable[[Context], Section]] = {
    "overhead": overhead.run,
    "contention": contention.run,
    "exhaustion": exhaustion.run,
    "output": output_volume.run,
    "suite": suite.run,
    "pytest": pytest_session.run,
    "wave": wave_of_tests.run,
    "preset": preset.run,
    "cpu_load": cpu_load.run,
    "html_report": html_report.run,
    "html_failures": html_report.run_failures,
    "imports": import_costs.run,
    "namespace": namespace_mode.run,
    "shard_cost": shard_cost.run,
    "gain": gain.run,
    "split": split.run,
    "history": history.run,
}
#: Set in the re-executed process inside the private network namespace.
NETNS_MARK = "ROS_ISOLATED_TEST_BENCH_NETNS"


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    """The command line; ``--only`` is for working on one benchmark."""
    parser = argparse.ArgumentParser(
        prog="benches/run.py",
        description="Benchmark ros-isolated-test against upstream's run_test_isolated.py.",
    )
    parser.add_argument("--quick", action="store_true", help="run each benchmark briefly")
    parser.add_argument(
        "--only",
        default=",".join(BENCHMARKS),
        help=f"comma-separated benchmarks to run (default: all of {', '.join(BENCHMARKS)})",
    )
    parser.add_argument(
        "--host-network",
        action="store_true",
        help="do not move into a private network namespace",
    )
    parser.add_argument("--keep", action="store_true", help="keep the work directory")
    args = parser.parse_args(argv)
    unknown = set(args.only.split(",")) - set(BENCHMARKS)
    if unknown:
        parser.error(f"unknown benchmark(s): {', '.join(sorted(unknown))}")
    return args


def enter_private_network(args: argparse.Namespace) -> str:
    """Re-execute in a new network namespace with loopback up; say where we run.

    Root uses ``unshare --net``; other users ``--map-root-user`` too, where the kernel
    allows unprivileged user namespaces. If neither works, the host network is used.
    """
    if os.environ.get(NETNS_MARK):
        return "a private network namespace (loopback only)"
    if args.host_network:
        return "the host network (--host-network)"
    unshare, ip = shutil.which("unshare"), shutil.which("ip")
    if unshare is None or ip is None:
        return "the host network (no unshare or ip command for a private namespace)"
    command = [unshare, "--net"] + ([] if os.geteuid() == 0 else ["--map-root-user"])
    probe = subprocess.run(
        [*command, "--", ip, "link", "set", "lo", "up"],
        capture_output=True,
        check=False,
    )
    if probe.returncode != 0:
        return "the host network (a private network namespace is not allowed here)"
    os.environ[NETNS_MARK] = "1"
    script = 'ip link set lo up && exec "$@"'
    argv = [*command, "--", "sh", "-c", script, "sh", sys.executable, *sys.orig_argv[1:]]
    sys.stdout.flush()
    os.execv(unshare, argv)
    raise AssertionError("unreachable")


def preflight() -> str | None:
    """Why the benchmarks cannot run with this interpreter, or None."""
    upstream = upstream_runner_path()
    if not upstream.is_file():
        return (
            f"upstream's runner is not at {upstream}: run this with the Python of a venv that "
            "has the ros extra (ros-jazzy-ament-cmake-ros, ros-jazzy-domain-coordinator)"
        )
    probe = subprocess.run(
        [sys.executable, "-c", "import ament_cmake_test, domain_coordinator, ros_isolated_test"],
        capture_output=True,
        text=True,
        check=False,
    )
    if probe.returncode != 0:
        return f"{sys.executable} cannot import both runners' modules: {probe.stderr.strip()}"
    return None


def _cpu_model() -> str:
    """The CPU's model name: absolute times only mean something next to it."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as handle:
            for line in handle:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def _memory() -> str:
    """Total memory, from /proc/meminfo."""
    try:
        with open("/proc/meminfo", encoding="utf-8") as handle:
            for line in handle:
                if line.startswith("MemTotal:"):
                    return f"{int(line.split()[1]) / 1024 / 1024:.0f} GiB"
    except (OSError, ValueError):
        pass
    return "unknown"


def _commit() -> str:
    """Which ros-isolated-test was measured (dirty: with uncommitted changes)."""
    proc = subprocess.run(
        ["git", "-C", str(REPO), "describe", "--always", "--dirty"],
        capture_output=True,
        text=True,
        check=False,
    )
    return proc.stdout.strip() or "unknown"


def header(ctx: Context, network: str, command: str) -> str:
    """The machine, the interpreter and its start-up cost, the date: context for the table."""
    reps = 5 if ctx.quick else 21
    progress("measuring interpreter start-up")
    warm = startup_seconds(ctx.env, reps, reexec=False)
    cold = startup_seconds(ctx.env, reps, reexec=True)
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    load = " / ".join(f"{value:.2f}" for value in os.getloadavg())
    cpus = os.cpu_count()
    usable = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else cpus
    return "\n".join(
        [
            f"- Date: {now}; command: `{command}`; ros-isolated-test at {_commit()}",
            f"- Machine: {usable} of {cpus} CPUs usable, {_cpu_model()}, {_memory()} memory, "
            f"Linux {platform.release()}; load average at start {load}",
            python_line(ctx),
            f"- Interpreter start-up (`python -u -c pass`, median of {reps}): {ms(warm)} as "
            f"under colcon (the ROS wheels' re-exec already done), {ms(cold)} from a plain "
            f"shell (the wheels re-execute the interpreter once)",
            "- Runners: "
            + "; ".join(f"{LABELS[r]} `{path}`" for r, path in ctx.runners.items())
            + "".join(f"; {LABELS[r]}: not measured ({why})" for r, why in ctx.missing.items()),
            f"- Network: {network}; lock directory private to this run; bytecode cached",
        ]
    )


def python_line(ctx: Context) -> str:
    """The header's interpreters: each pair's venv, or why the Kilted pair is not measured."""
    kilted = (
        f"ours vs Kilted upstream: not measured ({ctx.missing.get(KILTED, 'not set up')})"
        if KILTED in ctx.missing or KILTED not in ctx.runners
        else f"ours vs Kilted upstream both under the Kilted venv's `{ctx.python_of(KILTED)}`"
    )
    return (
        f"- Python: {platform.python_implementation()} {platform.python_version()}; "
        f"ours vs Jazzy upstream both under the Jazzy venv's `{ctx.python_of(UPSTREAM)}`; "
        f"{kilted} (each pair with its venv's environment, as its sourced setup gives it)"
    )


def make_context(work: Path, quick: bool) -> Context:
    """Both pairs' runners, interpreters and environments (the Kilted pair if set up)."""
    env = base_environment(work)
    runners = {OURS: ours_runner_path(), UPSTREAM: upstream_runner_path()}
    pythons = {OURS: sys.executable, UPSTREAM: sys.executable}
    envs = {OURS: env, UPSTREAM: env}
    missing: dict[str, str] = {}
    why = kilted_missing()
    if why is None:
        kilted_python = str(KILTED_VENV / "bin" / "python")
        kilted_env = venv_environment(env, KILTED_VENV, Path(sys.prefix))
        runners[OURS_KILTED] = ours_runner_path(kilted_python, kilted_env)
        runners[KILTED] = kilted_runner_path()
        for runner in (OURS_KILTED, KILTED):
            pythons[runner] = kilted_python
            envs[runner] = kilted_env
    else:
        missing = {OURS_KILTED: why, KILTED: why}
    return Context(
        python=sys.executable,
        runners=runners,
        work=work,
        env=env,
        quick=quick,
        pythons=pythons,
        envs=envs,
        missing=missing,
    )


def main(argv: Sequence[str] | None = None) -> int:
    """Run the chosen benchmarks; exit 0 unless one crashed (no thresholds are asserted)."""
    args = parse_args(sys.argv[1:] if argv is None else argv)
    network = enter_private_network(args)
    problem = preflight()
    if problem is not None:
        print(f"benches/run.py: error: {problem}", file=sys.stderr)
        return 2
    started = time.monotonic()
    work = Path(tempfile.mkdtemp(prefix="ros-isolated-test-bench-"))
    crashed: list[str] = []
    try:
        ctx = make_context(work, args.quick)
        command = "python benches/run.py" + (" --quick" if args.quick else "")
        title = "## Benchmarks: ros-isolated-test vs upstream run_test_isolated.py (Jazzy, Kilted)"
        print(title + "\n", flush=True)
        print(header(ctx, network, command) + "\n", flush=True)
        for name in args.only.split(","):
            try:
                section = BENCHMARKS[name](ctx)
            except Exception:
                crashed.append(name)
                print(f"### {name}: crashed\n\n```\n{traceback.format_exc()}```\n", flush=True)
                continue
            print(section.render() + "\n", flush=True)
    finally:
        if args.keep:
            progress(f"work directory kept: {work}")
        else:
            shutil.rmtree(work, ignore_errors=True)
    took = time.monotonic() - started
    print(f"All benchmarks took {took:.0f} s.", flush=True)
    if crashed:
        print(f"benches/run.py: crashed: {', '.join(crashed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())

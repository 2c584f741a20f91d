"""11. Import costs: what each library the product could use instead of its own code adds.

The runner starts once per test and its own work is a few milliseconds, so every module
it imports is paid by every test. Some jobs a library would do are written by hand for
that reason (the "Written by hand" table of docs/contributing.md lists them, with these
figures). This measures, for each library, what importing it adds on top of the
RUNNER's own imports (``ros_isolated_test.ament.args``), in fresh interpreters of
this venv, bytecode cached, as under colcon (the ROS wheels' re-exec already done):

- *import time*: ``-X importtime``'s cumulative time of the modules the library's import
  adds (those the RUNNER had not loaded), median of N runs;
- *wall time*: the whole process against the RUNNER's imports alone, median of N runs
  each, interleaved (the profiler's own cost is not in it; the machine's noise is).

Run alone, ``python benches/import_costs.py`` prints the table (``--quick``: fewer runs,
and only what is installed); ``benches/run.py`` runs it too. A library this venv lacks
is installed, in full mode only, into a throwaway directory put on ``PYTHONPATH`` of
every run alike (never into the venv); when that is not possible the table says so.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path

from common import (
    BOOTSTRAP_MARK,
    REPO,
    Context,
    Section,
    median,
    ms,
    parse_importtime,
    progress,
    run_timed,
)

#: What every run imports first: the ctest RUNNER's own imports.
BASELINE = "ros_isolated_test.ament.args"
#: (module imported, pip requirement, what the product does instead).
LIBRARIES = (
    ("pydantic_settings", "pydantic-settings", "settings: `runner/settings.py`"),
    ("junitparser", "junitparser", "result files: `xunit/reader.py`, `xunit/serialise.py`"),
    ("tabulate", "tabulate", "the `status` table: `cli/status_table.py`"),
    ("filelock", "filelock", "the lock: one `fcntl.flock`, `domain_coordinator/flock.py`"),
    ("xml.sax.saxutils", None, "XML escaping: `xunit/serialise.py`"),
    ("psutil", "psutil", "processes: `process/proc.py`"),
    ("dataclasses", None, "plain classes on a test's path: `runner/request.py`, `xunit/model.py`"),
    ("ctypes", None, "C library calls: `libc.py`, through `_ctypes` (which the RUNNER loads)"),
    ("shlex", None, "a command as a shell line: `text.shell_join`"),
)
_MARK = "import-costs: the library follows"
_CODE = "import {baseline}; import sys; sys.stderr.write({mark!r} + '\\n'); import {module}"


def _environment(base: Mapping[str, str], extra_path: Path | None) -> dict[str, str]:
    """Every run's environment: bytecode cached, no re-exec, the throwaway directory first."""
    env = dict(base)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    env[BOOTSTRAP_MARK] = "1"
    if extra_path is not None:
        env["PYTHONPATH"] = os.pathsep.join(
            part for part in (str(extra_path), env.get("PYTHONPATH", "")) if part
        )
    return env


def _missing(python: str, env: Mapping[str, str]) -> list[str]:
    """The modules of LIBRARIES this interpreter cannot find."""
    found = subprocess.run(
        [
            python,
            "-c",
            "import importlib.util, sys\n"
            "for name in sys.argv[1:]:\n"
            "    if importlib.util.find_spec(name) is None: print(name)",
            *(module for module, _, _ in LIBRARIES),
        ],
        env=dict(env),
        capture_output=True,
        text=True,
        check=True,
    )
    return found.stdout.split()


def _install(python: str, env: Mapping[str, str], modules: Sequence[str], target: Path) -> str:
    """Install the libraries of ``modules`` into ``target``; '' or why it failed."""
    requirements = [pip for module, pip, _ in LIBRARIES if module in modules and pip]
    progress(f"import costs: installing {', '.join(requirements)} into a throwaway directory")
    done = subprocess.run(
        [python, "-m", "pip", "install", "--quiet", "--target", str(target), *requirements],
        env=dict(env),
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        lines = (done.stderr or done.stdout).strip().splitlines()
        return lines[-1] if lines else f"pip exit code {done.returncode}"
    return ""


def _added_import_time(python: str, env: Mapping[str, str], module: str) -> tuple[float, int]:
    """Seconds of import time and the number of modules that ``import module`` adds."""
    code = _CODE.format(baseline=BASELINE, mark=_MARK, module=module)
    done = subprocess.run(
        [python, "-X", "importtime", "-c", code],
        env=dict(env),
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        check=True,
    )
    after = done.stderr.split(_MARK, 1)[1].splitlines()
    entries = parse_importtime(after)
    top = sum(cumulative for level, _, _, cumulative in entries if level == 0)
    return top / 1e6, len(entries)


def _wall(python: str, env: Mapping[str, str], module: str | None) -> float:
    """Wall seconds of a fresh interpreter importing the baseline, and ``module`` if given."""
    code = f"import {BASELINE}" + (f"; import {module}" if module else "")
    return run_timed([python, "-c", code], env).seconds


def measure(python: str, base_env: Mapping[str, str], quick: bool, work: Path) -> Section:
    """The table: each library's added import and wall time, or why it is not measured."""
    reps = 5 if quick else 21
    env = _environment(base_env, None)
    missing = _missing(python, env)
    unmeasured: dict[str, str] = {}
    if missing and quick:
        unmeasured = dict.fromkeys(missing, "not installed here (full mode installs it)")
    elif missing:
        target = work / "libraries"
        why = _install(python, env, missing, target)
        env = _environment(base_env, target)
        for module in _missing(python, env):
            unmeasured[module] = f"not installed here; pip could not install it ({why})"
    measured = [module for module, _, _ in LIBRARIES if module not in unmeasured]
    configs: list[str | None] = [None, *measured]
    for module in configs:  # warm-up: bytecode written, caches filled
        _wall(python, env, module)
    walls: dict[str | None, list[float]] = {module: [] for module in configs}
    imports: dict[str, list[float]] = {module: [] for module in measured}
    counts: dict[str, int] = {}
    progress(f"import costs: {len(configs)} imports, {reps} runs each")
    for rep in range(reps):
        for module in configs if rep % 2 == 0 else list(reversed(configs)):
            walls[module].append(_wall(python, env, module))
            if module is not None:
                seconds, counts[module] = _added_import_time(python, env, module)
                imports[module].append(seconds)
    baseline = median(walls[None])
    section = Section(
        f"11. Import costs: what a library adds to every test's start, on top of `{BASELINE}`",
        ("library", "instead of it", "modules it adds", "import time added", "wall time added"),
    )
    for module, _, instead in LIBRARIES:
        if module in unmeasured:
            section.rows.append((f"`{module}`", instead, "-", unmeasured[module], "-"))
            continue
        added = median(walls[module]) - baseline
        section.rows.append(
            (
                f"`{module}`",
                instead,
                str(counts[module]),
                ms(median(imports[module])),
                f"{added * 1000:+.1f} ms",
            )
        )
    section.notes.append(
        f"Python {sys.version.split()[0]} (`{_shown(python)}`); median of {reps} fresh "
        f"interpreters each, interleaved. A fresh interpreter importing `{BASELINE}` alone "
        f"(what the RUNNER imports) takes {ms(baseline)} of wall time. Import time is "
        "`-X importtime`'s cumulative time of the modules each library adds; wall time "
        "added is the whole process against that baseline (noisier: the machine's load is "
        "in it)."
    )
    return section


def _shown(path: str) -> str:
    """``path`` relative to the checkout when inside it: the table goes into the docs."""
    try:
        return str(Path(path).relative_to(REPO))
    except ValueError:
        return path


def run(ctx: Context) -> Section:
    """For benches/run.py: this venv's interpreter and environment, the run's scratch."""
    return measure(ctx.python, ctx.env, ctx.quick, ctx.scratch("import_costs"))


def main(argv: Sequence[str] | None = None) -> int:
    """Print the table; exit 0 (nothing is asserted)."""
    parser = argparse.ArgumentParser(
        prog="benches/import_costs.py",
        description="What each library the product could use instead of its own code adds.",
    )
    parser.add_argument("--quick", action="store_true", help="fewer runs; installed only")
    args = parser.parse_args(argv)
    work = Path(tempfile.mkdtemp(prefix="ros-isolated-test-import-costs-"))
    try:
        section = measure(sys.executable, os.environ, args.quick, work)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print(section.render())
    return 0


if __name__ == "__main__":
    sys.exit(main())

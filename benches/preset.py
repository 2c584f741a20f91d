"""8. Preset ID: what each runner does when the environment already has ROS_DOMAIN_ID.

Not timed. A developer's shell often exports ROS_DOMAIN_ID; ctest passes it on to the
runner. Three behaviours are possible: refuse (nothing is run, the user is told), keep
it (no reservation: the test shares the domain with whatever else uses it), or override
it (the test gets a reserved ID, the export is ignored). The test here prints the
domain it got, so the table says which one each runner does, from what it did.
"""

from __future__ import annotations

import subprocess

from common import LABELS, Context, Section, progress

#: The exported value: an ID no benchmark reserves (the pools are 1-101).
PRESET = "117"
_REPORT = 'echo "test ran on ROS_DOMAIN_ID=${ROS_DOMAIN_ID-unset}"'


def _behaviour(output: str, code: int) -> str:
    """Refuses / keeps / overrides, read from what the test printed and the exit code."""
    ran = [line for line in output.splitlines() if line.startswith("test ran on ")]
    if not ran:
        return f"refuses: the test did not run (exit {code})"
    value = ran[-1].removeprefix("test ran on ROS_DOMAIN_ID=")
    if value == PRESET:
        return f"keeps it: the test ran on {PRESET}, no ID reserved (exit {code})"
    return f"overrides it: the test ran on {value} (exit {code})"


def _first_word_of_its_own(output: str) -> str:
    """The runner's first line that is neither run_test.py's log nor the test's output."""
    for line in output.splitlines():
        text = line.strip()
        if text and not text.startswith(("-- run_test.py", "- ", "test ran on ")):
            return f"`{text[:200]}{'…' if len(text) > 200 else ''}`"
    return "nothing about the ID"


def run(ctx: Context) -> Section:
    """Each runner once, with ROS_DOMAIN_ID preset; what the test saw, what was said."""
    section = Section(
        f"8. Preset ID: `ROS_DOMAIN_ID={PRESET}` exported, a test that prints its domain",
        ("runner", "what it does", "what it says about it", "result file"),
    )
    scratch = ctx.scratch("preset")
    for runner in ctx.all_runners():
        progress(f"preset: {runner}")
        result = scratch / f"{runner}.xml"
        proc = subprocess.run(
            ctx.runner_command(runner, result, ("sh", "-c", _REPORT)),
            env=ctx.environment(runner, ROS_DOMAIN_ID=PRESET),
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            timeout=120,
            check=False,
        )
        said = _first_word_of_its_own(proc.stdout).replace("|", "\\|")
        section.rows.append(
            (
                LABELS[runner],
                _behaviour(proc.stdout, proc.returncode),
                said,
                "yes" if result.is_file() else "none",
            )
        )
    section.notes.append(
        "Not timed. Refusing is ours by design (a preset ID would put the test on a domain "
        "nobody reserved: docs/isolation.md's 'no silent sharing'); `DISABLE_ROS_ISOLATION=1` is "
        "the way to run on a chosen domain."
    )
    for runner, why in ctx.missing.items():
        section.notes.append(f"{LABELS[runner]}: not measured: {why}.")
    return section

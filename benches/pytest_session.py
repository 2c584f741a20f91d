"""6. The pytest plugin: what isolating a pytest session costs at its start.

A session with one trivial test, inside a ROS package (a package.xml: the plugin turns
itself on, reserves an ID, sweeps and releases it at the end) against the same session
with ``-p no:ros_isolated_test``; and outside a ROS package (the plugin loaded but
inactive) against the same. Interleaved, medians; the difference is the plugin's cost.
"""

from __future__ import annotations

from pathlib import Path

from common import Context, Section, interleaved, median, ms, progress, ratio, run_timed

TEST = "def test_nothing():\n    pass\n"
OFF = ("-p", "no:ros_isolated_test")
PLUGIN, DISABLED = "plugin", "off"


def _project(root: Path, ros: bool) -> Path:
    """A folder with one test, its own pytest.ini, and a package.xml when ``ros``."""
    (root / "test").mkdir(parents=True, exist_ok=True)
    (root / "pytest.ini").write_text("[pytest]\n")
    (root / "test" / "test_nothing.py").write_text(TEST)
    if ros:
        (root / "package.xml").write_text("<package format='3'><name>bench</name></package>\n")
    return root


def _measure(ctx: Context, root: Path, reps: int) -> dict[str, float]:
    """Median wall of the session with the plugin as it is, and turned off."""
    env = ctx.environment()
    base = [ctx.python, "-m", "pytest", "-q", "-p", "no:cacheprovider", "test"]
    commands = {PLUGIN: base, DISABLED: [*base, *OFF]}
    for command in commands.values():  # warm-up: bytecode, page cache
        run_timed(command, env, cwd=root)
    times: dict[str, list[float]] = {PLUGIN: [], DISABLED: []}
    for _rep, which in interleaved(reps, (PLUGIN, DISABLED)):
        outcome = run_timed(commands[which], env, cwd=root)
        if outcome.returncode != 0:
            raise RuntimeError(f"pytest ({which}) in {root} exited {outcome.returncode}")
        times[which].append(outcome.seconds)
    return {which: median(values) for which, values in times.items()}


def run(ctx: Context) -> Section:
    """The session's wall time with the plugin and without, in and outside a ROS package."""
    reps = 3 if ctx.quick else 21
    scratch = ctx.scratch("pytest_session")
    progress(f"pytest session: {reps} x 2 sessions in a ROS package, {reps} x 2 outside")
    active = _measure(ctx, _project(scratch / "ros", ros=True), reps)
    inactive = _measure(ctx, _project(scratch / "plain", ros=False), reps)
    section = Section(
        f"6. pytest session start: the plugin against -p no:ros_isolated_test "
        f"(one trivial test, median of {reps})",
        ("", "plugin", "-p no:ros_isolated_test", "difference", "plugin / off"),
    )
    for label, found in (
        ("in a ROS package (plugin active: reserve, sweep, release)", active),
        ("outside a ROS package (plugin inactive)", inactive),
    ):
        section.rows.append(
            (
                label,
                ms(found[PLUGIN]),
                ms(found[DISABLED]),
                ms(found[PLUGIN] - found[DISABLED]),
                ratio(found[PLUGIN], found[DISABLED]),
            )
        )
    section.notes.append(
        "The difference is what isolation costs a session once: importing the runner's "
        "policy and coordinator, one reservation, the sweep of leftovers and the release."
    )
    return section

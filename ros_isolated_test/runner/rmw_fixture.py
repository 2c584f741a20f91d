"""Kilted's rmw_test_fixture inside a test: kept off the test's ID, or started where it isolates.

What the fixture does (rmw_test_fixture_implementation, Kilted): ``run_rmw_isolated CMD``
and launch_ros's EnableRmwIsolation call ``rmw_test_isolation_start``, which does nothing
when RMW_TEST_FIXTURE_DISABLE_ISOLATION is non-empty. Else it loads the RMW's own fixture,
``lib<RMW_IMPLEMENTATION>_test_fixture.so`` (rmw_zenoh_cpp's starts a Zenoh router for the
process and points ZENOH_CONFIG_OVERRIDE at it, leaving ROS_DOMAIN_ID alone), or, where
the RMW has none (the DDS ones), its default one, which picks an ID of 1-101 by binding
127.0.0.1:32768+ID and overwrites ROS_DOMAIN_ID. The variable turns off every fixture, a
router too.

So the runner sets RMW_TEST_FIXTURE_DISABLE_ISOLATION=1 only where the default fixture
would run: the test, and anything in it that starts the fixture, keeps the ID the runner
holds, the one every record names. Where the RMW has a fixture of its own, the variable is
left alone and, as Kilted's ``run_test_isolated.py`` does for every test, the runner starts
the test under ``run_rmw_isolated``: the test gets what its RMW needs to be isolated (for
rmw_zenoh, a router of its own) beside the ID. A variable someone set is kept: a
non-empty one turns the fixture off already; an empty one asks for it, and the result
says that the test may then run on an ID of the fixture's choosing.
"""

from __future__ import annotations

import os

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

DISABLE_VAR = "RMW_TEST_FIXTURE_DISABLE_ISOLATION"
RMW_VAR = "RMW_IMPLEMENTATION"
#: What rmw_implementation loads when RMW_IMPLEMENTATION is unset (Jazzy, Kilted).
DEFAULT_RMW = "rmw_fastrtps_cpp"
#: RMWs known to have no fixture of their own: DDS ones, where the default chooses the ID.
DDS_RMWS = frozenset(
    {
        "rmw_fastrtps_cpp",
        "rmw_fastrtps_dynamic_cpp",
        "rmw_cyclonedds_cpp",
        "rmw_connextdds",
        "rmw_connextddsmicro",
        "rmw_gurumdds_cpp",
    }
)
#: Where Kilted's runner finds ``run_rmw_isolated``: the package's prefix, then this.
RUNNER_PACKAGE = "rmw_test_fixture_implementation"
RUNNER = "run_rmw_isolated"
#: The suite property saying what was done with the fixture (unset when nothing was).
PROPERTY = "rmw_test_fixture"


class Fixture:
    """What the runner does about the fixture for one test (see the module's docstring)."""

    __slots__ = ("library", "rmw", "runner", "user_value")

    def __init__(
        self, rmw: str, library: str | None, runner: str | None, user_value: str | None
    ) -> None:
        #: The RMW the test uses, and its own fixture library (None: the default fixture).
        self.rmw = rmw
        self.library = library
        #: ``run_rmw_isolated``'s path, when the RMW has a fixture of its own and it is installed.
        self.runner = runner
        #: RMW_TEST_FIXTURE_DISABLE_ISOLATION as the test's environment had it (None: unset).
        self.user_value = user_value

    @property
    def disables(self) -> bool:
        """Whether the runner sets the variable: the default fixture, nobody's value."""
        return self.library is None and self.user_value is None

    def variables(self) -> dict[str, str]:
        return {DISABLE_VAR: "1"} if self.disables else {}

    def wrapped(self, command: Sequence[str]) -> tuple[str, ...]:
        """``command`` under ``run_rmw_isolated`` where that starts the RMW's own fixture."""
        if self.runner is None or self.user_value or _runs_fixture_already(command):
            return tuple(command)
        return (self.runner, *command)

    def summary(self, domain_id: int) -> tuple[list[str], dict[str, str]]:
        """The lines and the property saying what was done, when it was not the silent default."""
        if self.library is None and self.user_value == "":
            text = (
                f"{DISABLE_VAR} is set empty, which leaves Kilted's rmw_test_fixture on: if the "
                f"test starts it (run_rmw_isolated, EnableRmwIsolation), the test runs on an ID "
                f"of the fixture's choosing, not on {domain_id}"
            )
            return [f"WARNING: {text}"], {PROPERTY: f"on ({DISABLE_VAR} set empty): {text}"}
        if self.library is None:
            return [], {}
        if self.user_value:
            return [], {PROPERTY: f"off ({DISABLE_VAR}={self.user_value} set before the runner)"}
        if self.runner is not None:
            text = (
                f"{self.rmw} has a test fixture of its own ({self.library}): the test runs "
                f"under {RUNNER}, which starts it (for rmw_zenoh_cpp, a Zenoh router of the "
                f"test's own) and leaves ROS_DOMAIN_ID {domain_id} as it is"
            )
            return [text], {PROPERTY: f"{RUNNER} in front: {text}"}
        text = (
            f"{self.rmw} has a test fixture of its own ({self.library}), but no {RUNNER} "
            f"is installed to start it (Kilted's {RUNNER_PACKAGE}): the test runs as it is"
        )
        return [text], {PROPERTY: f"not started: {text}"}


def _runs_fixture_already(command: Sequence[str]) -> bool:
    """The command is ``run_rmw_isolated ...`` itself: one fixture per process."""
    return bool(command) and os.path.basename(command[0]) == RUNNER


def decide(env: Mapping[str, str]) -> Fixture:
    """What to do for a test with environment ``env`` (before its ID is added)."""
    rmw = env.get(RMW_VAR, "").strip() or DEFAULT_RMW
    library = None if rmw in DDS_RMWS else _own_library(rmw, env)
    runner = _runner(env) if library is not None else None
    return Fixture(rmw, library, runner, env.get(DISABLE_VAR))


def _library_dirs(env: Mapping[str, str]) -> list[str]:
    """Where the loader finds a fixture library: LD_LIBRARY_PATH, then each ROS prefix's lib."""
    dirs = [item for item in env.get("LD_LIBRARY_PATH", "").split(os.pathsep) if item]
    prefixes = [item for item in env.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if item]
    return dirs + [os.path.join(prefix, "lib") for prefix in prefixes]


def _own_library(rmw: str, env: Mapping[str, str]) -> str | None:
    """The RMW's own fixture library's file name, when one is installed; else None."""
    name = f"lib{rmw}_test_fixture.so"
    if any(os.path.isfile(os.path.join(folder, name)) for folder in _library_dirs(env)):
        return name
    return None


def _runner(env: Mapping[str, str]) -> str | None:
    """``run_rmw_isolated`` of the first ROS prefix with its package (as Kilted's runner looks)."""
    for prefix in (item for item in env.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if item):
        marker = os.path.join(prefix, "share", "ament_index", "resource_index", "packages")
        if os.path.isfile(os.path.join(marker, RUNNER_PACKAGE)):
            path = os.path.join(prefix, "lib", RUNNER_PACKAGE, RUNNER)
            return path if os.access(path, os.X_OK) else None
    return None

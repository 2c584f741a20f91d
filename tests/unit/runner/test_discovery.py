"""``discovery``: how far the test's DDS discovery reaches: the environment the test receives.

A domain ID reserved on this machine means nothing to the next host, so by default the
runner confines discovery to localhost (ROS_AUTOMATIC_DISCOVERY_RANGE, or Humble's
ROS_LOCALHOST_ONLY). Every case here runs a real test command that dumps its own
environment, through the shell ``run`` and through the ctest RUNNER, and checks the
console line and the result file's properties that report the decision.
tests/e2e/test_network_isolation.py shows the same decision stopping real crosstalk. The
default and the override also run on each supported distro (the ``tools`` fixture): on
Kilted, with ROS_DISTRO=kilted, the range still goes in ROS_AUTOMATIC_DISCOVERY_RANGE.
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import pytest
from helpers import capabilities
from helpers.commands import run_cli, run_runner
from helpers.distros import Tools
from helpers.results import ResultSummary, load_result
from helpers.workspace import CrosstalkBuilds, crosstalk_workspace

if TYPE_CHECKING:  # for annotations only; at run time the module is loaded by path below
    from examples.crosstalk_workspace import Run

RANGE = "ROS_AUTOMATIC_DISCOVERY_RANGE"
ONLY = "ROS_LOCALHOST_ONLY"
PEERS = "ROS_STATIC_PEERS"
OVERRIDE = "ROS_ISOLATED_TEST_DISCOVERY_RANGE"
#: Whoever runs the suite may have these exported; every case sets them explicitly.
DISCOVERY_VARS = (RANGE, ONLY, PEERS, OVERRIDE, "ROS_DISTRO")
DOMAIN_LINE = "Running with ROS_DOMAIN_ID "
NOTE = "-- ros-isolated-test: "
DUMP = "import json, os, sys; open(sys.argv[1], 'w').write(json.dumps(dict(os.environ)))"
MODES = ["shell", "runner"]


@pytest.fixture
def denv(env: dict[str, str]) -> dict[str, str]:
    """The conftest ``env`` without any discovery variable of the caller's shell."""
    return {key: value for key, value in env.items() if key not in DISCOVERY_VARS}


@dataclass(frozen=True)
class Outcome:
    """One run of the environment-dumping test."""

    proc: subprocess.CompletedProcess[str]
    #: The environment the test process received; None if it never ran.
    seen: dict[str, str] | None
    result_file: Path

    @property
    def output(self) -> str:
        return self.proc.stdout + self.proc.stderr

    @property
    def received(self) -> dict[str, str]:
        assert self.proc.returncode == 0, self.output
        assert self.seen is not None, f"the test never ran:\n{self.output}"
        return self.seen

    @property
    def result(self) -> ResultSummary:
        return load_result(self.result_file)

    def after_domain_line(self) -> list[str]:
        """The console lines right after ``Running with ROS_DOMAIN_ID <id>``."""
        lines = self.proc.stdout.splitlines()
        found = [i for i, line in enumerate(lines) if line.startswith(DOMAIN_LINE)]
        assert len(found) == 1, f"expected one {DOMAIN_LINE!r} line:\n{self.output}"
        return lines[found[0] + 1 :]

    def discovery_line(self) -> str:
        following = self.after_domain_line()
        assert following, f"nothing after the domain line:\n{self.output}"
        line = following[0]
        assert line.startswith(NOTE + "discovery range "), (
            f"the line right after {DOMAIN_LINE!r} is not the discovery decision: {line!r}\n"
            f"{self.output}"
        )
        return line


def invoke(
    mode: str,
    runner_script: str,
    env: dict[str, str],
    tmp_path: Path,
    option: str | None = None,
    ament_env: Sequence[str] = (),
    tools: Tools | None = None,
) -> Outcome:
    """Run the dumping test through ``run`` (with ``--discovery-range option``) or the RUNNER.

    With ``tools``, the CLI, the RUNNER and the test are that distro's; else the suite's own.
    """
    seen_file = tmp_path / "seen.json"
    result = tmp_path / "out" / "pkg" / "t.xml"
    python = sys.executable if tools is None else tools.python
    command = [python, "-c", DUMP, str(seen_file)]
    if mode == "shell":
        assert not ament_env, "--env is the RUNNER's"
        chosen = ["--discovery-range", option] if option is not None else []
        args = ["run", "--junit-xml", str(result), *chosen, "--", *command]
        cli = run_cli if tools is None else tools.run_cli
        proc = cli(args, env, cwd=tmp_path)
    else:
        assert option is None, "the RUNNER takes run_test.py's arguments; use the variable"
        extra = ["--env", *ament_env] if ament_env else []
        args = [str(result), "--package-name", "pkg", "--generate-result-on-success", *extra]
        runner = run_runner if tools is None else tools.run_runner
        proc = runner(runner_script, [*args, "--command", *command], env, cwd=tmp_path)
    seen = json.loads(seen_file.read_text()) if seen_file.exists() else None
    return Outcome(proc, seen, result)


def assert_reported(outcome: Outcome, expected_range: str, source_has: str) -> dict[str, str]:
    """Console line and suite properties agree on the range; return the properties."""
    line = outcome.discovery_line()
    assert f"discovery range {expected_range} " in line, line
    assert source_has in line, line
    properties = outcome.result.properties
    assert properties.get("ros_discovery_range") == expected_range, properties
    assert source_has in properties.get("ros_discovery_range_source", ""), properties
    assert properties.get("ros_domain_id") == outcome.received["ROS_DOMAIN_ID"], properties
    return properties


# --- the default ----------------------------------------------------------------------------


@pytest.mark.parametrize("mode", MODES)
def test_default_confines_discovery_to_this_machine(
    tools: Tools, distro_runner_script: str, denv: dict[str, str], tmp_path: Path, mode: str
) -> None:
    denv = tools.env(denv)
    outcome = invoke(mode, distro_runner_script, denv, tmp_path, tools=tools)
    seen = outcome.received
    if tools.distro.name != "jazzy":  # Jazzy's environment is the suite's, as it always was
        assert seen.get("ROS_DISTRO") == tools.distro.name, "the tier is not that distro"
    assert seen[RANGE] == "LOCALHOST"
    assert ONLY not in seen
    assert PEERS not in seen
    properties = assert_reported(outcome, "LOCALHOST", "runner")
    assert "this machine" in outcome.discovery_line()
    assert "ros_static_peers" not in properties
    assert not any("WARNING" in line for line in outcome.after_domain_line()), outcome.output


@pytest.mark.parametrize("mode", MODES)
def test_empty_override_variable_means_no_override(
    runner_script: str, denv: dict[str, str], tmp_path: Path, mode: str
) -> None:
    denv[OVERRIDE] = ""
    outcome = invoke(mode, runner_script, denv, tmp_path)
    assert outcome.received[RANGE] == "LOCALHOST"
    assert_reported(outcome, "LOCALHOST", "runner")


# --- a range the user set -------------------------------------------------------------------


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("value", ["SUBNET", "LOCALHOST", "SYSTEM_DEFAULT"])
def test_users_range_is_respected_and_reported(
    runner_script: str, denv: dict[str, str], tmp_path: Path, mode: str, value: str
) -> None:
    denv[RANGE] = value
    outcome = invoke(mode, runner_script, denv, tmp_path)
    assert outcome.received[RANGE] == value
    assert_reported(outcome, value, "set by the user")


def test_range_given_with_ament_env_counts_as_the_users(
    runner_script: str, denv: dict[str, str], tmp_path: Path
) -> None:
    """``ament_add_test(... ENV ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET)`` is the package's choice."""
    outcome = invoke("runner", runner_script, denv, tmp_path, ament_env=[f"{RANGE}=SUBNET"])
    assert outcome.received[RANGE] == "SUBNET"
    assert_reported(outcome, "SUBNET", "set by the user")


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("value", ["subnet", "FOO", " SUBNET"])
def test_range_ros_does_not_know_is_reported_as_localhost_and_passed_unchanged(
    runner_script: str, denv: dict[str, str], tmp_path: Path, mode: str, value: str
) -> None:
    """ROS warns and falls back to LOCALHOST on these (measured): report what holds."""
    denv[RANGE] = value
    outcome = invoke(mode, runner_script, denv, tmp_path)
    assert outcome.received[RANGE] == value
    properties = assert_reported(outcome, "LOCALHOST", "set by the user")
    assert repr(value) in properties["ros_discovery_range_source"], properties


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("users_range", [None, "SUBNET"])
def test_users_localhost_only_on_jazzy_is_reported_as_localhost(
    runner_script: str,
    denv: dict[str, str],
    tmp_path: Path,
    mode: str,
    users_range: str | None,
) -> None:
    """ROS_LOCALHOST_ONLY=1 is deprecated but still honoured, over any range (measured)."""
    denv[ONLY] = "1"
    denv["ROS_DISTRO"] = "jazzy"
    if users_range is not None:
        denv[RANGE] = users_range
    outcome = invoke(mode, runner_script, denv, tmp_path)
    seen = outcome.received
    assert seen[ONLY] == "1"
    assert seen.get(RANGE) == users_range
    assert_reported(outcome, "LOCALHOST", f"{ONLY}=1 set by the user")


@pytest.mark.parametrize("mode", MODES)
def test_localhost_only_ros_does_not_honour_is_not_taken_for_localhost(
    runner_script: str, denv: dict[str, str], tmp_path: Path, mode: str
) -> None:
    denv[ONLY] = " 1 "
    outcome = invoke(mode, runner_script, denv, tmp_path)
    assert outcome.received.get(RANGE) == "LOCALHOST", (
        f"{ONLY}=' 1 ' is not '1' to ROS, and nothing else confines the test; reported: "
        f"{outcome.discovery_line()}"
    )


# --- --discovery-range and its variable -----------------------------------------------------

OVERRIDES = [
    ("shell", "option", "SUBNET"),
    ("shell", "option", "OFF"),
    ("shell", "option", "LOCALHOST"),
    ("shell", "option", "subnet"),
    ("shell", "variable", "SUBNET"),
    ("shell", "variable", "off"),
    ("runner", "variable", "SUBNET"),
    ("runner", "variable", "OFF"),
    ("runner", "variable", "system_default"),
]


@pytest.mark.parametrize(("mode", "how", "value"), OVERRIDES)
def test_override_wins_over_the_users_range_and_localhost_only(
    tools: Tools,
    distro_runner_script: str,
    denv: dict[str, str],
    tmp_path: Path,
    mode: str,
    how: str,
    value: str,
) -> None:
    denv = tools.env(denv)
    wanted = value.upper()
    denv[RANGE] = "SUBNET" if wanted == "LOCALHOST" else "LOCALHOST"
    denv[ONLY] = "1"  # would override any range: it has to go
    if how == "variable":
        denv[OVERRIDE] = value
    option = value if how == "option" else None
    outcome = invoke(mode, distro_runner_script, denv, tmp_path, option=option, tools=tools)
    seen = outcome.received
    assert seen[RANGE] == wanted
    assert ONLY not in seen, f"{ONLY}={seen[ONLY]} left in: it overrides {RANGE}"
    properties = assert_reported(outcome, wanted, "")
    assert "user" not in properties["ros_discovery_range_source"], properties


def test_option_wins_over_the_variable(denv: dict[str, str], tmp_path: Path) -> None:
    denv[OVERRIDE] = "OFF"
    outcome = invoke("shell", "", denv, tmp_path, option="SUBNET")
    assert outcome.received[RANGE] == "SUBNET"
    assert_reported(outcome, "SUBNET", "--discovery-range")


INVALID = [
    ("shell", "option", "FOO"),
    ("shell", "option", ""),
    ("shell", "variable", "FOO"),
    ("runner", "variable", "FOO"),
    ("runner", "variable", "LOCAL HOST"),
]


@pytest.mark.parametrize(("mode", "how", "value"), INVALID)
def test_invalid_override_is_a_usage_error_and_nothing_runs(
    runner_script: str, denv: dict[str, str], tmp_path: Path, mode: str, how: str, value: str
) -> None:
    if how == "variable":
        denv[OVERRIDE] = value
    outcome = invoke(mode, runner_script, denv, tmp_path, option=value if how == "option" else None)
    assert outcome.proc.returncode == 2, outcome.output
    assert outcome.seen is None, "a test with an unusable range must not run"
    assert DOMAIN_LINE not in outcome.proc.stdout
    assert "discovery-range" in outcome.proc.stderr or OVERRIDE in outcome.proc.stderr, (
        outcome.output
    )
    if mode == "runner":
        # ctest's reader must still find a result file saying why.
        case = outcome.result.only
        assert case.outcome in ("error", "failure"), case
        assert OVERRIDE in case.message + case.text, case
        assert repr(value) in case.message + case.text, case


# --- Humble: ROS_LOCALHOST_ONLY carries the range -------------------------------------------


@pytest.mark.parametrize("mode", MODES)
def test_humble_default_uses_localhost_only(
    runner_script: str, denv: dict[str, str], tmp_path: Path, mode: str
) -> None:
    denv["ROS_DISTRO"] = "humble"
    outcome = invoke(mode, runner_script, denv, tmp_path)
    seen = outcome.received
    assert seen[ONLY] == "1"
    assert RANGE not in seen, "Humble has no ROS_AUTOMATIC_DISCOVERY_RANGE: nothing to add"
    assert_reported(outcome, "LOCALHOST", "runner")


@pytest.mark.parametrize(("mode", "how"), [("shell", "option"), ("runner", "variable")])
@pytest.mark.parametrize("users_only", [None, "1"])
def test_humble_subnet_override_sets_localhost_only_0(
    runner_script: str,
    denv: dict[str, str],
    tmp_path: Path,
    mode: str,
    how: str,
    users_only: str | None,
) -> None:
    denv["ROS_DISTRO"] = "humble"
    if users_only is not None:
        denv[ONLY] = users_only
    if how == "variable":
        denv[OVERRIDE] = "SUBNET"
    outcome = invoke(
        mode, runner_script, denv, tmp_path, option="SUBNET" if how == "option" else None
    )
    seen = outcome.received
    assert seen[ONLY] == "0"
    assert RANGE not in seen
    assert_reported(outcome, "SUBNET", "")


@pytest.mark.parametrize(("mode", "how"), [("shell", "option"), ("runner", "variable")])
def test_humble_off_is_a_usage_error(
    runner_script: str, denv: dict[str, str], tmp_path: Path, mode: str, how: str
) -> None:
    """Humble cannot turn discovery off; running with more than asked for would be a lie."""
    denv["ROS_DISTRO"] = "humble"
    if how == "variable":
        denv[OVERRIDE] = "OFF"
    outcome = invoke(mode, runner_script, denv, tmp_path, option="OFF" if how == "option" else None)
    assert outcome.proc.returncode == 2, outcome.output
    assert outcome.seen is None
    assert "OFF" in outcome.proc.stderr and "humble" in outcome.proc.stderr, outcome.output
    case = outcome.result.only
    assert case.outcome in ("error", "failure"), case
    assert "humble" in case.message + case.text, case


@pytest.mark.parametrize("mode", MODES)
def test_humble_users_localhost_only_0_is_respected(
    runner_script: str, denv: dict[str, str], tmp_path: Path, mode: str
) -> None:
    denv["ROS_DISTRO"] = "humble"
    denv[ONLY] = "0"
    outcome = invoke(mode, runner_script, denv, tmp_path)
    assert outcome.received[ONLY] == "0"
    assert RANGE not in outcome.received
    assert_reported(outcome, "SUBNET", "set by the user")


@pytest.mark.parametrize("value", ["LOCALHOST", "subnet"])
def test_humble_ignores_the_range_variable(
    runner_script: str, denv: dict[str, str], tmp_path: Path, value: str
) -> None:
    denv["ROS_DISTRO"] = "humble"
    denv[RANGE] = value
    outcome = invoke("shell", runner_script, denv, tmp_path)
    assert outcome.received.get(ONLY) == "1", (
        f"Humble does not read {RANGE}; without {ONLY}=1 it discovers the whole subnet, "
        f"yet the runner reports {outcome.result.properties.get('ros_discovery_range')}"
    )
    assert_reported(outcome, "LOCALHOST", "runner")


# --- ROS_STATIC_PEERS -----------------------------------------------------------------------

PEER_LIST = "10.203.99.7;10.203.99.8"


def assert_peers_warned(outcome: Outcome) -> None:
    seen = outcome.received
    assert seen[PEERS] == PEER_LIST, "static peers must reach the test unchanged"
    assert seen[RANGE] == "LOCALHOST", "peers do not change the range the runner sets"
    properties = assert_reported(outcome, "LOCALHOST", "runner")
    assert properties.get("ros_static_peers") == PEER_LIST, properties
    assert PEER_LIST in outcome.discovery_line()
    warnings = [line for line in outcome.after_domain_line()[1:] if "WARNING" in line]
    assert len(warnings) == 1, outcome.output
    assert warnings[0].startswith(NOTE + "WARNING: "), warnings[0]
    assert f"{PEERS}={PEER_LIST}" in warnings[0], warnings[0]
    assert "beyond this machine" in warnings[0], warnings[0]
    # Printed with the decision, before the test starts.
    lines = outcome.after_domain_line()
    invoking = next(i for i, line in enumerate(lines) if "invoking in" in line)
    assert lines.index(warnings[0]) < invoking, outcome.output


@pytest.mark.parametrize("mode", MODES)
def test_static_peers_pass_through_with_a_warning(
    runner_script: str, denv: dict[str, str], tmp_path: Path, mode: str
) -> None:
    denv[PEERS] = PEER_LIST
    assert_peers_warned(invoke(mode, runner_script, denv, tmp_path))


def test_static_peers_given_with_ament_env_warn_too(
    runner_script: str, denv: dict[str, str], tmp_path: Path
) -> None:
    """CMake splits ``a;b`` into two ``--env`` items; the runner joins them back."""
    first, second = PEER_LIST.split(";")
    items = [f"{PEERS}={first}", second]
    assert_peers_warned(invoke("runner", runner_script, denv, tmp_path, ament_env=items))


# --- DISABLE_ROS_ISOLATION ------------------------------------------------------------------


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize(
    "users",
    [
        {},
        {RANGE: "subnet", ONLY: "1", PEERS: PEER_LIST},
        {"ROS_DISTRO": "humble", OVERRIDE: "SUBNET"},
    ],
    ids=["nothing-set", "users-vars", "humble-and-override"],
)
def test_disabled_isolation_changes_nothing_about_discovery(
    runner_script: str, denv: dict[str, str], tmp_path: Path, mode: str, users: dict[str, str]
) -> None:
    denv.update(users)
    denv["DISABLE_ROS_ISOLATION"] = "1"
    outcome = invoke(mode, runner_script, denv, tmp_path)
    seen = outcome.received
    for name in (RANGE, ONLY, PEERS):
        assert seen.get(name) == denv.get(name), f"{name} changed with isolation disabled"
    if OVERRIDE in users:
        # Asked for explicitly, so the user is told it is not applied.
        assert "is not applied: DISABLE_ROS_ISOLATION" in outcome.proc.stdout, outcome.output
    else:
        assert "discovery range" not in outcome.proc.stdout, outcome.output
    properties = outcome.result.properties
    assert properties.get("isolation") == "disabled", properties
    assert not {"ros_discovery_range", "ros_static_peers"} & properties.keys(), properties


# --- the example package's parallel suite ---------------------------------------------------


ws = crosstalk_workspace()


@pytest.fixture(scope="module")
def example_run(
    crosstalk_builds: CrosstalkBuilds, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[Run]:
    """The six-test suite at -j6 through our RUNNER, with no discovery variable of the caller."""
    with pytest.MonkeyPatch.context() as patch:
        for name in (*DISCOVERY_VARS, "ROS_ISOLATED_TEST_DOMAINS"):
            patch.delenv(name, raising=False)
        patch.setenv("ROS_ISOLATED_TEST_LOCK_DIR", str(tmp_path_factory.mktemp("example_locks")))
        run = crosstalk_builds.test("isolated")
    yield run


@pytest.mark.colcon
@capabilities.COLCON
def test_example_parallel_suite_passes_with_localhost(example_run: Run) -> None:
    """Within one host LOCALHOST must not stop a test's own nodes from finding each other."""
    failed = {
        c.name: c.record for c in example_run.cases if c.record is None or not c.record.passed
    }
    assert len(example_run.cases) == 6
    assert not failed, f"failed under LOCALHOST: {failed}\n{example_run.test_output}"
    assert all(c.record is not None and c.record.own_received > 0 for c in example_run.cases)
    result = example_run.result
    assert (result.returncode, result.errors, result.failures) == (0, 0, 0), result.line
    files = sorted((example_run.base / "build").glob(f"{ws.PACKAGE}/test_results/**/*.xml"))
    assert len(files) == 6, files
    properties = [load_result(path).properties for path in files]
    for path, found in zip(files, properties, strict=True):
        assert found.get("ros_discovery_range") == "LOCALHOST", (path, found)
        assert "runner" in found.get("ros_discovery_range_source", ""), (path, found)
    ids = [found.get("ros_domain_id", "") for found in properties]
    assert len(set(ids)) == 6, f"domain IDs shared: {ids}"
    assert sorted(ids) == sorted(str(d) for d in example_run.domain_ids), (
        "the result files disagree with the IDs the tests saw"
    )

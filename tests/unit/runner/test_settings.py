"""``settings``: read once, from options and the environment; each error names its source.

An option wins over its variable, which is then not even read; a bad value is one line
naming where it came from, at every entry point (``run``, the RUNNER, ``status``), exit
2 with a result file where a run was asked for; only ``run`` reads the rerun count; a
resource request no runner could ever give is refused at once, never waited for.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from helpers.commands import ament, run_cli
from helpers.results import load_result

from ros_isolated_test.runner import settings
from ros_isolated_test.runner.settings import (
    DEFAULT_WAIT_TIMEOUT,
    DISCOVERY_RANGE_ENV,
    LOCK_DIR_ENV,
    MAX_RERUNS,
    POOL_ENV,
    RERUNS_ENV,
    WAIT_TIMEOUT_ENV,
    SettingsError,
)


def test_defaults_and_values_from_the_environment(tmp_path: Path) -> None:
    plain = settings.read({})
    assert plain.wait_timeout == DEFAULT_WAIT_TIMEOUT
    assert plain.pool == tuple(range(1, 102))
    assert plain.discovery_range is None
    assert plain.isolation_disabled is False
    assert plain.reruns == 0
    given = settings.read(
        {
            WAIT_TIMEOUT_ENV: " 7.5 ",
            POOL_ENV: "3-4,9",
            LOCK_DIR_ENV: str(tmp_path),
            DISCOVERY_RANGE_ENV: "subnet",
            "DISABLE_ROS_ISOLATION": "yes",
            RERUNS_ENV: " 3 ",
        }
    )
    assert given.wait_timeout == 7.5
    assert given.pool == (3, 4, 9)
    assert given.lock_dir == tmp_path
    assert given.discovery_range == "SUBNET"
    assert given.isolation_disabled is True
    assert given.reruns == 3


def test_an_option_wins_and_its_variable_is_not_even_read() -> None:
    environ = {WAIT_TIMEOUT_ENV: "nan", DISCOVERY_RANGE_ENV: "nowhere", RERUNS_ENV: "many"}
    chosen = settings.read(environ, wait_timeout=3.0, discovery_range="OFF", reruns=0)
    assert (chosen.wait_timeout, chosen.discovery_range, chosen.reruns) == (3.0, "OFF", 0)


@pytest.mark.parametrize(
    ("environ", "option", "named"),
    [
        ({WAIT_TIMEOUT_ENV: "nan"}, {}, WAIT_TIMEOUT_ENV),
        ({WAIT_TIMEOUT_ENV: "inf"}, {}, WAIT_TIMEOUT_ENV),
        ({WAIT_TIMEOUT_ENV: "-1"}, {}, WAIT_TIMEOUT_ENV),
        ({WAIT_TIMEOUT_ENV: "ten"}, {}, WAIT_TIMEOUT_ENV),
        ({POOL_ENV: "0-5"}, {}, POOL_ENV),
        ({DISCOVERY_RANGE_ENV: "LOCAL HOST"}, {}, DISCOVERY_RANGE_ENV),
        ({}, {"discovery_range": "nowhere"}, "--discovery-range"),
        ({RERUNS_ENV: "-1"}, {}, RERUNS_ENV),
        ({RERUNS_ENV: "1.5"}, {}, RERUNS_ENV),
        ({RERUNS_ENV: "٣"}, {}, RERUNS_ENV),  # a digit to isdigit(), not to a user
        ({RERUNS_ENV: str(MAX_RERUNS + 1)}, {}, RERUNS_ENV),  # each attempt is kept in memory
        ({RERUNS_ENV: "9" * 5000}, {}, RERUNS_ENV),  # past int()'s digit limit: still ours
    ],
)
def test_a_bad_value_is_one_line_naming_its_source(
    environ: dict[str, str], option: dict[str, str], named: str
) -> None:
    with pytest.raises(SettingsError) as raised:
        settings.read(environ, **option)  # type: ignore[arg-type]
    message = str(raised.value)
    assert named in message and "\n" not in message
    others = {WAIT_TIMEOUT_ENV, POOL_ENV, DISCOVERY_RANGE_ENV, RERUNS_ENV, "--discovery-range"}
    others -= {named}
    assert not [other for other in others if other in message], message


@pytest.mark.parametrize("entry", ["run", "runner", "status"])
def test_every_entry_point_refuses_a_bad_variable_in_one_line_with_exit_2(
    env: dict[str, str], runner_script: str, tmp_path: Path, entry: str
) -> None:
    env[WAIT_TIMEOUT_ENV] = "nan"
    result = tmp_path / "pkg" / "r.xml"
    if entry == "run":
        proc = run_cli(["run", "--junit-xml", str(result), "--", "touch", "ran"], env, cwd=tmp_path)
    elif entry == "runner":
        proc = ament(runner_script, result, ["touch", "ran"], env, cwd=tmp_path)
    else:
        proc = run_cli(["status"], env, cwd=tmp_path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and WAIT_TIMEOUT_ENV in lines[0], proc.stderr
    assert not (tmp_path / "ran").exists()
    if entry != "status":
        case = load_result(result).only
        assert case.outcome == "error" and WAIT_TIMEOUT_ENV in case.message
    # Control: with the variable fixed, the same call goes through.
    env[WAIT_TIMEOUT_ENV] = "30"
    if entry == "run":
        again = run_cli(
            ["run", "--junit-xml", str(result), "--", "touch", "ran"], env, cwd=tmp_path
        )
    elif entry == "runner":
        again = ament(
            runner_script,
            result,
            ["touch", "ran"],
            env,
            "--generate-result-on-success",
            cwd=tmp_path,
        )
    else:
        again = run_cli(["status"], env, cwd=tmp_path)
    assert again.returncode == 0, again.stdout + again.stderr


def test_the_wait_timeout_option_is_not_read_from_the_variable_by_click(
    env: dict[str, str], tmp_path: Path
) -> None:
    """One parser: a bad variable is reported by settings (naming it), not by click."""
    env[WAIT_TIMEOUT_ENV] = "ten"
    proc = run_cli(["run", "--", "true"], env, cwd=tmp_path)
    assert proc.returncode == 2
    assert f"{WAIT_TIMEOUT_ENV}='ten' is not a number of seconds" in proc.stderr, proc.stderr
    # The option given, the variable is never read.
    given = run_cli(["run", "--wait-timeout", "5", "--", "true"], env, cwd=tmp_path)
    assert given.returncode == 0, given.stdout + given.stderr


def test_the_rerun_count_goes_up_to_its_documented_maximum() -> None:
    """The control of the cap: the maximum itself (and leading zeros) is accepted."""
    assert settings.reruns_from(str(MAX_RERUNS)) == MAX_RERUNS == 100
    assert settings.read({RERUNS_ENV: f" 0{MAX_RERUNS} "}).reruns == MAX_RERUNS


@pytest.mark.parametrize("entry", ["status", "run"])
def test_only_run_reads_the_rerun_variable(env: dict[str, str], tmp_path: Path, entry: str) -> None:
    """A bad ROS_ISOLATED_TEST_RERUNS exported for `run` never breaks `status`; `run` refuses it."""
    env[RERUNS_ENV] = "two"
    if entry == "status":
        proc = run_cli(["status"], env, cwd=tmp_path)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        assert RERUNS_ENV not in proc.stderr, proc.stderr
    else:
        result = tmp_path / "r.xml"
        proc = run_cli(["run", "--junit-xml", str(result), "--", "true"], env, cwd=tmp_path)
        assert proc.returncode == 2, proc.stdout + proc.stderr
        assert f"{RERUNS_ENV}='two' is not a number of reruns" in proc.stderr, proc.stderr
        assert load_result(result).only.outcome == "error"


RESOURCES_ENV = settings.RESOURCES_ENV
CAPACITY_ENV = settings.CAPACITY_ENV


def test_resources_from_the_variable_or_the_option() -> None:
    assert (settings.read({}).resources, settings.read({}).capacity) == ({}, {})
    from_env = settings.read({RESOURCES_ENV: "gpu=1,mem=1G"})
    assert from_env.resources == {"gpu": 1, "mem": 1 << 30}
    assert from_env.capacity["gpu"] == 1  # the capacity of every name asked for
    # The option wins, and its variable is not even read: a bad one breaks nothing.
    assert settings.read({RESOURCES_ENV: "bogus"}, resources="lidar=1").resources == {"lidar": 1}
    assert settings.read({RESOURCES_ENV: "bogus"}, resources="").resources == {}


def test_the_capacity_holds_every_name_it_sets() -> None:
    chosen = settings.read({CAPACITY_ENV: "gpu=2,lidar=3"}, resources="gpu=2")
    assert (chosen.resources, chosen.capacity) == ({"gpu": 2}, {"gpu": 2, "lidar": 3})


@pytest.mark.parametrize(
    ("environ", "option", "says"),
    [
        # Above the default capacity: 1 of any other name, this process's CPUs.
        ({RESOURCES_ENV: "gpu=2"}, {}, f"{RESOURCES_ENV}: gpu=2 is more than this machine's "),
        ({}, {"resources": "gpu=2"}, "--resources: gpu=2 is more than"),
        ({}, {"resources": "mem=1048576T"}, "--resources: mem=1048576T is more than"),
        # Above a capacity set explicitly.
        (
            {CAPACITY_ENV: "gpu=2", RESOURCES_ENV: "gpu=3"},
            {},
            f"capacity of gpu, 2 (as set in {CAPACITY_ENV})",
        ),
        # The origin an entry point names (the RUNNER's --env, a pytest option).
        ({}, {"resources": "gpu", "resources_origin": "--env X"}, "--env X: 'gpu' is not"),
        # A bad capacity, whether or not anything is asked.
        ({CAPACITY_ENV: "gpu"}, {}, f"{CAPACITY_ENV}: 'gpu' is not name=amount"),
        ({CAPACITY_ENV: "gpu=0"}, {"resources": ""}, f"{CAPACITY_ENV}: gpu='0' is zero"),
    ],
)
def test_a_request_that_cannot_be_had_is_refused_now(
    environ: dict[str, str], option: dict[str, str], says: str
) -> None:
    """Never waited for: no runner could ever give it."""
    with pytest.raises(SettingsError) as raised:
        settings.read(environ, **option)  # type: ignore[arg-type]
    message = str(raised.value)
    assert says in message and "\n" not in message, message


def test_the_default_cpu_capacity_is_a_bound_and_an_explicit_one_lifts_it() -> None:
    """The control of the refusals above: what fits is taken, at the very bound too."""
    cpus = len(os.sched_getaffinity(0))
    assert settings.read({}, resources=f"cpu={cpus}").resources == {"cpu": cpus}
    with pytest.raises(SettingsError, match=rf"capacity of cpu, {cpus} \(by default\)"):
        settings.read({}, resources=f"cpu={cpus + 1}")
    lifted = settings.read({CAPACITY_ENV: f"cpu={cpus + 1}"}, resources=f"cpu={cpus + 1}")
    assert lifted.capacity == {"cpu": cpus + 1}
    assert settings.read({CAPACITY_ENV: "gpu=2"}, resources="gpu=2").resources == {"gpu": 2}

"""``partition``: a Gazebo transport partition per test, beside its domain ID, and its switch.

Gazebo's transport ignores ROS_DOMAIN_ID, so the runner gives each test GZ_PARTITION and
IGN_PARTITION of its own: a name that carries the host, the ID and the runner's PID in
characters every transport accepts, said and recorded by a real run. The switch that
turns it off reads on/off words and refuses anything else. Whether a test gets one,
and the refusal of a partition someone else set (as a preset ROS_DOMAIN_ID is refused),
are the environment policy's (test_environment_partition.py); the real transport's
view is in the Gazebo isolation tests.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from helpers.commands import MODES
from helpers.partition_runs import SHOW, invoke
from helpers.results import domain_of, load_result

from ros_isolated_test.runner import partition, settings

SAFE = set("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-.")


# --- the name ---------------------------------------------------------------------------


def test_the_name_carries_host_id_and_runner_pid_in_safe_characters() -> None:
    assert partition.name("ci-7", 17, 4242) == "rit_ci-7_d17_4242"
    for host in ("build box/1@lab", "hôte", "a\r\nb", "", "x" * 300, "ci.example.org"):
        name = partition.name(host, 232, 4194303)
        assert set(name) <= SAFE, name
        assert name.startswith("rit_") and name.endswith("_d232_4194303"), name
        assert len(name) <= 60, name
    assert partition.name("ci.example.org", 3, 9) == "rit_ci.example.org_d3_9"


def test_names_differ_in_each_of_host_id_and_pid() -> None:
    base = ("ci-runner-0001.build.example.org.long.suffix.here", 5, 100)
    other_hosts = [
        "ci-runner-0002.build.example.org.long.suffix.here",
        "ci-runner-0001.build.example.org.long.suffix.hers",
    ]
    names = {
        partition.name(*base),
        *(partition.name(host, 5, 100) for host in other_hosts),
        partition.name(base[0], 6, 100),
        partition.name(base[0], 5, 101),
    }
    assert len(names) == 5, names


def test_this_runners_name_is_the_one_its_record_gives() -> None:
    """``status`` rebuilds it from the holder record: host (uname), ID, PID."""
    expected = partition.name(os.uname().nodename, 9, os.getpid())
    assert partition.for_this_runner(9) == expected


def test_the_variables_and_the_line_that_says_them() -> None:
    """Both variables name the one partition; the line says it, or why none is set."""
    assert partition.variables("rit_h_d3_9") == {
        "GZ_PARTITION": "rit_h_d3_9",
        "IGN_PARTITION": "rit_h_d3_9",
    }
    said = partition.describe("rit_h_d3_9")
    assert said == "Gazebo transport partition rit_h_d3_9 (GZ_PARTITION, IGN_PARTITION)"
    # The control: none set says so, naming the switch that turned it off.
    assert partition.describe(None).startswith(
        "Gazebo transport partition not set (ROS_ISOLATED_TEST_GZ_PARTITION=off): "
    )


# --- the switch -------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("value", "wanted"),
    [
        (None, True),
        ("", True),
        ("on", True),
        (" ON ", True),
        ("1", True),
        ("off", False),
        ("0", False),
        ("false", False),
        ("No", False),
    ],
)
def test_the_switch_reads_on_and_off_words(value: str | None, wanted: bool) -> None:
    assert partition.enabled(value) is wanted


@pytest.mark.parametrize("value", ["of", "disable", "2"])
def test_the_switch_refuses_anything_else_naming_itself(value: str) -> None:
    with pytest.raises(partition.PartitionSettingError, match="ROS_ISOLATED_TEST_GZ_PARTITION"):
        partition.enabled(value)
    with pytest.raises(settings.SettingsError, match=f"{value!r} is neither on nor off"):
        settings.read({partition.OPT_OUT_ENV: value})


# --- a real run: run and the RUNNER ------------------------------------------------------


@pytest.mark.parametrize("mode", MODES)
def test_each_test_gets_its_partition_said_and_recorded(
    runner_script: str, env: dict[str, str], tmp_path: Path, mode: str
) -> None:
    proc, result = invoke(mode, runner_script, env, tmp_path, ["sh", "-c", SHOW])
    assert proc.returncode == 0, proc.stdout + proc.stderr
    domain_id = domain_of(proc.stdout)
    shown = next(line for line in proc.stdout.splitlines() if line.startswith("gz="))
    runner_pid = int(shown.rsplit("runner=", 1)[1])
    name = partition.name(os.uname().nodename, domain_id, runner_pid)
    assert f"gz={name} ign={name} runner={runner_pid}\n" in proc.stdout
    said = f"-- ros-isolated-test: Gazebo transport partition {name} (GZ_PARTITION, IGN_PARTITION)"
    assert said in proc.stdout.splitlines()
    summary = load_result(result)
    assert summary.properties["gz_partition"] == name
    assert summary.properties["ros_domain_id"] == str(domain_id)

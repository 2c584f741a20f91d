"""Every environment variable and result-file property of ours: its name, meaning, readers.

One list, so the names are spelt once: code takes them from here, the command's
``--help`` epilog is generated from :data:`ENVIRONMENT`, and a test checks that
docs/reference.md and docs/result-file.md list exactly these names. Plain data with no
imports: it sits at the bottom layer, and the RUNNER imports it on every test's path.
"""

from __future__ import annotations


class Name:
    """One name: what it means, and who reads (or writes) it."""

    __slots__ = ("meaning", "name", "readers")

    def __init__(self, name: str, meaning: str, readers: str) -> None:
        self.name = name
        self.meaning = meaning
        self.readers = readers

    def __repr__(self) -> str:
        return f"Name({self.name!r})"


# --- environment variables ----------------------------------------------------------------------

DISABLE = "DISABLE_ROS_ISOLATION"
DOMAINS = "ROS_ISOLATED_TEST_DOMAINS"
LOCK_DIR = "ROS_ISOLATED_TEST_LOCK_DIR"
WAIT_TIMEOUT = "ROS_ISOLATED_TEST_WAIT_TIMEOUT"
DISCOVERY_RANGE = "ROS_ISOLATED_TEST_DISCOVERY_RANGE"
RERUNS = "ROS_ISOLATED_TEST_RERUNS"
RERUNS_FLAKY = "ROS_ISOLATED_TEST_RERUNS_FLAKY"
RESOURCES = "ROS_ISOLATED_TEST_RESOURCES"
CAPACITY = "ROS_ISOLATED_TEST_CAPACITY"
GZ_PARTITION_SWITCH = "ROS_ISOLATED_TEST_GZ_PARTITION"
ISOLATION = "ROS_ISOLATED_TEST_ISOLATION"
SHARD = "ROS_ISOLATED_TEST_SHARD"
DURATIONS = "ROS_ISOLATED_TEST_DURATIONS"
HISTORY = "ROS_ISOLATED_TEST_HISTORY"
HISTORY_BY_COLCON = "ROS_ISOLATED_TEST_HISTORY_BY_COLCON"
COLCON = "ROS_ISOLATED_TEST_COLCON"
HELD_DOMAIN_ID = "ROS_ISOLATED_TEST_HELD_DOMAIN_ID"

#: Ours first (what ``--help`` lists), then the ones of others we read or set.
ENVIRONMENT = (
    Name(
        DOMAINS,
        "the domain IDs to hand out, e.g. 1-50,215-232; default 1-101, less any "
        "whose DDS ports fall in net.ipv4.ip_local_port_range",
        "runner, plugin, status",
    ),
    Name(
        LOCK_DIR,
        "the lock directory shared by every runner on the machine",
        "runner, plugin, status",
    ),
    Name(WAIT_TIMEOUT, "seconds to wait for a free ID (run --wait-timeout)", "runner, plugin"),
    Name(
        DISCOVERY_RANGE,
        "LOCALHOST|SUBNET|OFF|SYSTEM_DEFAULT (run --discovery-range)",
        "runner, plugin",
    ),
    Name(RERUNS, "run a failed test again up to N times (run --rerun-failures)", "runner"),
    Name(
        RERUNS_FLAKY,
        "as many, only for a test the history calls flaky (run --rerun-flaky)",
        "runner",
    ),
    Name(
        RESOURCES,
        "resources the test holds, e.g. cpu=2,mem=4G,gpu=1 (run --resources)",
        "runner, plugin",
    ),
    Name(
        CAPACITY,
        "what the machine has, e.g. cpu=8,mem=16G,gpu=1,sim=2; default: the "
        "CPUs usable, MemTotal, 1 of anything else; give every runner the same",
        "runner, plugin, status",
    ),
    Name(
        GZ_PARTITION_SWITCH,
        "off: set no Gazebo partition (GZ_PARTITION, IGN_PARTITION) "
        "per test, and refuse no preset one",
        "runner, plugin",
    ),
    Name(
        ISOLATION,
        "domain|namespace|auto: namespace gives the test its own network, "
        "/dev/shm and IPC too, never waiting for an ID (run --isolation)",
        "runner, plugin",
    ),
    Name(DISABLE, "1: run without reserving an ID (loudly)", "runner, plugin"),
    Name(SHARD, "I/N: run only share I of N of the tests (run --shard)", "runner, plugin, report"),
    Name(DURATIONS, "the durations file (absolute) the split balances by", "runner, plugin, shard"),
    Name(
        HISTORY,
        "the history database run records its test into, and the pytest plugin its "
        "--junit-xml; colcon test (the extension) records its whole run there",
        "runner, plugin, history, colcon extension",
    ),
    Name(
        HISTORY_BY_COLCON,
        "set by the colcon extension for colcon test: it records the whole run, so run "
        "and the plugin under it record nothing of their own",
        "set by the colcon extension, read by the runner and the plugin",
    ),
    Name(COLCON, "off: every colcon extension of ours off", "colcon extension"),
    Name(
        HELD_DOMAIN_ID,
        "set by the runner in the test's environment: the ID it reserved",
        "set by the runner, read by the plugin",
    ),
    Name(
        "ROS_DOMAIN_ID",
        "refused when preset; set by the runner to the ID it reserved",
        "runner, plugin",
    ),
    Name("GZ_PARTITION", "refused when preset; set by the runner per test", "runner, plugin"),
    Name("IGN_PARTITION", "refused when preset; set by the runner per test", "runner, plugin"),
    Name(
        "RMW_TEST_FIXTURE_DISABLE_ISOLATION",
        "set by the runner where Kilted's rmw_test_fixture would choose an ID of its own",
        "set by the runner",
    ),
    Name(
        "COLCON_EXTENSION_BLOCKLIST",
        "colcon's own: naming colcon's domain-ID coordinator or ours turns it off",
        "runner, colcon extension",
    ),
)

# --- result-file properties (of the suite; ``attempt_<k>.<name>``: an earlier attempt's) -------

COMMAND = "command"
DOMAIN_ID = "ros_domain_id"
EXIT = "exit"
EXIT_CODE = "exit_code"
SIGNAL = "signal"
DURATION = "duration"
RUNNER_VERSION = "runner_version"
STARTED_AT = "started_at"
ENDED_AT = "ended_at"
WAIT_DOMAIN = "wait_domain_seconds"
WAIT_RESOURCES = "wait_resources_seconds"
DOMAIN_POOL = "domain_pool"
GZ_PARTITION = "gz_partition"
SHARD_PROPERTY = "shard"
SHARD_PLAN = "shard_plan"
ATTEMPTS = "attempts"
FLAKY_CASES = "flaky_cases"
RENAMED_CASES = "renamed_cases"
RESULT_FILE_IN_PLACE = "result_file_in_place"
PLACEHOLDER_WRITTEN_AT = "placeholder_written_at"
IDENTITY = "ros_isolated_test_identity"
SECONDS = "ros_isolated_test_seconds"
ROS_DOMAIN_IDS = "ros_domain_ids"
ROS_DOMAIN_ID_RESERVED = "ros_domain_id_reserved"
ROS_DOMAIN_ID_REPLACED = "ros_domain_id_replaced"
ISOLATION_PROPERTY = "isolation"
ROS_DISCOVERY_RANGE = "ros_discovery_range"
ROS_DISCOVERY_RANGE_SOURCE = "ros_discovery_range_source"
RMW_TEST_FIXTURE = "rmw_test_fixture"
SIGNAL_RECEIVED = "signal_received"
SIGNAL_AFTER_TEST = "signal_after_test"
RESOURCES_PROPERTY = "resources"
RESOURCES_WAITED = "resources_waited"
CAPACITY_PROPERTY = "capacity"
SETTINGS_NOTES = "settings_notes"
RERUN_FAILURES = "rerun_failures"
RERUN_FLAKY = "rerun_flaky"
RERUN_NOT_RUN = "rerun_not_run"
RESULT_FILE_REPAIRS = "result_file_repairs"
ORIGINAL_RESULT_FILE = "original_result_file"
ORIGINAL_RESULT_FILE_ERROR = "original_result_file_error"
OUTPUT_FILE_ERROR = "output_file_error"
CONSOLE_ERROR = "console_error"
RESULT_WRITE_ERROR = "result_write_error"
LEFTOVER_PROCESSES = "leftover_processes"
SURVIVING_PROCESSES = "surviving_processes"
#: How an earlier attempt's properties are named: ``attempt_1.exit_code``.
ATTEMPT_PREFIX = "attempt_{number}."

PROPERTIES = (
    Name(COMMAND, "the test's command line", "report"),
    Name(DOMAIN_ID, "the domain ID the test ran on", "report, history"),
    Name(ROS_DOMAIN_IDS, "every attempt's ID, after reruns", "report"),
    Name(ROS_DOMAIN_ID_RESERVED, "yes: reserved by the runner (namespace isolation)", "report"),
    Name(ROS_DOMAIN_ID_REPLACED, "an ID another tool set, replaced by ours", "report"),
    Name(GZ_PARTITION, "the Gazebo partition the test had", "report, status"),
    Name(ISOLATION_PROPERTY, "domain, namespace, or why not isolated", "report, colcon summary"),
    Name(ROS_DISCOVERY_RANGE, "the test's discovery range", "report"),
    Name(ROS_DISCOVERY_RANGE_SOURCE, "where its discovery range came from", "report"),
    Name(RMW_TEST_FIXTURE, "what Kilted's rmw_test_fixture did in the test", "report"),
    Name(EXIT, "how the test ended, in words", "report, history"),
    Name(EXIT_CODE, "the test's exit code", "report"),
    Name(SIGNAL, "the signal that killed the test", "report"),
    Name(SIGNAL_RECEIVED, "the signal the runner got before the test started", "report"),
    Name(SIGNAL_AFTER_TEST, "the signal the runner got after the test ended", "report"),
    Name(DURATION, "seconds the test ran", "report, history"),
    Name(
        STARTED_AT,
        "when the command started (local ISO 8601, microseconds, zone)",
        "report, history",
    ),
    Name(ENDED_AT, "when the command ended", "report"),
    Name(WAIT_DOMAIN, "seconds waited for an ID", "report"),
    Name(WAIT_RESOURCES, "seconds waited for the resources asked for", "report"),
    Name(DOMAIN_POOL, "the pool the ID came from", "report"),
    Name(RESOURCES_PROPERTY, "the resources the test held", "report"),
    Name(RESOURCES_WAITED, "seconds waited for them", "report"),
    Name(CAPACITY_PROPERTY, "the machine's capacity", "report"),
    Name(RUNNER_VERSION, "the runner's version: the file is ours", "report, history"),
    Name(SETTINGS_NOTES, "notes on the settings, as printed", "report"),
    Name(SHARD_PROPERTY, "the share that ran the test, I/N", "report, history"),
    Name(
        SHARD_PLAN,
        "the plan of the split: the durations file's fingerprint, or count",
        "report, history",
    ),
    Name(ATTEMPTS, "how many attempts ran", "report, history"),
    Name(FLAKY_CASES, "how many cases passed after failing", "report"),
    Name(RENAMED_CASES, "cases renamed apart for GitLab's keys", "report"),
    Name(RERUN_FAILURES, "the reruns allowed", "report"),
    Name(RERUN_FLAKY, "the reruns allowed because the test history calls the test flaky", "report"),
    Name(RERUN_NOT_RUN, "why a rerun did not run", "report"),
    Name(RESULT_FILE_REPAIRS, "what was fixed in the test's own file", "report"),
    Name(RESULT_FILE_IN_PLACE, "the test wrote its file in place itself", "report"),
    Name(PLACEHOLDER_WRITTEN_AT, "when the placeholder was written", "report"),
    Name(ORIGINAL_RESULT_FILE, "where the test's own file is kept", "report"),
    Name(ORIGINAL_RESULT_FILE_ERROR, "why the test's own file could not be read", "report"),
    Name(OUTPUT_FILE_ERROR, "why --output-file lost output", "report"),
    Name(CONSOLE_ERROR, "why the console lost output", "report"),
    Name(RESULT_WRITE_ERROR, "why the full result could not be written", "report"),
    Name(LEFTOVER_PROCESSES, "processes the test left, ended by the runner", "report"),
    Name(SURVIVING_PROCESSES, "processes that could not be ended", "report"),
    Name(IDENTITY, "a pytest item's test under the plugin (a case property)", "report, shard"),
    Name(
        SECONDS,
        "a pytest item's run time, to the microsecond (a case property)",
        "report --durations",
    ),
)

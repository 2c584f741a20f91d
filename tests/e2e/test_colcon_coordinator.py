"""colcon's domain-ID coordinator active in colcon: its ID is a tool's, replaced; a user's is not.

colcon-ros-domain-id-coordinator (scripts/setup.sh installs it apart, given to colcon on
PYTHONPATH here only) sets ROS_DOMAIN_ID for every colcon task, one ID per package, and
holds it by binding TCP 32768+ID for the task's life. A workspace of two unmodified
ament_cmake packages (three rclpy token talkers each) and an ament_python one, built once
with the zero-edit recipe and tested once with packages and tests in parallel: every test
runs on an ID of its own from our pool, none of them one colcon allocated during the run
(its debug log names each), and says that it replaced colcon's; ``status``, read while it
runs, names colcon's IDs as colcon's and our runners as having replaced them. A
ROS_DOMAIN_ID the user set is still refused under the same colcon. Control: the same
packages built without the recipe run on colcon's IDs, one per package, and the talkers of
one package hear each other.

An ID a package's environment hook sets (``set;ROS_DOMAIN_ID;<id>`` in a dependency's
``domain.dsv``) is colcon's doing but no coordinator's: refused, with the coordinator not
installed whether or not another process holds 32768+ID (bound as our runner holds its
ID, or listening), and with it installed too (it holds the ID it gave, not the hook's).
Both packages are built with the others; each case is one cheap ``colcon test`` of one.
"""

from __future__ import annotations

import re
import socket
import subprocess
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import pytest
from helpers import capabilities
from helpers.commands import run_cli
from helpers.domains import free_ids
from helpers.results import load_result
from helpers.workspace import crosstalk_workspace, two_talker_packages

from ros_isolated_test.domain_coordinator.pool import parse_pool
from ros_isolated_test.domain_coordinator.status import DomainUse, domain_uses
from ros_isolated_test.process import proc

if TYPE_CHECKING:  # annotations only; at run time the module is loaded by path
    from examples.crosstalk_workspace import Record

pytestmark = [
    pytest.mark.colcon,
    capabilities.COLCON.mark,
    capabilities.COLCON_COORDINATOR.mark,
]

#: The second ament_cmake package: zero_edit_talkers under another name, with other tokens.
SECOND = ("coordinated_talkers", ("oak", "pine", "rowan"))
PACKAGE_OF = {
    **dict.fromkeys(("ivy", "juniper", "kale"), "zero_edit_talkers"),
    **dict.fromkeys(SECOND[1], SECOND[0]),
    "nettle": "zero_edit_py",
}
CMAKE_TOKENS = sorted(token for token, package in PACKAGE_OF.items() if package != "zero_edit_py")
RECIPE = "colcon build --cmake-args -DCMAKE_PROJECT_INCLUDE=$(ros-isolated-test cmake-include)"
#: A package whose environment hook sets ROS_DOMAIN_ID, and one whose test depends on it.
HOOK, HOOKED = "domain_hook", "hooked_test"
IN_PARALLEL = (
    f"colcon --log-level debug test --packages-skip {HOOK} {HOOKED} --parallel-workers 3 "
    "--ctest-args -j3"
)
#: colcon given no coordinator: nothing on PYTHONPATH (it is not installed anywhere else).
NO_COORDINATOR = {"PYTHONPATH": ""}
ALLOCATED = re.compile(r"Allocated ROS_DOMAIN_ID=(\d+) for '([^']+)'")
#: The runner's first line when it replaced colcon's ID.
REPLACING = re.compile(
    r"Running with ROS_DOMAIN_ID (\d+) .*, replacing ROS_DOMAIN_ID (\d+) of colcon's "
    r"domain-ID coordinator"
)


@dataclass(frozen=True)
class Run:
    """One ``colcon test`` of the workspace: what its tests recorded and what colcon logged."""

    records: dict[str, Record]
    #: Package name -> the ID colcon's coordinator allocated for its test task.
    allocated: dict[str, int]
    output: str
    #: What ``status`` saw while the tests ran (each ID in use, read in this process), the
    #: first time it saw a runner that replaced colcon's ID beside colcon's own; the rows
    #: of any other colcon on the machine left out.
    seen: list[DomainUse]
    #: ``status``'s table, printed by the CLI at the moment it saw a replaced ID.
    table: str


class Workspace:
    """The packages in a folder of their own, colcon given the coordinator on PYTHONPATH."""

    def __init__(self, root: Path, env: Mapping[str, str]) -> None:
        self.root = root
        two_talker_packages(root, *SECOND)
        _hook_packages(root / "src" / "hooked")
        ws = crosstalk_workspace()
        self.env: dict[str, str] = ws.colcon_env(ws.Toolchain(base_env=env))
        self.env["COLCON_HOME"] = str(root / "colcon-home")
        self.env.pop("COLCON_DEFAULTS_FILE", None)
        # The coordinator, for this workspace's colcon only (and what colcon starts).
        self.env["PYTHONPATH"] = str(capabilities.COLCON_COORDINATOR_DIR)

    def start(
        self, line: str, records: Path, extra: Mapping[str, str] | None = None
    ) -> subprocess.Popen[str]:
        records.mkdir(parents=True, exist_ok=True)
        env = {**self.env, "CROSSTALK_RECORD_DIR": str(records), **(extra or {})}
        return subprocess.Popen(
            ["bash", "-c", line], cwd=self.root, env=env,
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        )  # fmt: skip

    def shell(self, line: str, records: Path, extra: Mapping[str, str] | None = None) -> str:
        process = self.start(line, records, extra)
        output, _ = process.communicate()
        return output

    def allocated(self, log_base: str) -> dict[str, int]:
        """What the coordinator allocated for each package's task, from colcon's debug log."""
        text = (self.root / log_base / "latest_test" / "logger_all.log").read_text()
        return {Path(base).name: int(domain) for domain, base in ALLOCATED.findall(text)}


_MANIFEST = """\
<?xml version="1.0"?>
<package format="3">
  <name>{name}</name>
  <version>0.1.0</version>
  <description>{description}</description>
  <maintainer email="maintainer@example.com">Example Maintainer</maintainer>
  <license>Apache-2.0</license>
  <buildtool_depend>ament_cmake</buildtool_depend>
{depends}  <export><build_type>ament_cmake</build_type></export>
</package>
"""
_LISTS = """\
cmake_minimum_required(VERSION 3.15)
project({name} NONE)
find_package(ament_cmake REQUIRED)
{body}
ament_package()
"""


def _hook_packages(root: Path) -> None:
    """:data:`HOOK` (its hook sets ROS_DOMAIN_ID, the value written by :func:`_set_hook`)
    and :data:`HOOKED`, whose one test prints the ID it got; colcon applies a dependency's
    hooks to a package's test task."""
    hook = root / HOOK
    (hook / "hooks").mkdir(parents=True)
    _write_hook(hook / "hooks", 0)
    (hook / "package.xml").write_text(
        _MANIFEST.format(name=HOOK, description="Sets ROS_DOMAIN_ID by a hook.", depends="")
    )
    (hook / "CMakeLists.txt").write_text(
        _LISTS.format(name=HOOK, body="ament_environment_hooks(hooks/domain.sh hooks/domain.dsv)")
    )
    hooked = root / HOOKED
    hooked.mkdir(parents=True)
    (hooked / "package.xml").write_text(
        _MANIFEST.format(
            name=HOOKED, description="One test.", depends=f"  <depend>{HOOK}</depend>\n"
        )
    )
    body = (
        "if(BUILD_TESTING)\n"
        '  ament_add_test(hooked_id COMMAND sh -c "echo id=$ROS_DOMAIN_ID"\n'
        "    GENERATE_RESULT_FOR_RETURN_CODE_ZERO)\n"
        "endif()"
    )
    (hooked / "CMakeLists.txt").write_text(_LISTS.format(name=HOOKED, body=body))


def _read_records(folder: Path) -> dict[str, Record]:
    records: dict[str, Record] = crosstalk_workspace().read_records(folder)
    return records


def _first_line(log: str, token: str) -> str:
    """The runner's first line for ``token``'s test, from ctest's verbose log (``N: line``)."""
    number = re.search(rf"^(\d+): token={token} ", log, re.M)
    assert number is not None, log[-3000:]
    line = re.search(rf"^{number[1]}: (Running with .*)$", log, re.M)
    assert line is not None, log[-3000:]
    return line[1]


@pytest.fixture(scope="module")
def pool_env(module_env: dict[str, str]) -> dict[str, str]:
    return {**module_env, "ROS_ISOLATED_TEST_DOMAINS": ",".join(map(str, free_ids(12)))}


@pytest.fixture(scope="module")
def workspace(tmp_path_factory: pytest.TempPathFactory, pool_env: dict[str, str]) -> Workspace:
    """Built once with the recipe, colcon's coordinator active (as it is for a user)."""
    ws = Workspace(tmp_path_factory.mktemp("coordinated"), pool_env)
    output = ws.shell(RECIPE, ws.root / "records-build")
    assert (ws.root / "install" / SECOND[0]).is_dir(), output
    return ws


def _tree(root: int) -> set[int]:
    """``root`` and every process below it, now."""
    parents: dict[int, int] = {}
    for pid in proc.pids():
        stat = proc.read_stat(pid)
        if stat is not None:
            parents[stat.pid] = stat.ppid
    tree = {root}
    for member in parents:
        chain = [member]
        while chain[-1] in parents and chain[-1] not in tree and len(chain) < 64:
            chain.append(parents[chain[-1]])
        if chain[-1] in tree:
            tree.update(chain)
    return tree


def _watch(
    ws: Workspace, pool_env: Mapping[str, str], process: subprocess.Popen[str]
) -> tuple[list[DomainUse], str]:
    """What ``status`` sees of every valid ID while ``process`` runs, until it sees a replacement.

    Read in this process (the CLI's own reading) every half second; once our runner's row
    says it replaced colcon's ID, the CLI prints its table once, as a person would see it.
    """
    lock_dir = Path(pool_env["ROS_ISOLATED_TEST_LOCK_DIR"])
    everything = parse_pool("1-232")
    while process.poll() is None:
        ours = _tree(process.pid)
        uses = [
            use
            for use in domain_uses(lock_dir, everything)
            # Another colcon on the machine (another session's) is not this run's.
            if use.via != "colcon" or (use.holder is not None and use.holder.pid in ours)
        ]
        if any(use.replaced for use in uses) and any(use.via == "colcon" for use in uses):
            table = run_cli(["status"], {**pool_env, "ROS_ISOLATED_TEST_DOMAINS": "1-232"})
            return uses, table.stdout
        time.sleep(0.5)
    return [], ""


@pytest.fixture(scope="module")
def coordinated(workspace: Workspace, pool_env: dict[str, str]) -> Run:
    """The recipe's build tested once, packages and tests in parallel, status watched."""
    records = workspace.root / "records"
    process = workspace.start(IN_PARALLEL, records)
    seen, table = _watch(workspace, pool_env, process)
    output, _ = process.communicate()
    return Run(_read_records(records), workspace.allocated("log"), output, seen, table)


@capabilities.SOCK_DIAG_BOUND
def test_every_test_runs_on_an_id_of_its_own_none_of_colcons(coordinated: Run) -> None:
    records, allocated = coordinated.records, coordinated.allocated
    assert set(allocated) >= set(PACKAGE_OF.values()), coordinated.output[-3000:]
    assert sorted(records) == sorted(PACKAGE_OF), f"records: {sorted(records)}"
    failed = {r.token: r.foreign for r in records.values() if not r.passed}
    assert not failed, f"failed under colcon's coordinator: {failed}"
    ids = [int(r.domain_id or -1) for r in records.values()]
    assert len(set(ids)) == len(ids), f"domain IDs: {ids}"
    assert not set(ids) & set(allocated.values()), (ids, allocated)


@capabilities.SOCK_DIAG_BOUND
def test_tests_of_both_packages_ran_at_once(coordinated: Run) -> None:
    records = coordinated.records
    together = [
        (a, b)
        for a in CMAKE_TOKENS
        for b in CMAKE_TOKENS
        if PACKAGE_OF[a] < PACKAGE_OF[b]
        and records[a].start < records[b].end
        and records[b].start < records[a].end
    ]
    assert together, {t: (r.start, r.end) for t, r in records.items()}


@capabilities.SOCK_DIAG_BOUND
def test_each_result_says_which_of_colcons_ids_it_replaced(
    coordinated: Run, workspace: Workspace
) -> None:
    """The first line and the result file of each ctest test, the pytest plugin's for the
    ament_python package: colcon's ID for that package, and why it was replaced."""
    logged = {
        package: (workspace.root / "log" / "latest_test" / package / "stdout.log").read_text()
        for package in {PACKAGE_OF[token] for token in CMAKE_TOKENS}
    }
    for token in CMAKE_TOKENS:
        package = PACKAGE_OF[token]
        path = workspace.root / "build" / package / "test_results" / package / f"talker_{token}.xml"
        result = load_result(path)
        colcon_id = coordinated.allocated[package]
        replaced = result.properties["ros_domain_id_replaced"]
        assert replaced.startswith(f"{colcon_id}: "), replaced
        assert "colcon's domain-ID coordinator" in replaced, replaced
        assert result.properties["ros_domain_id"] == coordinated.records[token].domain_id
        first = REPLACING.search(_first_line(logged[package], token))
        assert first is not None and first.groups() == (
            coordinated.records[token].domain_id,
            str(colcon_id),
        ), logged[package][:3000]
    pytest_xml = (workspace.root / "build" / "zero_edit_py" / "pytest.xml").read_text()
    assert f'name="ros_domain_id_replaced" value="{coordinated.allocated["zero_edit_py"]}: ' in (
        pytest_xml
    ), pytest_xml[:3000]


@capabilities.SOCK_DIAG_BOUND
def test_status_names_colcons_ids_and_what_replaced_them(coordinated: Run) -> None:
    colcon_rows = {use.domain_id for use in coordinated.seen if use.via == "colcon"}
    assert colcon_rows and colcon_rows <= set(coordinated.allocated.values()), coordinated.seen
    replaced = [use for use in coordinated.seen if use.via == "lock" and use.replaced]
    assert replaced and all(int(use.replaced.split()[0]) in colcon_rows for use in replaced), (
        replaced
    )
    # Nothing of colcon's tree is a squatter on an ID colcon holds: its tasks carry it.
    squatting = [
        (use.domain_id, use.holder.command if use.holder else "")
        for use in coordinated.seen
        if use.via == "environment" and use.domain_id in colcon_rows
    ]
    assert not squatting
    assert re.search(r"^\s*\d+\s+colcon\s+\d+ ", coordinated.table, re.M), coordinated.table
    assert "[replaced colcon's ROS_DOMAIN_ID " in coordinated.table, coordinated.table


@capabilities.SOCK_DIAG_BOUND
def test_a_hand_set_id_is_still_refused(workspace: Workspace) -> None:
    """``ROS_DOMAIN_ID=<id> colcon test``: colcon's coordinator gives the task another ID,
    but the user's is the one that counts, refused with the message it always had."""
    output = workspace.shell(
        "colcon test --packages-select zero_edit_talkers --ctest-args -R talker_ivy",
        workspace.root / "records-hand-set",
        {"ROS_DOMAIN_ID": "5"},
    )
    path = workspace.root / "build" / "zero_edit_talkers" / "test_results" / "zero_edit_talkers"
    result = load_result(path / "talker_ivy.xml")
    assert result.only.outcome == "failure", output
    message = result.only.message
    assert message.startswith(
        "refusing to run: ROS_DOMAIN_ID is already set to '5' where colcon's domain-ID "
        "coordinator runs (it gave this task "
    ), message
    assert result.properties["exit"] == "not run"


@pytest.fixture(scope="module")
def plain(workspace: Workspace, pool_env: dict[str, str]) -> Run:
    """The control: the same packages built without the recipe, tested the same way."""
    bases = "--build-base build-plain --install-base install-plain"
    workspace.shell(f"colcon --log-base log-plain build {bases}", workspace.root / "records-x")
    records = workspace.root / "records-plain"
    output = workspace.shell(
        f"colcon --log-base log-plain --log-level debug test {bases} --parallel-workers 3 "
        "--ctest-args -j3 --pytest-args -p no:ros_isolated_test",
        records,
    )
    return Run(_read_records(records), workspace.allocated("log-plain"), output, [], "")


def test_without_the_recipe_tests_of_a_package_share_colcons_id_and_hear_each_other(
    plain: Run,
) -> None:
    records, allocated = plain.records, plain.allocated
    assert sorted(records) == sorted(PACKAGE_OF), plain.output[-3000:]
    for token, record in records.items():
        assert record.domain_id == str(allocated[PACKAGE_OF[token]]), (token, record, allocated)
    heard = {t: records[t].foreign for t in CMAKE_TOKENS if records[t].foreign}
    assert len(heard) >= 4, f"only {len(heard)} of 6 heard crosstalk: control too weak"
    same_package = {
        t: [other for other in foreign if PACKAGE_OF.get(other) == PACKAGE_OF[t]]
        for t, foreign in heard.items()
    }
    assert all(same_package.values()), heard


# --- an ID a package's environment hook sets: colcon's doing, no coordinator's -------------


def _write_hook(folder: Path, domain_id: int) -> None:
    """The hook, as ament has it: a shell script (what colcon's ``sh`` sources for a
    task) and its ``.dsv`` twin (what colcon's Python-side setup reads)."""
    (folder / "domain.sh").write_text(f"export ROS_DOMAIN_ID={domain_id}\n")
    (folder / "domain.dsv").write_text(f"set;ROS_DOMAIN_ID;{domain_id}\n")


def _set_hook(workspace: Workspace, domain_id: int) -> None:
    """The installed hook's value (read by colcon at each ``colcon test``)."""
    _write_hook(workspace.root / "install" / HOOK / "share" / HOOK / "environment", domain_id)


def _test_hooked(
    workspace: Workspace, domain_id: int, holder: str, coordinator: bool
) -> tuple[str, dict[str, int]]:
    """``colcon test`` of :data:`HOOKED` alone, its hook's port held as ``holder`` says
    (``none``; ``bound``, as our runner holds its ID; ``listening``): its output, and what
    a coordinator allocated (its debug log; a log base of the run's own, as colcon names
    a run's log folder by the second)."""
    log_base = f"log-hooked-{holder}-{coordinator}"
    _set_hook(workspace, domain_id)
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        if holder != "none":
            sock.bind(("", 32768 + domain_id))
        if holder == "listening":
            sock.listen()
        output = workspace.shell(
            f"colcon --log-base {log_base} --log-level debug test --packages-select {HOOKED}",
            workspace.root / "records-hooked",
            {} if coordinator else NO_COORDINATOR,
        )
    finally:
        sock.close()
    return output, workspace.allocated(log_base)


def _refused(workspace: Workspace, domain_id: int, output: str) -> None:
    """The hooked test's result: the hook's ID refused as any preset ID, nothing run."""
    path = workspace.root / "build" / HOOKED / "test_results" / HOOKED / "hooked_id.xml"
    result = load_result(path)
    assert result.only.outcome == "failure", output[-3000:]
    assert result.only.message.startswith(
        f"refusing to run: ROS_DOMAIN_ID is already set to '{domain_id}', so the test would "
        "share that domain"
    ), result.only.message
    assert result.properties["exit"] == "not run"
    assert "ros_domain_id_replaced" not in result.properties


@pytest.mark.parametrize(
    "holder", ["none", pytest.param("bound", marks=capabilities.SOCK_DIAG_BOUND.mark), "listening"]
)
def test_a_hooks_id_is_refused_without_the_coordinator_whoever_holds_its_port(
    workspace: Workspace, holder: str
) -> None:
    """No coordinator (none allocated anything), colcon set the hook's ID: refused, though
    another process holds its port (once taken for colcon's coordinator's, then replaced)."""
    (domain_id,) = free_ids(1)
    output, allocated = _test_hooked(workspace, domain_id, holder, coordinator=False)
    assert allocated == {}, allocated
    _refused(workspace, domain_id, output)


@capabilities.SOCK_DIAG_BOUND
def test_a_hooks_id_is_refused_with_the_coordinator_which_holds_only_its_own(
    workspace: Workspace,
) -> None:
    """The coordinator allocated another ID for the task (its own, which the other tests
    see replaced); the hook's value won, and its port is held by another process: refused."""
    (domain_id,) = free_ids(1)
    output, allocated = _test_hooked(workspace, domain_id, "bound", coordinator=True)
    assert HOOKED in allocated and allocated[HOOKED] != domain_id, (allocated, output[-3000:])
    _refused(workspace, domain_id, output)

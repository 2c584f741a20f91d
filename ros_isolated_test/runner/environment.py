"""Environment policy: what the test's environment is, and whether isolation may go ahead.

A preset ROS_DOMAIN_ID is refused rather than respected: upstream silently runs the test
on it, so a developer's exported ID turns a parallel run into crosstalk nobody notices.
A preset Gazebo partition (GZ_PARTITION, IGN_PARTITION) is refused for the same reason:
the runner gives each test one of its own (see ``partition``).

Namespace isolation (``--isolation namespace``) is decided here too: what contradicts it
(a discovery range or static peers that need the outside network, files of the test in
the host's /dev/shm, which its private one hides: ``private_shm``) and, for ``auto``,
whether this host allows it, probed once before anything is reserved.
"""

from __future__ import annotations

import errno
import os
from collections.abc import Mapping, Sequence

from ros_isolated_test import names, not_run
from ros_isolated_test.domain_coordinator.resources import RESOURCES_ENV
from ros_isolated_test.runner import discovery, partition, rmw_fixture
from ros_isolated_test.runner.request import EnvAssignment
from ros_isolated_test.runner.settings import (
    DISABLE_VAR,
    ISOLATION_ENV,
    RERUNS_ENV,
    Settings,
    SettingsError,
    disables_isolation,
    isolation_from,
)

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from pathlib import Path

    from ros_isolated_test.domain_coordinator.upstream import Setter
    from ros_isolated_test.process.namespace_diagnosis import Problem

DOMAIN_VAR = "ROS_DOMAIN_ID"
#: Beside ROS_DOMAIN_ID where a runner holds it: a pytest under it sees it held, not preset.
HELD_VAR = names.HELD_DOMAIN_ID


def held_for_us(environ: Mapping[str, str]) -> bool:
    """Whether ROS_DOMAIN_ID is one a runner of ours reserved for whatever runs here.

    A plain ROS_DOMAIN_ID is not: the mark must name that very ID.
    """
    held = environ.get(HELD_VAR)
    return held is not None and held == environ.get(DOMAIN_VAR)


class RefusedError(not_run.NotRun):
    """Isolation cannot be promised; nothing may run. The message is one line."""

    outcome = not_run.FAILURE  # refused on purpose: the user fixes it

    def __init__(self, message: str, variable: str = DOMAIN_VAR) -> None:
        super().__init__(message)
        #: The preset variable that was refused (the pytest plugin names it).
        self.variable = variable


class Policy:
    """What the runner decided before anything runs."""

    __slots__ = (
        "asked",
        "discovery",
        "env",
        "fallback",
        "fixture",
        "gz_partition",
        "isolate",
        "mode",
        "namespaces",
        "notes",
        "replaced",
    )

    def __init__(
        self,
        isolate: bool,
        env: dict[str, str],
        notes: tuple[str, ...],
        discovery: discovery.Discovery | None = None,
        gz_partition: bool = False,
        namespaces: bool = False,
        mode: str = "domain",
        fallback: str | None = None,
        asked: str = "",
        replaced: Setter | None = None,
        fixture: rmw_fixture.Fixture | None = None,
    ) -> None:
        #: Reserve a domain ID (False only with DISABLE_ROS_ISOLATION).
        self.isolate = isolate
        #: The test's environment, without ROS_DOMAIN_ID when ``isolate`` is set.
        self.env = env
        #: Lines to print before the test starts (variables set, loud warnings).
        self.notes = notes
        #: How far discovery reaches; None when isolation is disabled (nothing is changed).
        self.discovery = discovery
        #: Give the test a Gazebo partition of its own (not opted out, isolation on).
        self.gz_partition = gz_partition
        #: Run the test in namespaces of its own (``process.namespace``): never wait for an ID.
        self.namespaces = namespaces
        #: The isolation mode asked for (settings, or ``--env``, which has the last word).
        self.mode = mode
        #: Why ``auto`` runs on the domain ID alone (namespaces not allowed, or contradicted).
        self.fallback = fallback
        #: How the mode was asked for (``--isolation namespace``, the variable), for messages.
        self.asked = asked
        #: The tool (colcon's domain-ID coordinator, upstream's runner or Kilted's fixture)
        #: whose ROS_DOMAIN_ID the test's own ID replaces; None when none was set.
        self.replaced = replaced
        #: What is done about Kilted's rmw_test_fixture in the test (None: isolation off).
        self.fixture = fixture

    def refusal(self, error: OSError) -> RefusedError:
        """The refusal for namespaces the test could not enter when it was started.

        ``--isolation namespace`` probes nothing beforehand (a probe costs as much as
        the set-up itself): the test's own start is the probe, before anything of it ran.
        """
        from ros_isolated_test.process.namespace import NamespaceError
        from ros_isolated_test.process.namespace_diagnosis import explain

        problem = explain(
            error
            if isinstance(error, NamespaceError)
            else NamespaceError("unshare", error.errno or errno.EPERM)
        )
        return _refused_namespaces(self.asked, problem)

    def partition_for(self, domain_id: int) -> str | None:
        """The test's Gazebo partition on ``domain_id``, held by this process (None: none set)."""
        return partition.for_this_runner(domain_id) if self.gz_partition else None

    def wrapped(self, command: Sequence[str]) -> tuple[str, ...]:
        """The command the test is started with: under the RMW's own fixture where it needs one."""
        return tuple(command) if self.fixture is None else self.fixture.wrapped(command)

    def for_domain(self, domain_id: int) -> dict[str, str]:
        """The test's environment once ``domain_id`` is held."""
        env = self.discovery.apply(self.env) if self.discovery is not None else self.env
        env = {**env, DOMAIN_VAR: str(domain_id), HELD_VAR: str(domain_id)}
        if self.fixture is not None:
            env.update(self.fixture.variables())
        name = self.partition_for(domain_id)
        if name is not None:
            env.update(partition.variables(name))
        return env


def apply_assignments(
    base: Mapping[str, str], assignments: Sequence[EnvAssignment]
) -> tuple[dict[str, str], list[str]]:
    """run_test.py's ``--env`` then ``--append-env``, and the lines that report them.

    Appending to an unset or empty variable gives the plain value: upstream's leading
    separator would put the current directory on PATH or LD_LIBRARY_PATH.
    """
    env = dict(base)
    notes: list[str] = []
    sets = [item for item in assignments if not item.append]
    appends = [item for item in assignments if item.append]
    for item in sets:
        env[item.name] = item.value
    if sets:
        notes.append("extra environment variables:")
        notes.extend(f" - {name}={env[name]}" for name in sorted({i.name for i in sets}))
    if appends:
        notes.append("extra environment variables to append:")
    for item in appends:
        current = env.get(item.name, "")
        if current and not current.endswith(os.pathsep):
            current += os.pathsep
        env[item.name] = current + item.value
        notes.append(f" - {item.name}+={item.value}")
    return env, notes


def decide(
    assignments: Sequence[EnvAssignment],
    settings: Settings,
    environ: Mapping[str, str] | None = None,
    env_origin: str = "--env",
    in_process: bool = False,
    xdist: bool = False,
    command: Sequence[str] = (),
    result_file: Path | None = None,
) -> Policy:
    """Build the test's environment, or raise :class:`RefusedError` for a preset domain.

    DISABLE_ROS_ISOLATION counts wherever the test's environment gets it: the runner's
    own environment (``settings``) or an ``--env`` assignment (ament_add_test's ENV),
    which, like any assignment, has the last word; so does ROS_ISOLATED_TEST_ISOLATION.
    ``in_process``: the work runs in this process (the pytest plugin), which enters
    the namespaces itself; ``xdist``: in pytest-xdist's workers, which cannot.
    ``command`` and ``result_file`` (when the command names it) are what namespaces
    must not hide from the test (``private_shm``), with its working directory. Raises
    :class:`~ros_isolated_test.runner.discovery.DiscoveryError` for a range the test's
    environment cannot carry (OFF on Humble), :class:`RefusedError` for namespace
    isolation that cannot be had.
    """
    environ = os.environ if environ is None else environ
    gz_partition = _partition_wanted(assignments, settings, env_origin)
    mode, asked = _isolation_wanted(assignments, settings, env_origin)
    env, notes = apply_assignments(environ, assignments)
    # Reruns are this runner's to make: a runner inside the test would add N x N attempts.
    env.pop(RERUNS_ENV, None)
    env.pop(names.RERUNS_FLAKY, None)
    # The test holds what its runner asked for: a runner inside it asking again would wait
    # for what its own parent holds.
    env.pop(RESOURCES_ENV, None)
    # The split is this runner's to decide, for the whole test: a runner or the pytest
    # plugin inside it would split the test's own tests again, over the same shares.
    env.pop(names.SHARD, None)
    env.pop(names.DURATIONS, None)
    assigned = any(item.name == DISABLE_VAR and not item.append for item in assignments)
    if assigned:
        disabled, origin = disables_isolation(env.get(DISABLE_VAR)), f" (by {env_origin})"
    else:
        disabled, origin = settings.isolation_disabled, ""
    preset = [item for item in assignments if item.name == DOMAIN_VAR]
    if not disabled:
        if preset:
            # Appends are applied last: the last of them, else the last set, is what counts.
            item = ([given for given in preset if given.append] or preset)[-1]
            origin = _origin(item, env_origin)
            raise RefusedError(
                f"refusing to run: {DOMAIN_VAR}={item.value!r} is passed with {origin}, so the "
                f"test would share that domain with whatever else runs in it; remove it from "
                f"{origin} (the runner picks a free ID), or add {DISABLE_VAR}=1 to "
                f"{env_origin} (or the runner's environment) to run without isolation"
            )
        replaced = _tool_domain(environ[DOMAIN_VAR]) if DOMAIN_VAR in environ else None
        if replaced is not None and replaced.own_value is not None:
            # A user's export that the tool put aside: still the user's, refused as ever.
            where = (
                f" where {replaced.short} runs (it gave this task {replaced.value} in its place)"
            )
            raise RefusedError(_preset_refusal(replaced.own_value, where))
        env.pop(DOMAIN_VAR, None)
        if gz_partition:
            _refuse_preset_partition(assignments, environ, env_origin)
        confined = discovery.decide(env, settings.discovery_range)
        cut_off = _contradiction(mode, confined, env, command, result_file)
        namespaces, fallback = _namespaces(mode, asked, cut_off, in_process, xdist)
        return Policy(
            isolate=True,
            env=env,
            notes=tuple(notes),
            discovery=confined,
            gz_partition=gz_partition,
            namespaces=namespaces,
            mode=mode,
            fallback=fallback,
            asked=asked,
            replaced=replaced,
            fixture=rmw_fixture.decide(env),
        )
    domain = env.get(DOMAIN_VAR)
    where = f"{DOMAIN_VAR}={domain}" if domain is not None else f"{DOMAIN_VAR} unset (domain 0)"
    warnings = [
        f"WARNING: {DISABLE_VAR} is set{origin}: running WITHOUT isolation on {where}; "
        "this test hears and disturbs every other ROS process on that domain"
    ]
    if settings.discovery_range is not None:
        warnings.append(
            f"WARNING: the discovery range {settings.discovery_range} is not applied: "
            f"{DISABLE_VAR} leaves the test's environment as it is"
        )
    if mode != "domain":
        warnings.append(
            f"WARNING: {asked} is not applied: {DISABLE_VAR} runs the test as it is, "
            "without namespaces"
        )
    return Policy(isolate=False, env=env, notes=(*notes, *warnings), mode=mode, asked=asked)


def _origin(item: EnvAssignment, env_origin: str) -> str:
    """The option that passed ``item``, named in messages so the user edits that one.

    ``--append-env`` (ament_add_test's APPEND_ENV) for an appended one.
    """
    if not item.append:
        return env_origin
    return env_origin.replace("--env", "--append-env").replace(" ENV)", " APPEND_ENV)")


def _preset_refusal(value: str, where: str = "") -> str:
    """The refusal of a ROS_DOMAIN_ID someone set: the same words wherever it was set."""
    meaning = " (empty: ROS reads it as domain 0)" if not value.strip() else ""
    return (
        f"refusing to run: {DOMAIN_VAR} is already set to {value!r}{meaning}{where}, so the "
        f"test would share that domain with whatever else runs in it; unset it "
        f"(unset {DOMAIN_VAR}) and the runner picks a free ID, or set "
        f"{DISABLE_VAR}=1 to run without isolation"
    )


def _tool_domain(value: str, bound_shown: bool | None = None) -> Setter:
    """The tool (``domain_coordinator.upstream``) that set ``value`` here and holds it.

    Else refused, saying why where this kernel hides colcon's (``bound_shown``: its probe).
    """
    from ros_isolated_test.domain_coordinator import upstream

    if (setter := upstream.setter_of(os.getpid(), value, bound_shown)) is not None:
        return setter
    if (unseen := upstream.unseen_colcon(os.getpid(), value, bound_shown)) is None:
        raise RefusedError(_preset_refusal(value))
    fix = f"or set {DISABLE_VAR}=1 to run without isolation"
    raise RefusedError(f"refusing to run: {upstream.unseen_cause(unseen)}, {fix}")


def _isolation_wanted(
    assignments: Sequence[EnvAssignment], settings: Settings, env_origin: str
) -> tuple[str, str]:
    """The isolation mode, and how it was asked (for messages): ``--env`` has the last word.

    Read like the Gazebo switch: a CMake project sets it per test with
    ``ENV ROS_ISOLATED_TEST_ISOLATION=namespace``; a bad value is refused (exit 2).
    """
    given = [item for item in assignments if item.name == ISOLATION_ENV and not item.append]
    if given:
        origin = f"{ISOLATION_ENV} (by {env_origin})"
        try:
            mode = isolation_from(given[-1].value, origin)
        except SettingsError as error:
            raise RefusedError(str(error), ISOLATION_ENV) from None
        return mode, f"{ISOLATION_ENV}={mode} (by {env_origin})"
    mode, origin = settings.isolation, settings.isolation_origin
    return mode, f"--isolation {mode}" if origin == "--isolation" else f"{origin}={mode}"


#: Names a test in its own network namespace can still reach: its loopback.
_LOCAL_NAMES = frozenset({"localhost", "localhost.localdomain", "ip6-localhost", "ip6-loopback"})


def _remote_peer(peers: str) -> str | None:
    """The first of ROS_STATIC_PEERS (``;``-separated) that is not this loopback, if any."""
    for peer in (item.strip() for item in peers.split(";")):
        if not peer or peer.lower() in _LOCAL_NAMES:
            continue
        import ipaddress

        try:
            if ipaddress.ip_address(peer.strip("[]")).is_loopback:
                continue
        except ValueError:
            pass  # a host name: another host, as far as a loopback-only network goes
        return peer
    return None


_NETWORK = "gives the test a network of its own, loopback only"


def _contradiction(
    mode: str,
    confined: discovery.Discovery,
    env: Mapping[str, str],
    command: Sequence[str],
    result_file: Path | None,
) -> tuple[str, str, str] | None:
    """What namespaces would cut the test off from: (what they give, the cause, the fix).

    Its discovery needing the outside network, or its files in the host's /dev/shm
    (``private_shm``); None: nothing (and always in domain mode).
    """
    if mode == "domain":
        return None
    if confined.range == "SUBNET":
        return (
            _NETWORK,
            f"its discovery range is SUBNET ({confined.source}), which needs the outside network",
            "use LOCALHOST (--discovery-range LOCALHOST)",
        )
    peer = _remote_peer(confined.peers)
    if peer is not None:
        return (
            _NETWORK,
            f"{discovery.PEERS_VAR}={confined.peers} names another host ({peer}), which it "
            "cannot reach",
            f"name only localhost there, or unset {discovery.PEERS_VAR}",
        )
    from ros_isolated_test.runner import private_shm

    hidden = private_shm.hidden(command, env, result_file)
    if hidden:
        return private_shm.GIVES, private_shm.cause(hidden), private_shm.FIX
    return None


def _namespaces(
    mode: str,
    asked: str,
    contradiction: tuple[str, str, str] | None,
    in_process: bool,
    xdist: bool,
) -> tuple[bool, str | None]:
    """(whether the test gets namespaces, why ``auto`` falls back) for ``mode``.

    ``namespace`` refuses what cannot work: a contradiction, or a host that forbids user
    namespaces. ``auto`` falls back to the domain ID instead, so it must know before the
    reservation (it waits for an ID only without namespaces): it probes, once
    (``namespace_diagnosis.problem``). So does work in this very process (the pytest plugin).
    ``namespace`` for a test the runner starts does not: the test's start is the probe
    (:meth:`Policy.refusal`), which saves a second set-up on every test.
    """
    if mode == "domain":
        return False, None
    if contradiction is not None:
        gives, cause, fix = contradiction
        if mode == "namespace":
            raise RefusedError(
                f"refusing to run: {asked} {gives}, but {cause}; {fix}, or use isolation "
                f"domain ({ISOLATION_ENV}, run --isolation)",
                ISOLATION_ENV,
            )
        return False, f"as namespaces would cut it off: {cause}"
    if mode == "namespace" and not (in_process or xdist):
        return True, None
    from ros_isolated_test.process import namespace_diagnosis
    from ros_isolated_test.process.namespace import NamespaceError

    problem = (
        namespace_diagnosis.explain(NamespaceError("xdist", errno.EINVAL))
        if xdist
        else namespace_diagnosis.problem(in_process)
    )
    if problem is None:
        return True, None
    if mode == "namespace":
        raise _refused_namespaces(asked, problem)
    return False, f"as namespaces are not allowed here: {problem.cause}"


def _refused_namespaces(asked: str, problem: Problem) -> RefusedError:
    """``--isolation namespace`` where namespaces cannot be had: the cause and the fix."""
    return RefusedError(
        f"refusing to run: {asked} needs Linux user namespaces, which cannot be had here: "
        f"{problem.cause}; {problem.fix}, or use isolation auto (falls back to the domain "
        f"ID) or domain ({ISOLATION_ENV}, run --isolation)",
        ISOLATION_ENV,
    )


def _partition_wanted(
    assignments: Sequence[EnvAssignment], settings: Settings, env_origin: str
) -> bool:
    """The partition switch: an ``--env`` assignment (ament_add_test's ENV) has the last word.

    A CMake project sets it per test there; the runner's own environment is read once, in
    ``settings``. A value that is neither on nor off is refused like a preset (exit 2).
    """
    given = [item for item in assignments if item.name == partition.OPT_OUT_ENV]
    if not given:
        return settings.gz_partition
    try:
        return partition.enabled(given[-1].value, f"{partition.OPT_OUT_ENV} (by {env_origin})")
    except partition.PartitionSettingError as error:
        raise RefusedError(str(error), partition.OPT_OUT_ENV) from None


def _refuse_preset_partition(
    assignments: Sequence[EnvAssignment], environ: Mapping[str, str], env_origin: str
) -> None:
    """A Gazebo partition set by anyone but the runner, refused as a preset domain ID is.

    Kept, the test's simulation would share it with every other test run on it, and
    Gazebo's transport ignores ROS_DOMAIN_ID: the crosstalk the runner exists to prevent.
    """
    fix = (
        f"the runner sets one per test; or set {partition.OPT_OUT_ENV}=off to manage "
        f"Gazebo partitions yourself, or {DISABLE_VAR}=1 to run without isolation"
    )
    for variable in partition.VARIABLES:
        given = [item for item in assignments if item.name == variable]
        if given:
            item = ([each for each in given if each.append] or given)[-1]
            origin = _origin(item, env_origin)
            raise RefusedError(
                f"refusing to run: {variable}={item.value!r} is passed with {origin}, "
                f"so the test's simulation would share that Gazebo transport partition with "
                f"whatever else runs in it; remove it from {origin} ({fix})",
                variable,
            )
    for variable in partition.VARIABLES:
        if variable in environ:
            raise RefusedError(
                f"refusing to run: {variable} is already set to {environ[variable]!r}, so the "
                f"test's simulation would share that Gazebo transport partition with whatever "
                f"else runs in it; unset it (unset {variable}): {fix}",
                variable,
            )

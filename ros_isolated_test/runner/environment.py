"""Environment policy: what the test's environment is, and whether isolation may go ahead.

A preset ROS_DOMAIN_ID is refused rather than respected: upstream silently runs the test
on it, so a developer's exported ID turns a parallel run into crosstalk nobody notices.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence

from ros_isolated_test.runner import discovery
from ros_isolated_test.runner.request import EnvAssignment
from ros_isolated_test.runner.settings import (
    DISABLE_VAR,
    RERUNS_ENV,
    Settings,
    disables_isolation,
)

DOMAIN_VAR = "ROS_DOMAIN_ID"
#: Set beside ROS_DOMAIN_ID to the same ID wherever a runner (or the pytest plugin) holds
#: it: a pytest started under a runner sees the ID is held for it, not preset by someone.
HELD_VAR = "ROS_ISOLATED_TEST_HELD_DOMAIN_ID"


def held_for_us(environ: Mapping[str, str]) -> bool:
    """Whether ROS_DOMAIN_ID is one a runner of ours reserved for whatever runs here.

    A plain ROS_DOMAIN_ID is not: the mark must name that very ID.
    """
    held = environ.get(HELD_VAR)
    return held is not None and held == environ.get(DOMAIN_VAR)


class RefusedError(Exception):
    """Isolation cannot be promised; nothing may run. The message is one line."""


class Policy:
    """What the runner decided before anything runs."""

    __slots__ = ("discovery", "env", "isolate", "notes")

    def __init__(
        self,
        isolate: bool,
        env: dict[str, str],
        notes: tuple[str, ...],
        discovery: discovery.Discovery | None = None,
    ) -> None:
        #: Reserve a domain ID (False only with DISABLE_ROS_ISOLATION).
        self.isolate = isolate
        #: The test's environment, without ROS_DOMAIN_ID when ``isolate`` is set.
        self.env = env
        #: Lines to print before the test starts (variables set, loud warnings).
        self.notes = notes
        #: How far discovery reaches; None when isolation is disabled (nothing is changed).
        self.discovery = discovery

    def for_domain(self, domain_id: int) -> dict[str, str]:
        """The test's environment once ``domain_id`` is held."""
        env = self.discovery.apply(self.env) if self.discovery is not None else self.env
        return {**env, DOMAIN_VAR: str(domain_id), HELD_VAR: str(domain_id)}


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
) -> Policy:
    """Build the test's environment, or raise :class:`RefusedError` for a preset domain.

    DISABLE_ROS_ISOLATION counts wherever the test's environment gets it: the runner's
    own environment (``settings``) or an ``--env`` assignment (ament_add_test's ENV),
    which, like any assignment, has the last word. Raises
    :class:`~ros_isolated_test.runner.discovery.DiscoveryError` for a range the test's
    environment cannot carry (OFF on Humble).
    """
    environ = os.environ if environ is None else environ
    env, notes = apply_assignments(environ, assignments)
    # Reruns are this runner's to make: a runner started inside the test would make its
    # own on top of them, N x N attempts.
    env.pop(RERUNS_ENV, None)
    assigned = any(item.name == DISABLE_VAR and not item.append for item in assignments)
    if assigned:
        disabled, origin = disables_isolation(env.get(DISABLE_VAR)), f" (by {env_origin})"
    else:
        disabled, origin = settings.isolation_disabled, ""
    preset = [item for item in assignments if item.name == DOMAIN_VAR]
    if not disabled:
        if preset:
            value = env[DOMAIN_VAR]
            raise RefusedError(
                f"refusing to run: {DOMAIN_VAR}={value!r} is passed with {env_origin}, so the "
                f"test would share that domain with whatever else runs in it; remove it from "
                f"{env_origin} (the runner picks a free ID), or add {DISABLE_VAR}=1 to "
                f"{env_origin} (or the runner's environment) to run without isolation"
            )
        if DOMAIN_VAR in environ:
            value = environ[DOMAIN_VAR]
            meaning = " (empty: ROS reads it as domain 0)" if not value.strip() else ""
            raise RefusedError(
                f"refusing to run: {DOMAIN_VAR} is already set to {value!r}{meaning}, so the "
                f"test would share that domain with whatever else runs in it; unset it "
                f"(unset {DOMAIN_VAR}) and the runner picks a free ID, or set "
                f"{DISABLE_VAR}=1 to run without isolation"
            )
        confined = discovery.decide(env, settings.discovery_range)
        return Policy(isolate=True, env=env, notes=tuple(notes), discovery=confined)
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
    return Policy(isolate=False, env=env, notes=(*notes, *warnings))

"""How far a test's DDS discovery reaches: this machine only, unless asked otherwise.

A domain ID reserved here says nothing to the next machine on the network: two CI
hosts both running a test on domain 1 hear each other. Confining discovery to
localhost (measured: either side alone is enough) makes the per-machine reservation
a real isolation, while processes of one test on one host still find each other.
"""

from __future__ import annotations

from collections.abc import Mapping

from ros_isolated_test import names, not_run

RANGE_VAR = "ROS_AUTOMATIC_DISCOVERY_RANGE"
LOCALHOST_ONLY_VAR = "ROS_LOCALHOST_ONLY"
PEERS_VAR = "ROS_STATIC_PEERS"
OVERRIDE_ENV = names.DISCOVERY_RANGE
OVERRIDE_ORIGIN = f"--discovery-range / {OVERRIDE_ENV}"
RANGES = ("LOCALHOST", "SUBNET", "OFF", "SYSTEM_DEFAULT")
DEFAULT_RANGE = "LOCALHOST"
#: Distributions from before ROS_AUTOMATIC_DISCOVERY_RANGE (Iron added it).
_LOCALHOST_ONLY_DISTROS = frozenset({"foxy", "galactic", "humble"})


class DiscoveryError(not_run.NotRun, ValueError):
    """A range that cannot be used; the message names it and the choices."""


class Discovery:
    """What the runner decided about discovery, and the variables that carry it."""

    __slots__ = ("peers", "range", "removals", "source", "updates", "warnings")

    def __init__(
        self,
        range: str,
        source: str,
        updates: dict[str, str] | None = None,
        removals: tuple[str, ...] = (),
        peers: str = "",
        warnings: tuple[str, ...] = (),
    ) -> None:
        self.range = range
        #: Who chose it: "runner default", "--discovery-range", "the environment", ...
        self.source = source
        self.updates: dict[str, str] = updates if updates is not None else {}
        self.removals = removals
        self.peers = peers
        self.warnings = warnings

    def apply(self, env: Mapping[str, str]) -> dict[str, str]:
        """The test's environment with the decision in it."""
        result = {key: value for key, value in env.items() if key not in self.removals}
        result.update(self.updates)
        return result

    def describe(self) -> str:
        """One line for the console, right after ``Running with ROS_DOMAIN_ID``."""
        text = f"discovery range {self.range} ({self.source})"
        if self.range == "LOCALHOST":
            text += ": DDS discovery stays on this machine"
        if self.peers:
            text += f"; static peers {self.peers}"
        return text

    def properties(self) -> dict[str, str]:
        """Suite properties, so a reader of a failed CI job sees how the test was isolated."""
        found = {"ros_discovery_range": self.range, "ros_discovery_range_source": self.source}
        if self.peers:
            found["ros_static_peers"] = self.peers
        return found


def check_range(value: str, origin: str) -> str:
    """A valid range name, or :class:`DiscoveryError` naming ``origin`` and the choices."""
    upper = value.strip().upper()
    if upper not in RANGES:
        raise DiscoveryError(
            f"{origin}={value!r} is not a discovery range; use one of {', '.join(RANGES)}"
        )
    return upper


def _users_choice(env: Mapping[str, str], humble: bool) -> tuple[str, str] | None:
    """The range the user's own variables already set, which the runner respects."""
    # ROS compares the exact string: " 1 " is not "1", and confines nothing.
    only = env.get(LOCALHOST_ONLY_VAR)
    if humble:
        # Humble reads only ROS_LOCALHOST_ONLY; a range variable there changes nothing.
        if only is None:
            return None
        return ("LOCALHOST" if only == "1" else "SUBNET"), f"{LOCALHOST_ONLY_VAR} set by the user"
    if only == "1":
        # Deprecated but still honoured, and it overrides the range: report what holds.
        return "LOCALHOST", f"{LOCALHOST_ONLY_VAR}=1 set by the user"
    user = env.get(RANGE_VAR, "")
    if user in RANGES:
        return user, f"{RANGE_VAR} set by the user"
    if user:
        # Measured: an invalid or lower-case value warns and falls back to LOCALHOST.
        return "LOCALHOST", f"ROS reads {RANGE_VAR}={user!r}, set by the user, as LOCALHOST"
    return None


def decide(env: Mapping[str, str], override: str | None) -> Discovery:
    """Choose the range for the test's environment ``env`` (the user's variables in it).

    ``--discovery-range`` wins; else a range the user set is kept; else LOCALHOST. On
    distributions without ROS_AUTOMATIC_DISCOVERY_RANGE, ROS_LOCALHOST_ONLY carries it.
    """
    humble = env.get("ROS_DISTRO", "").strip().lower() in _LOCALHOST_ONLY_DISTROS
    peers = env.get(PEERS_VAR, "").strip()
    warnings: tuple[str, ...] = ()
    if peers:
        warnings = (
            f"WARNING: {PEERS_VAR}={peers} is set: this test's discovery reaches beyond this "
            "machine to those peers, where other tests may use the same domain ID",
        )
    if override is None:
        users = _users_choice(env, humble)
        if users is not None:
            return Discovery(users[0], users[1], peers=peers, warnings=warnings)
        chosen, source = DEFAULT_RANGE, "set by the runner"
    else:
        chosen, source = check_range(override, OVERRIDE_ORIGIN), OVERRIDE_ORIGIN
    removals: tuple[str, ...] = ()
    if not humble:
        # ROS_LOCALHOST_ONLY=1 would override the chosen range: it goes.
        updates, removals = {RANGE_VAR: chosen}, (LOCALHOST_ONLY_VAR,)
    elif chosen == "OFF":
        raise DiscoveryError(
            "discovery range OFF needs ROS 2 Iron or newer (ROS_DISTRO is humble); "
            "use LOCALHOST or SUBNET"
        )
    else:
        updates = {LOCALHOST_ONLY_VAR: "1" if chosen == "LOCALHOST" else "0"}
    return Discovery(chosen, source, updates, removals, peers, warnings)

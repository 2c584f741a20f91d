"""The Gazebo transport partition of a test: its name and the variables that carry it.

Gazebo (gz sim, Ignition before it) talks over its own transport, which ignores
ROS_DOMAIN_ID: with no partition set, every simulation of one user on one host shares
one, so two simulation tests hear each other's /clock and models (and ros_gz_bridge
carries that into each test's own domain). A partition per test closes that gap.

The name is a pure function of what a holder record already holds (host, domain ID,
runner PID): ``status`` shows any runner's partition without asking it. The runner's PID
makes it unique on the machine while the test lives (the ID alone is reused as soon as
it is released); the host keeps it apart from tests on other hosts of the network, which
Gazebo's multicast discovery reaches.
"""

from __future__ import annotations

import os

from ros_isolated_test import names, not_run
from ros_isolated_test.switches import NotOnOff, on_off
from ros_isolated_test.text import bounded

#: Read by gz-transport 12 and later (Garden, Harmonic: Jazzy's, Ionic, Jetty).
GZ_VAR = "GZ_PARTITION"
#: Read by ignition-transport 11 and earlier (Fortress: Humble's, Citadel).
IGN_VAR = "IGN_PARTITION"
VARIABLES = (GZ_VAR, IGN_VAR)
#: The one switch: ``off`` sets no partition variable (and refuses no preset one).
OPT_OUT_ENV = names.GZ_PARTITION_SWITCH
#: The suite property naming the partition.
PROPERTY = names.GZ_PARTITION

#: What every Gazebo release accepts in a partition (``/`` and ``@`` are not safe).
_SAFE = frozenset("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-.")
#: Longest host part kept: the whole name stays short enough to show in a table.
HOST_CHARS = 32


class PartitionSettingError(not_run.NotRun, ValueError):
    """The switch has a value that is neither on nor off: one line naming it and the fix."""


def enabled(value: str | None, origin: str = OPT_OUT_ENV) -> bool:
    """Whether the runner sets a partition, from the switch's value (None: unset: yes).

    Anything but a plain on or off word is refused: a typo must not silently drop the
    isolation nor keep it against the user's wish.
    """
    try:
        return on_off(value, unset=True)
    except NotOnOff:
        raise PartitionSettingError(
            f"{origin}={value!r} is neither on nor off; set {OPT_OUT_ENV}=off to set no "
            "Gazebo partition, or unset it"
        ) from None


def _host_part(host: str) -> str:
    """``host`` in safe characters, bounded; its head and tail kept, where hosts differ."""
    safe = "".join(char if char in _SAFE else "-" for char in host) or "host"
    head = HOST_CHARS // 2
    return bounded(safe, HOST_CHARS, head=head, tail=HOST_CHARS - head - 1, mark="-")


def name(host: str, domain_id: int, pid: int) -> str:
    """The partition of the test a runner ``pid`` on ``host`` runs on ``domain_id``.

    Letters, digits, ``_``, ``-`` and ``.`` only, at most 60 characters.
    """
    return f"rit_{_host_part(host)}_d{int(domain_id)}_{int(pid)}"


def for_this_runner(domain_id: int) -> str:
    """The partition of the test this process runs on ``domain_id`` (as its record says)."""
    return name(os.uname().nodename, domain_id, os.getpid())


def variables(partition: str) -> dict[str, str]:
    """Both variables, so every Gazebo release of either name reads the partition."""
    return {variable: partition for variable in VARIABLES}


def describe(partition: str | None) -> str:
    """The console line beside the domain ID's: the partition, or that none is set."""
    if partition is None:
        return (
            f"Gazebo transport partition not set ({OPT_OUT_ENV}=off): {GZ_VAR} and "
            f"{IGN_VAR} are as the test's environment has them"
        )
    return f"Gazebo transport partition {partition} ({GZ_VAR}, {IGN_VAR})"

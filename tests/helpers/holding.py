"""A run on a pool of one ID, in process, and whether another runner could take that ID now.

For the tests of what holds an ID around the work (``runner.isolation``, ``runner.attempt``):
they build the policy as an entry point does, from variables, never this process's own.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from ros_isolated_test.domain_coordinator.reservation import DomainCoordinator
from ros_isolated_test.runner import environment, settings


def one_id_policy(
    lock_dir: Path, domain_id: int, base: Mapping[str, str] | None = None, **more: str
) -> tuple[environment.Policy, settings.Settings]:
    """The policy and settings of a run on a pool of ``domain_id`` alone, never waiting.

    ``base``: the rest of the environment the test gets (default: none); ``more``: variables.
    """
    environ = {
        **(base or {}),
        "ROS_ISOLATED_TEST_LOCK_DIR": str(lock_dir),
        "ROS_ISOLATED_TEST_DOMAINS": str(domain_id),
        "ROS_ISOLATED_TEST_WAIT_TIMEOUT": "0",
        **more,
    }
    config = settings.read(environ)
    return environment.decide((), config, environ), config


def free_now(coordinator: DomainCoordinator) -> bool:
    """Whether another runner could take the ID now (it gives it back at once)."""
    taken = coordinator.reserve_if_free(["another runner"])
    if taken is None:
        return False
    taken.release()
    return True

"""Machine-wide reservation of ROS_DOMAIN_IDs on file locks.

Named ``ros_isolated_test.domain_coordinator`` on purpose: ROS ships a top-level
``domain_coordinator`` that a sourced setup puts first on PYTHONPATH.
"""

from ros_isolated_test.domain_coordinator.lock_dir import (
    LOCK_DIR_ENV,
    LockDirError,
    ensure_lock_dir,
    lock_dir_from_env,
)
from ros_isolated_test.domain_coordinator.pool import POOL_ENV, PoolSpecError, parse_pool
from ros_isolated_test.domain_coordinator.reservation import (
    DomainCoordinator,
    PoolExhaustedError,
    Reservation,
)
from ros_isolated_test.domain_coordinator.squatters import Squatter
from ros_isolated_test.domain_coordinator.status import HeldDomain, held_domains

__all__ = [
    "LOCK_DIR_ENV",
    "POOL_ENV",
    "DomainCoordinator",
    "HeldDomain",
    "LockDirError",
    "PoolExhaustedError",
    "PoolSpecError",
    "Reservation",
    "Squatter",
    "ensure_lock_dir",
    "held_domains",
    "lock_dir_from_env",
    "parse_pool",
]

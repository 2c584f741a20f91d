"""Machine-wide reservation of ROS_DOMAIN_IDs on file locks.

Named ``ros_isolated_test.domain_coordinator`` on purpose: ROS ships a top-level
``domain_coordinator`` that a sourced setup puts first on PYTHONPATH.

The names below load their module on first use: the runner imports only the modules
a reservation needs (``status`` and its helpers stay unloaded on a test's path).
"""

from __future__ import annotations

import importlib

TYPE_CHECKING = False
if TYPE_CHECKING:
    from ros_isolated_test.domain_coordinator.lock_dir import (
        LOCK_DIR_ENV,
        LockDirError,
        ensure_lock_dir,
        lock_dir_from_env,
    )
    from ros_isolated_test.domain_coordinator.pool import POOL_ENV, PoolSpecError, parse_pool
    from ros_isolated_test.domain_coordinator.reservation import DomainCoordinator, Reservation
    from ros_isolated_test.domain_coordinator.squatters import Squatter
    from ros_isolated_test.domain_coordinator.status import DomainUse, domain_uses
    from ros_isolated_test.domain_coordinator.waiting import PoolExhaustedError

_MODULE_OF = {
    "LOCK_DIR_ENV": "lock_dir",
    "LockDirError": "lock_dir",
    "ensure_lock_dir": "lock_dir",
    "lock_dir_from_env": "lock_dir",
    "POOL_ENV": "pool",
    "PoolSpecError": "pool",
    "parse_pool": "pool",
    "DomainCoordinator": "reservation",
    "PoolExhaustedError": "waiting",
    "Reservation": "reservation",
    "Squatter": "squatters",
    "DomainUse": "status",
    "domain_uses": "status",
}

__all__ = [
    "LOCK_DIR_ENV",
    "POOL_ENV",
    "DomainCoordinator",
    "DomainUse",
    "LockDirError",
    "PoolExhaustedError",
    "PoolSpecError",
    "Reservation",
    "Squatter",
    "domain_uses",
    "ensure_lock_dir",
    "lock_dir_from_env",
    "parse_pool",
]


def __getattr__(name: str) -> object:
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{module}"), name)

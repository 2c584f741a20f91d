"""Exit codes of the runner, one meaning each, so CI logs and scripts can tell them apart."""

from __future__ import annotations

import signal

PASSED = 0
#: The test failed: non-zero exit, failures in its result file, or no result file.
FAILED = 1
#: Nothing was run: bad arguments, or a preset ROS_DOMAIN_ID was refused.
USAGE = 2
#: Nothing was run: no domain ID could be reserved (pool exhausted, lock dir unusable).
NO_DOMAIN = 3
#: The runner's own ``--timeout`` ended the test (the convention of timeout(1)).
TIMEOUT = 124
#: The command exists but could not be executed (shell convention).
NOT_EXECUTABLE = 126
#: The command was not found (shell convention).
NOT_FOUND = 127


def for_signal(signum: int) -> int:
    """Exit code of a process killed by ``signum``, as shells report it."""
    return 128 + signum


def signal_name(signum: int) -> str:
    """``SIGSEGV`` for 11; a number we cannot name stays a number."""
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f"signal {signum}"

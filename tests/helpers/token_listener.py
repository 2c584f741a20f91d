#!/usr/bin/env python3
"""The next test on the same domain: counts tokens it hears that are not its own.

Usage: token_listener.py TOKEN [--watch-pid PID] [--listen SECONDS]

It publishes TOKEN and waits to hear it first, so silence means isolation, not broken
DDS; then listens --listen seconds more. --watch-pid names the earlier test's daemon:
whether it was still alive when this test was handed the ID is reported too. Prints
one line ``RESULT {json}``; exits 0 only if it heard itself, nothing foreign, and the
daemon was gone.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

# Run as a program: its folder is on sys.path, the folder holding `helpers` is not.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from helpers.token_exchange import exchange


def alive(pid: int) -> bool:
    """Running (not a zombie): a zombie no longer talks on any domain."""
    try:
        data = Path(f"/proc/{pid}/stat").read_bytes()
    except OSError:
        return False
    return data[data.rfind(b")") + 2 :].split()[0] != b"Z"


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("token")
    parser.add_argument("--watch-pid", type=int)
    parser.add_argument("--listen", type=float, default=4.0)
    args = parser.parse_args()
    # Before importing rclpy (half a second): as close to the reservation as we can get.
    watched_alive = args.watch_pid is not None and alive(args.watch_pid)

    report = exchange(args.token, "token_listener", lambda heard_for: heard_for < args.listen)
    report["watched_alive_at_start"] = watched_alive
    print("RESULT " + json.dumps(report), flush=True)
    return 0 if report["own"] and not report["foreign"] and not watched_alive else 1


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env python3
"""A test that leaks a daemon: double-forks an rclpy talker, then exits 0 at once.

Usage: daemon_talker.py PID_FILE TOKEN [--detach-stdio] [--linger SECONDS]

The talker (fork, setsid, fork: reparented away from the test, in a session of its
own) publishes TOKEN on token_exchange.TOPIC at 20 Hz until it is signalled, and writes its PID to
PID_FILE once its publisher exists. On SIGTERM, SIGINT or SIGHUP it keeps publishing
for --linger seconds before it exits, as a node with slow cleanup does: a runner that
released the ID before the talker was really gone would let the next test hear it.
It never lives longer than MAX_LIFE_S, so a broken teardown cannot leak it forever.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import time
from pathlib import Path

# Run as a program: its folder is on sys.path, the folder holding `helpers` is not.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from helpers.token_exchange import PERIOD_S, publishing

MAX_LIFE_S = 120.0
START_DEADLINE_S = 30.0


def talk(pid_file: Path, token: str, linger: float) -> None:
    """Runs in the daemon: rclpy is imported (by ``publishing``) only here, after the forks."""
    stop_at = time.monotonic() + MAX_LIFE_S

    def on_signal(signum: int, _frame: object) -> None:
        nonlocal stop_at
        stop_at = min(stop_at, time.monotonic() + linger)

    for signum in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP):
        signal.signal(signum, on_signal)
    with publishing(token, "daemon_talker") as (_node, executor, _qos):
        partial = pid_file.with_name(pid_file.name + ".partial")
        partial.write_text(str(os.getpid()))
        partial.rename(pid_file)
        print(f"daemon talker {os.getpid()} publishing {token!r}", flush=True)
        while time.monotonic() < stop_at:
            executor.spin_once(timeout_sec=PERIOD_S)


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("pid_file", type=Path)
    parser.add_argument("token")
    parser.add_argument("--detach-stdio", action="store_true")
    parser.add_argument("--linger", type=float, default=0.0)
    args = parser.parse_args()
    sys.stdout.flush()
    if os.fork() == 0:
        os.setsid()
        if os.fork() != 0:
            os._exit(0)
        if args.detach_stdio:
            null = os.open(os.devnull, os.O_RDWR)
            for fd in (0, 1, 2):
                os.dup2(null, fd)
        try:
            talk(args.pid_file, args.token, args.linger)
        finally:
            os._exit(0)
    os.wait()  # the intermediate process: the talker is now an orphan
    deadline = time.monotonic() + START_DEADLINE_S
    while not args.pid_file.exists():
        if time.monotonic() > deadline:
            print("the daemon talker did not start", flush=True)
            return 1
        time.sleep(0.02)
    print(f"leaving daemon talker {args.pid_file.read_text()} behind", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

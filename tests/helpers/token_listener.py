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
import os
import sys
import time
from collections import Counter
from pathlib import Path

TOPIC = "/ros_isolated_test/process_tree"
PERIOD_S = 0.05
OWN_DEADLINE_S = 15.0


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

    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from rclpy.signals import SignalHandlerOptions
    from std_msgs.msg import String  # type: ignore[import-untyped]

    own = 0
    foreign: Counter[str] = Counter()

    def on_message(message: String) -> None:
        nonlocal own
        if message.data == args.token:
            own += 1
        else:
            foreign[message.data] += 1

    context = Context()
    rclpy.init(args=[], context=context, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("token_listener", context=context)
    qos = QoSProfile(  # type: ignore[no-untyped-call]
        history=HistoryPolicy.KEEP_LAST,
        depth=50,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.VOLATILE,
    )
    publisher = node.create_publisher(String, TOPIC, qos)
    node.create_subscription(String, TOPIC, on_message, qos)
    node.create_timer(PERIOD_S, lambda: publisher.publish(String(data=args.token)))
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    deadline = time.monotonic() + OWN_DEADLINE_S
    while not own and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=PERIOD_S)
    if own:
        deadline = time.monotonic() + args.listen
        while time.monotonic() < deadline:
            executor.spin_once(timeout_sec=PERIOD_S)
    executor.shutdown()
    node.destroy_node()  # type: ignore[no-untyped-call]
    context.try_shutdown()
    report = {
        "domain_id": os.environ.get("ROS_DOMAIN_ID"),
        "own": own,
        "foreign": dict(foreign),
        "watched_alive_at_start": watched_alive,
    }
    print("RESULT " + json.dumps(report), flush=True)
    return 0 if own and not foreign and not watched_alive else 1


if __name__ == "__main__":
    sys.exit(main())

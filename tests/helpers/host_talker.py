#!/usr/bin/env python3
"""A test on one "host": publishes TOKEN until told to stop, having first heard itself.

Usage: host_talker.py TOKEN READY_FILE STOP_FILE [--max-seconds S]

Publishes TOKEN on token_listener.py's topic at 20 Hz and subscribes to it too. Once it
has heard its own token (so DDS works here with whatever discovery range it was given)
it creates READY_FILE, then keeps publishing until STOP_FILE exists or --max-seconds
pass. Prints one line ``RESULT {json}``; exits 0 if it heard itself.
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


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("token")
    parser.add_argument("ready_file", type=Path)
    parser.add_argument("stop_file", type=Path)
    parser.add_argument("--max-seconds", type=float, default=40.0)
    args = parser.parse_args()

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
    node = rclpy.create_node("host_talker", context=context)
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
    started = time.monotonic()
    while not own and time.monotonic() < started + OWN_DEADLINE_S:
        executor.spin_once(timeout_sec=PERIOD_S)
    if own:
        args.ready_file.write_text(str(os.getpid()))
        while not args.stop_file.exists() and time.monotonic() < started + args.max_seconds:
            executor.spin_once(timeout_sec=PERIOD_S)
    executor.shutdown()
    node.destroy_node()  # type: ignore[no-untyped-call]
    context.try_shutdown()
    report = {"domain_id": os.environ.get("ROS_DOMAIN_ID"), "own": own, "foreign": dict(foreign)}
    print("RESULT " + json.dumps(report), flush=True)
    return 0 if own else 1


if __name__ == "__main__":
    sys.exit(main())

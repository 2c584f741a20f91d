#!/usr/bin/env python3
"""Publish one token on a shared topic and fail on hearing anybody else's.

Six copies run at once under ctest. On one ROS domain they hear each other and fail;
each on a domain of its own, they pass. Hearing its own token first proves that DDS
works at all, so a pass is never just silence.

Usage: token_talker.py TOKEN
Writes $CROSSTALK_RECORD_DIR/TOKEN.json when that variable is set.
"""

from __future__ import annotations

import json
import os
import sys
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

TOPIC = "/crosstalk"
PUBLISH_PERIOD_S = 0.05  # 20 Hz
OWN_TOKEN_DEADLINE_S = 15.0  # discovery plus first delivery, generous for a loaded machine
LISTEN_S = 4.0  # after hearing ourselves: long enough to overlap with the other five
QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=50,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)


class TokenTalker:
    """Publishes a token on a timer and counts every token heard on the same topic."""

    def __init__(self, node: Node, token: str) -> None:
        self.token = token
        self.own_received = 0
        self.foreign: Counter[str] = Counter()
        self._publisher = node.create_publisher(String, TOPIC, QOS)
        node.create_subscription(String, TOPIC, self._on_message, QOS)
        node.create_timer(PUBLISH_PERIOD_S, self._publish)

    def _publish(self) -> None:
        self._publisher.publish(String(data=self.token))

    def _on_message(self, message: String) -> None:
        if message.data == self.token:
            self.own_received += 1
        else:
            self.foreign[message.data] += 1


def spin_until(
    executor: SingleThreadedExecutor, deadline: float, done: Callable[[], bool] | None = None
) -> None:
    """Spin in short slices (never forever) until the deadline or until done() is true."""
    while time.monotonic() < deadline:
        if done is not None and done():
            return
        executor.spin_once(timeout_sec=PUBLISH_PERIOD_S)


def talk(token: str) -> TokenTalker:
    """Run the publish-and-listen exchange on a context of our own, then shut it down."""
    context = Context()
    rclpy.init(args=[], context=context)
    executor = SingleThreadedExecutor(context=context)
    node = rclpy.create_node(f"token_talker_{token_node_suffix(token)}", context=context)
    try:
        talker = TokenTalker(node, token)
        executor.add_node(node)
        spin_until(
            executor,
            time.monotonic() + OWN_TOKEN_DEADLINE_S,
            lambda: talker.own_received > 0,
        )
        if talker.own_received:
            spin_until(executor, time.monotonic() + LISTEN_S)
        return talker
    finally:
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()


def token_node_suffix(token: str) -> str:
    """Node names allow only letters, digits and underscores; tokens are free text."""
    return "".join(c if c.isalnum() else "_" for c in token) or "empty"


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        print(f"usage: {Path(argv[0]).name} TOKEN", file=sys.stderr)
        return 2
    token = argv[1]
    start = time.time()
    domain_id = os.environ.get("ROS_DOMAIN_ID")
    print(f"token={token} ROS_DOMAIN_ID={domain_id if domain_id is not None else 'unset'}")

    talker = talk(token)
    end = time.time()
    passed = talker.own_received > 0 and not talker.foreign
    if not talker.own_received:
        verdict = (
            f"FAIL token={token}: never received its own token in {OWN_TOKEN_DEADLINE_S:.0f} s"
            " (DDS delivery broken?)"
        )
    elif talker.foreign:
        heard = ", ".join(f"{t} x{n}" for t, n in sorted(talker.foreign.items()))
        verdict = f"FAIL token={token}: crosstalk, received foreign tokens: {heard}"
    else:
        verdict = (
            f"PASS token={token}: received own token {talker.own_received} times, no other token"
        )

    record_dir = os.environ.get("CROSSTALK_RECORD_DIR")
    if record_dir:
        record = {
            "token": token,
            "domain_id": domain_id,
            "pid": os.getpid(),
            "start": start,
            "end": end,
            "own_received": talker.own_received,
            "foreign": dict(talker.foreign),
            "passed": passed,
        }
        Path(record_dir).mkdir(parents=True, exist_ok=True)
        (Path(record_dir) / f"{token}.json").write_text(json.dumps(record, indent=2) + "\n")

    print(verdict)
    return 0 if passed else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv))

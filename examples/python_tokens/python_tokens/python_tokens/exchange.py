"""Publish a token on a shared topic in this process, and fail on hearing anybody else's.

Tests call :func:`check` with a token of their own. On one ROS domain, tests running at
the same time hear each other and fail; each on a domain of its own, they pass. Hearing
its own token first proves DDS works at all, so a pass is never just silence. With
CROSSTALK_RECORD_DIR set, each check writes TOKEN.json there (domain, PID, what it heard).
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

TOPIC = "/python_tokens"
PERIOD_S = 0.05
#: Discovery and first delivery; generous for a loaded machine.
OWN_DEADLINE_S = 15.0
#: Listening after hearing ourselves: long enough to overlap with the other tests.
LISTEN_S = 4.0
QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=50,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)


def _spin(executor: SingleThreadedExecutor, seconds: float, done: object = None) -> None:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and not (callable(done) and done()):
        executor.spin_once(timeout_sec=PERIOD_S)


def listen(token: str) -> tuple[int, dict[str, int]]:
    """Publish ``token`` and count what is heard: (own deliveries, foreign tokens)."""
    heard = {"own": 0}
    foreign: dict[str, int] = {}

    def on_message(message: String) -> None:
        if message.data == token:
            heard["own"] += 1
        else:
            foreign[message.data] = foreign.get(message.data, 0) + 1

    context = Context()
    rclpy.init(args=[], context=context)
    executor = SingleThreadedExecutor(context=context)
    node = rclpy.create_node(f"python_tokens_{token}", context=context)
    try:
        publisher = node.create_publisher(String, TOPIC, QOS)
        node.create_subscription(String, TOPIC, on_message, QOS)
        node.create_timer(PERIOD_S, lambda: publisher.publish(String(data=token)))
        executor.add_node(node)
        _spin(executor, OWN_DEADLINE_S, lambda: heard["own"] > 0)
        if heard["own"]:
            _spin(executor, LISTEN_S)
    finally:
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()
    return heard["own"], foreign


def check(token: str) -> None:
    """Assert that ``token`` is heard, and nothing else: the test's whole verdict."""
    domain_id = os.environ.get("ROS_DOMAIN_ID")
    start = time.time()
    own, foreign = listen(token)
    record_dir = os.environ.get("CROSSTALK_RECORD_DIR")
    if record_dir:
        record = {
            "token": token,
            "domain_id": domain_id,
            "pid": os.getpid(),
            "start": start,
            "end": time.time(),
            "own_received": own,
            "foreign": foreign,
            "passed": bool(own) and not foreign,
        }
        Path(record_dir).mkdir(parents=True, exist_ok=True)
        (Path(record_dir) / f"{token}.json").write_text(json.dumps(record) + "\n")
    assert own, f"never heard its own token {token!r} in {OWN_DEADLINE_S:.0f} s"
    assert not foreign, f"crosstalk on ROS_DOMAIN_ID {domain_id}: heard {foreign}"

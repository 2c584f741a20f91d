"""The exchange the helper tests make: publish a token, hear it, then keep listening.

Hearing its own token first proves DDS works with whatever domain and discovery range
the test was given, so silence afterwards means isolation, not a broken middleware.
``publishing`` alone is what the leaked daemon of daemon_talker.py runs.
"""

from __future__ import annotations

import contextlib
import os
import time
from collections import Counter
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import QoSProfile

TOPIC = "/ros_isolated_test/process_tree"
PERIOD_S = 0.05
OWN_DEADLINE_S = 15.0


@contextlib.contextmanager
def publishing(
    token: str, node_name: str
) -> Iterator[tuple[Node, SingleThreadedExecutor, QoSProfile]]:
    """A node publishing ``token`` on TOPIC every PERIOD_S, torn down on leaving.

    Its own rclpy context, without rclpy's signal handlers: the helpers handle signals.
    rclpy is imported here, not at the top: a helper that forks first imports it after.
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from rclpy.signals import SignalHandlerOptions
    from std_msgs.msg import String  # type: ignore[import-untyped]

    context = Context()
    rclpy.init(args=[], context=context, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node(node_name, context=context)
    qos = QoSProfile(  # type: ignore[no-untyped-call]
        history=HistoryPolicy.KEEP_LAST,
        depth=50,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.VOLATILE,
    )
    publisher = node.create_publisher(String, TOPIC, qos)
    node.create_timer(PERIOD_S, lambda: publisher.publish(String(data=token)))
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        yield node, executor, qos
    finally:
        executor.shutdown()
        node.destroy_node()  # type: ignore[no-untyped-call]
        context.try_shutdown()


def exchange(
    token: str,
    node_name: str,
    keep_going: Callable[[float], bool],
    on_heard: Callable[[], None] | None = None,
) -> dict[str, object]:
    """Publish ``token`` at 20 Hz and count what is heard on the shared topic.

    Once its own token is heard, ``on_heard`` runs and spinning goes on while
    ``keep_going(seconds since then)`` is true. Returns the report both helpers print.
    """
    from std_msgs.msg import String

    own = 0
    foreign: Counter[str] = Counter()

    def on_message(message: String) -> None:
        nonlocal own
        if message.data == token:
            own += 1
        else:
            foreign[message.data] += 1

    with publishing(token, node_name) as (node, executor, qos):
        node.create_subscription(String, TOPIC, on_message, qos)
        deadline = time.monotonic() + OWN_DEADLINE_S
        while not own and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=PERIOD_S)
        if own:
            if on_heard is not None:
                on_heard()
            heard_at = time.monotonic()
            while keep_going(time.monotonic() - heard_at):
                executor.spin_once(timeout_sec=PERIOD_S)
    return {"domain_id": os.environ.get("ROS_DOMAIN_ID"), "own": own, "foreign": dict(foreign)}

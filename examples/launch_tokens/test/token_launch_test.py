"""A launch test: start a token talker, then check in the test case that only its token is heard.

The talker is the crosstalk demo's own (examples/crosstalk_demo/test/token_talker.py),
started with ``ExecuteProcess``; its token comes from ``LAUNCH_TOKEN`` (the test's ENV).
Four of these run at once: on one ROS domain each hears the others' tokens and fails; each
on a domain of its own, all pass. Hearing the talker's token first proves DDS works, so a
pass is never just silence; and the talker itself fails on a foreign token (its exit code
is checked after shutdown), so both ends of the exchange are judged.
"""

from __future__ import annotations

import os
import sys
import time
import unittest
from collections import Counter
from pathlib import Path

import launch
import launch.actions
import launch_testing.actions
import launch_testing.asserts
import launch_testing.util
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from std_msgs.msg import String

TALKER = Path(__file__).resolve().parents[2] / "crosstalk_demo" / "test" / "token_talker.py"
sys.path.insert(0, str(TALKER.parent))
import token_talker  # noqa: E402  (the talker's topic, QoS and timings, never a copy)

TOKEN = os.environ["LAUNCH_TOKEN"]


def generate_test_description() -> tuple[launch.LaunchDescription, dict[str, object]]:
    talker = launch.actions.ExecuteProcess(
        cmd=[sys.executable, str(TALKER), TOKEN], name=f"talker_{TOKEN}", output="screen"
    )
    # The talker ends by itself; the launch must outlive it until the test case is done.
    keep_alive = launch_testing.util.KeepAliveProc()
    ready = launch_testing.actions.ReadyToTest()
    return launch.LaunchDescription([talker, keep_alive, ready]), {"talker": talker}


class TestOnlyOwnTokenHeard(unittest.TestCase):
    def test_only_own_token_heard(self, proc_info: object, talker: object) -> None:
        heard: Counter[str] = Counter()
        context = Context()
        rclpy.init(args=[], context=context)
        executor = SingleThreadedExecutor(context=context)
        node = rclpy.create_node(
            f"listener_{token_talker.token_node_suffix(TOKEN)}", context=context
        )
        try:
            node.create_subscription(
                String, token_talker.TOPIC, lambda m: heard.update([m.data]), token_talker.QOS
            )
            executor.add_node(node)
            token_talker.spin_until(
                executor,
                time.monotonic() + token_talker.OWN_TOKEN_DEADLINE_S,
                lambda: heard[TOKEN] > 0,
            )
            if heard[TOKEN]:  # then listen while the talker does
                token_talker.spin_until(executor, time.monotonic() + token_talker.LISTEN_S)
        finally:
            executor.shutdown()
            node.destroy_node()
            context.try_shutdown()
        # The talker ends by itself and writes its record: let it, whatever we heard.
        proc_info.assertWaitForShutdown(process=talker, timeout=60)  # type: ignore[attr-defined]
        domain = os.environ.get("ROS_DOMAIN_ID", "unset")
        print(f"listener token={TOKEN} ROS_DOMAIN_ID={domain} heard={dict(heard)}")
        self.assertGreater(heard[TOKEN], 0, f"never heard its own token {TOKEN}")
        foreign = {token: count for token, count in heard.items() if token != TOKEN}
        self.assertEqual(foreign, {}, f"crosstalk: heard tokens not its own: {foreign}")


@launch_testing.post_shutdown_test()
class TestTalkerPassed(unittest.TestCase):
    def test_talker_exit_code(self, proc_info: object, talker: object) -> None:
        """The talker exits 1 when it heard a foreign token itself."""
        launch_testing.asserts.assertExitCodes(proc_info, process=talker)

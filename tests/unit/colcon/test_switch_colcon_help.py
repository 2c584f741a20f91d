from __future__ import annotations

from ros_isolated_test.colcon.environment_variable import ROS_ISOLATED_TEST_COLCON
from ros_isolated_test.colcon.switch import VARIABLE


def test_colcon_help_lists_the_switch() -> None:
    assert ROS_ISOLATED_TEST_COLCON.name == VARIABLE
    assert "off" in ROS_ISOLATED_TEST_COLCON.description

"""The ``colcon_core.environment_variable`` entry: ``colcon --help`` lists our switch."""

from __future__ import annotations

from colcon_core.environment_variable import EnvironmentVariable  # type: ignore[import-untyped]

from ros_isolated_test.colcon.switch import DESCRIPTION, VARIABLE

ROS_ISOLATED_TEST_COLCON = EnvironmentVariable(VARIABLE, DESCRIPTION)

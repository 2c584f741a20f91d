"""Run ROS 2 tests in parallel, each on a ROS_DOMAIN_ID of its own."""

__version__ = "0.1.0"

"""A pytest test (ament_add_pytest_test) that fails without a ROS_DOMAIN_ID of its own."""

import os


def test_has_a_domain_id() -> None:
    value = os.environ.get("ROS_DOMAIN_ID", "")
    assert value.isdigit(), f"ROS_DOMAIN_ID is {value!r}"

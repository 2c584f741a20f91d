#!/usr/bin/env python3
"""Exit 0 when ROS_DOMAIN_ID is as expected: `check_domain.py set` or `check_domain.py unset`."""

import os
import sys

expect = sys.argv[1]
value = os.environ.get("ROS_DOMAIN_ID")
print(f"ROS_DOMAIN_ID={value!r}, expected {expect}")
sys.exit(0 if (value is not None) == (expect == "set") else 1)

"""The RUNNER's old home: a forwarding script for workspaces configured before it moved.

The RUNNER lives in ``ros_isolated_test.ament``; a CMake cache or a colcon defaults file
written earlier still names ``runner/ament/run_test_isolated.py``.
"""

"""``python -m ros_isolated_test``: the same CLI as the ``ros-isolated-test`` command."""

from ros_isolated_test.runner.cli import main

main()

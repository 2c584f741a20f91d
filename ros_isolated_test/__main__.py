"""``python -m ros_isolated_test``: the same CLI as the ``ros-isolated-test`` command."""

from ros_isolated_test.cli import main

main()

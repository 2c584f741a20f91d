"""The pytest side: a ROS_DOMAIN_ID of its own for each pytest session, launch tests case by case.

``plugin`` is the ``pytest11`` entry point (named ``ros_isolated_test``: ``-p
no:ros_isolated_test`` turns it off) and holds only pytest's hooks; each hook hands its
work to the module that does it, as pytest-xdist's plugin.py hands its work to the
session it drives:

- ``options``: the plugin's options and the rules that turn it on (read by every pytest
  run, so it imports nothing of the runner);
- ``holding``: the runner's decision for the session, the ID and resources it holds
  (os.environ, pytest's header, ``--junit-xml``), and their release;
- ``interrupts``: SIGTERM and SIGHUP end the session as Ctrl-C does; an xdist controller
  passes them on to its workers and waits for them;
- ``launch_testing_cases`` and ``launch_testing_verdicts``: launch_testing files reported
  case by case (the only modules that read launch_testing);
- ``launch_pytest_tests``: launch_pytest's tests each reported as itself, a launch that
  fails one error (the only module that reads launch_pytest);
- ``scheduling``: pytest-xdist keeps a launch's tests on one worker.

Nothing here is imported by pytest until the plugin's hooks ask for it.
"""

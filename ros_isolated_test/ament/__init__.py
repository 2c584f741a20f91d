"""The ctest RUNNER: ``run_test_isolated.py`` (the script ctest runs) and ``args`` (its arguments).

The argument set is ament_cmake_test's ``run_test.py``, parsed into the same request
every other entry point builds.
"""

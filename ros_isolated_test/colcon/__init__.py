"""colcon's way in: installed means on, for ``colcon build`` and ``colcon test``.

colcon loads these extensions from its own Python's entry points (pyproject.toml), so
installing ros-isolated-test where colcon runs is all it takes: ``argument_parser``
points every ament_cmake package at the stable include of ``project_include``,
``event_handler`` ends ``colcon test`` with one summary line and the page of
``summary``. ``switch`` reads ``ROS_ISOLATED_TEST_COLCON`` (off turns all of it off),
``environment_variable`` lists it in ``colcon --help``. Only colcon imports the modules
that import colcon; the runner never imports this package.
"""

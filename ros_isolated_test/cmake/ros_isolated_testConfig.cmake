# CMake package of ros-isolated-test: find_package(ros_isolated_test REQUIRED).
#
# pip installs this file under <prefix>/share/ros_isolated_test/cmake/, next to the
# <prefix>/bin/ros-isolated-test command, so CMake finds it from PATH alone (CMake turns
# every PATH entry ending in bin/ into a search prefix): no CMAKE_PREFIX_PATH is needed.
#
# Provides:
#   ros_isolated_test_all()           every later ament_add_test (and so ament_add_gtest,
#                                     ament_add_gmock, ament_add_pytest_test,
#                                     add_launch_test, ...) without a RUNNER of its own runs
#                                     through ros-isolated-test
#   ros_isolated_add_test()           ament_add_test with our RUNNER
#   ros_isolated_add_gtest()          ament_add_gtest with our RUNNER
#   ros_isolated_add_gmock()          ament_add_gmock with our RUNNER
#   ros_isolated_add_pytest_test()    ament_add_pytest_test with our RUNNER
#   ros_isolated_add_launch_test()    add_launch_test with our RUNNER
#   ros_isolated_test_RUNNER          the RUNNER script's path (also the global property
#                                     ROS_ISOLATED_TEST_RUNNER)
#   ROS_ISOLATED_TEST_EXECUTABLE      (cache) the ros-isolated-test command that was asked

if(DEFINED _ros_isolated_test_CONFIG_INCLUDED)
  return()
endif()
set(_ros_isolated_test_CONFIG_INCLUDED TRUE)

# The command of this very installation first (<prefix>/bin beside <prefix>/share), so a
# second installation earlier on PATH cannot hand us a runner of another version.
get_filename_component(_ros_isolated_test_prefix "${CMAKE_CURRENT_LIST_DIR}/../../.." ABSOLUTE)
find_program(ROS_ISOLATED_TEST_EXECUTABLE ros-isolated-test
  PATHS "${_ros_isolated_test_prefix}/bin"
  NO_DEFAULT_PATH)
find_program(ROS_ISOLATED_TEST_EXECUTABLE ros-isolated-test)
set(_ros_isolated_test_fix
  "Install ros-isolated-test into the environment colcon and CMake run in (the source "
  "package built and its install/setup.bash sourced, or pip: see Install it in its README), "
  "with its ros-isolated-test command on PATH, or name the command with "
  "-DROS_ISOLATED_TEST_EXECUTABLE=/path/to/ros-isolated-test.")

if(NOT ROS_ISOLATED_TEST_EXECUTABLE)
  set(ros_isolated_test_FOUND FALSE)
  set(ros_isolated_test_NOT_FOUND_MESSAGE
    "the ros-isolated-test command was found neither in ${_ros_isolated_test_prefix}/bin "
    "nor on PATH. ${_ros_isolated_test_fix}")
  string(REPLACE ";" "" ros_isolated_test_NOT_FOUND_MESSAGE
    "${ros_isolated_test_NOT_FOUND_MESSAGE}")
  unset(_ros_isolated_test_CONFIG_INCLUDED)
  return()
endif()

execute_process(
  COMMAND "${ROS_ISOLATED_TEST_EXECUTABLE}" runner-path
  OUTPUT_VARIABLE _ros_isolated_test_runner
  ERROR_VARIABLE _ros_isolated_test_error
  RESULT_VARIABLE _ros_isolated_test_rc
  OUTPUT_STRIP_TRAILING_WHITESPACE
  ERROR_STRIP_TRAILING_WHITESPACE)
if(NOT _ros_isolated_test_rc STREQUAL "0" OR NOT EXISTS "${_ros_isolated_test_runner}")
  set(ros_isolated_test_FOUND FALSE)
  set(ros_isolated_test_NOT_FOUND_MESSAGE
    "'${ROS_ISOLATED_TEST_EXECUTABLE} runner-path' did not print the path of the RUNNER "
    "script (exit status ${_ros_isolated_test_rc}, output '${_ros_isolated_test_runner}', "
    "error '${_ros_isolated_test_error}'). ${_ros_isolated_test_fix}")
  string(REPLACE ";" "" ros_isolated_test_NOT_FOUND_MESSAGE
    "${ros_isolated_test_NOT_FOUND_MESSAGE}")
  unset(_ros_isolated_test_CONFIG_INCLUDED)
  return()
endif()

set(ros_isolated_test_RUNNER "${_ros_isolated_test_runner}")
# A global property as well: the macros may be called in a directory scope that never saw
# the variable (find_package in a sibling directory).
set_property(GLOBAL PROPERTY ROS_ISOLATED_TEST_RUNNER "${_ros_isolated_test_runner}")
if(NOT ros_isolated_test_FIND_QUIETLY)
  message(STATUS "Found ros_isolated_test: tests run through ${_ros_isolated_test_runner}")
endif()

include("${CMAKE_CURRENT_LIST_DIR}/ros_isolated_test_macros.cmake")
include("${CMAKE_CURRENT_LIST_DIR}/ros_isolated_test_all.cmake")

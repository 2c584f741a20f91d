# ros_isolated_add_*: the ament and launch_testing test macros with ros-isolated-test as
# RUNNER. Each takes exactly the arguments of the macro it wraps, and one more:
# RERUNS <n> runs a failed test again up to n times, every attempt kept in its result file
# (ENV ROS_ISOLATED_TEST_RERUNS=<n>, which the RUNNER reads). Our RUNNER comes first, so a
# RUNNER the call names itself comes later and wins (cmake_parse_arguments keeps the last
# value).

# The RUNNER script's path, wherever find_package(ros_isolated_test) was called.
function(_ros_isolated_test_runner var)
  get_property(_runner GLOBAL PROPERTY ROS_ISOLATED_TEST_RUNNER)
  if(NOT _runner)
    message(FATAL_ERROR "ros_isolated_test: no RUNNER script is known; call "
      "find_package(ros_isolated_test REQUIRED) before the ros_isolated_* macros")
  endif()
  set(${var} "${_runner}" PARENT_SCOPE)
endfunction()

# The call's arguments in ${var}, RERUNS <n> turned into ENV ROS_ISOLATED_TEST_RERUNS=<n>.
# Last: ament_add_test passes ENV on as --env, where the last value of a variable wins.
function(_ros_isolated_test_arguments var)
  cmake_parse_arguments(_rit "" "RERUNS" "" ${ARGN})
  set(_arguments ${_rit_UNPARSED_ARGUMENTS})
  if("RERUNS" IN_LIST _rit_KEYWORDS_MISSING_VALUES)
    set(_rit_RERUNS "")
  endif()
  if(DEFINED _rit_RERUNS)
    _ros_isolated_test_check_reruns("${_rit_RERUNS}")
    list(APPEND _arguments ENV "ROS_ISOLATED_TEST_RERUNS=${_rit_RERUNS}")
  endif()
  set(${var} "${_arguments}" PARENT_SCOPE)
endfunction()

# Stops configuring when RERUNS is no whole number: the test would fail at every run.
function(_ros_isolated_test_check_reruns value)
  if(NOT value MATCHES "^[0-9]+$")
    message(FATAL_ERROR "ros_isolated_test: RERUNS '${value}' is not a number of reruns; "
      "pass a whole number, 0 or more (e.g. RERUNS 2)")
  endif()
endfunction()

# Macros, not functions: a macro runs in the caller's scope, so what find_package() sets
# when a macro finds ament_cmake_gtest, ament_cmake_pytest, ... outlives the call, and the
# next call neither finds the package again nor loads its files a second time. Their own
# variables carry the _ros_isolated_test prefix, as they land in the caller's scope too.

# ros_isolated_add_test(testname COMMAND ... [RERUNS n] [any ament_add_test argument])
macro(ros_isolated_add_test _ros_isolated_test_name)
  _ros_isolated_test_runner(_ros_isolated_test_runner_path)
  _ros_isolated_test_arguments(_ros_isolated_test_arguments ${ARGN})
  ament_add_test("${_ros_isolated_test_name}" RUNNER "${_ros_isolated_test_runner_path}"
    ${_ros_isolated_test_arguments})
endmacro()

# ros_isolated_add_gtest(target source... [any ament_add_gtest argument])
macro(ros_isolated_add_gtest _ros_isolated_test_target)
  if(NOT COMMAND ament_add_gtest)
    find_package(ament_cmake_gtest REQUIRED)
  endif()
  _ros_isolated_test_runner(_ros_isolated_test_runner_path)
  _ros_isolated_test_arguments(_ros_isolated_test_arguments ${ARGN})
  ament_add_gtest("${_ros_isolated_test_target}" RUNNER "${_ros_isolated_test_runner_path}"
    ${_ros_isolated_test_arguments})
endmacro()

# ros_isolated_add_gmock(target source... [any ament_add_gmock argument])
macro(ros_isolated_add_gmock _ros_isolated_test_target)
  if(NOT COMMAND ament_add_gmock)
    find_package(ament_cmake_gmock REQUIRED)
  endif()
  _ros_isolated_test_runner(_ros_isolated_test_runner_path)
  _ros_isolated_test_arguments(_ros_isolated_test_arguments ${ARGN})
  ament_add_gmock("${_ros_isolated_test_target}" RUNNER "${_ros_isolated_test_runner_path}"
    ${_ros_isolated_test_arguments})
endmacro()

# ros_isolated_add_pytest_test(testname path [any ament_add_pytest_test argument])
macro(ros_isolated_add_pytest_test _ros_isolated_test_name _ros_isolated_test_path)
  if(NOT COMMAND ament_add_pytest_test)
    find_package(ament_cmake_pytest REQUIRED)
  endif()
  _ros_isolated_test_runner(_ros_isolated_test_runner_path)
  _ros_isolated_test_arguments(_ros_isolated_test_arguments ${ARGN})
  ament_add_pytest_test("${_ros_isolated_test_name}" "${_ros_isolated_test_path}"
    RUNNER "${_ros_isolated_test_runner_path}" ${_ros_isolated_test_arguments})
endmacro()

# ros_isolated_add_launch_test(file [any add_launch_test argument])
macro(ros_isolated_add_launch_test _ros_isolated_test_file)
  if(NOT COMMAND add_launch_test)
    find_package(launch_testing_ament_cmake REQUIRED)
  endif()
  _ros_isolated_test_runner(_ros_isolated_test_runner_path)
  _ros_isolated_test_arguments(_ros_isolated_test_arguments ${ARGN})
  # add_launch_test passes arguments it does not know (RUNNER) on to ament_add_test.
  add_launch_test("${_ros_isolated_test_file}"
    RUNNER "${_ros_isolated_test_runner_path}" ${_ros_isolated_test_arguments})
endmacro()

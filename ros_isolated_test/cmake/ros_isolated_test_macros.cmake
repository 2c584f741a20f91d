# ros_isolated_add_*: the ament and launch_testing test macros with ros-isolated-test as
# RUNNER. Each takes exactly the arguments of the macro it wraps. Our RUNNER comes first,
# so a RUNNER the call names itself comes later and wins (cmake_parse_arguments keeps the
# last value).

# The RUNNER script's path, wherever find_package(ros_isolated_test) was called.
function(_ros_isolated_test_runner var)
  get_property(_runner GLOBAL PROPERTY ROS_ISOLATED_TEST_RUNNER)
  if(NOT _runner)
    message(FATAL_ERROR "ros_isolated_test: no RUNNER script is known; call "
      "find_package(ros_isolated_test REQUIRED) before the ros_isolated_* macros")
  endif()
  set(${var} "${_runner}" PARENT_SCOPE)
endfunction()

# ros_isolated_add_test(testname COMMAND ... [any ament_add_test argument])
function(ros_isolated_add_test testname)
  _ros_isolated_test_runner(_runner)
  ament_add_test("${testname}" RUNNER "${_runner}" ${ARGN})
endfunction()

# ros_isolated_add_gtest(target source... [any ament_add_gtest argument])
function(ros_isolated_add_gtest target)
  if(NOT COMMAND ament_add_gtest)
    find_package(ament_cmake_gtest REQUIRED)
  endif()
  _ros_isolated_test_runner(_runner)
  ament_add_gtest("${target}" RUNNER "${_runner}" ${ARGN})
endfunction()

# ros_isolated_add_gmock(target source... [any ament_add_gmock argument])
function(ros_isolated_add_gmock target)
  if(NOT COMMAND ament_add_gmock)
    find_package(ament_cmake_gmock REQUIRED)
  endif()
  _ros_isolated_test_runner(_runner)
  ament_add_gmock("${target}" RUNNER "${_runner}" ${ARGN})
endfunction()

# ros_isolated_add_pytest_test(testname path [any ament_add_pytest_test argument])
function(ros_isolated_add_pytest_test testname path)
  if(NOT COMMAND ament_add_pytest_test)
    find_package(ament_cmake_pytest REQUIRED)
  endif()
  _ros_isolated_test_runner(_runner)
  ament_add_pytest_test("${testname}" "${path}" RUNNER "${_runner}" ${ARGN})
endfunction()

# ros_isolated_add_launch_test(file [any add_launch_test argument])
#
# A macro, not a function: launch_testing_ament_cmake is found here only when the package
# has a launch test, and what find_package() sets must outlive the call, or the next call
# would load the package again.
macro(ros_isolated_add_launch_test _ros_isolated_test_file)
  if(NOT COMMAND add_launch_test)
    find_package(launch_testing_ament_cmake REQUIRED)
  endif()
  _ros_isolated_test_runner(_ros_isolated_test_launch_runner)
  # add_launch_test passes arguments it does not know (RUNNER) on to ament_add_test.
  add_launch_test("${_ros_isolated_test_file}"
    RUNNER "${_ros_isolated_test_launch_runner}" ${ARGN})
endmacro()

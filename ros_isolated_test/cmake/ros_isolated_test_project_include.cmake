# Zero edits: every test an ament_cmake package registers runs on a ROS_DOMAIN_ID of its
# own, without a line of the package changed. Give this file to CMake as
#
#   colcon build --cmake-args -DCMAKE_PROJECT_INCLUDE=$(ros-isolated-test cmake-include)
#
# CMake (3.15 and newer) includes it right after every project() call of the build, in
# that call's directory scope. In an ament_cmake package (a package.xml beside the
# project() call whose build_type is ament_cmake) it finds ament_cmake_test before the
# package does and calls ros_isolated_test_all(): every later ament_add_test (and so
# ament_add_gtest, ament_add_gmock, ament_add_pytest_test, add_launch_test, ...) without a
# RUNNER of its own runs through ros-isolated-test, and a test with its own RUNNER keeps
# it. ament's include guards keep the wrapper when the package itself finds ament_cmake
# later; a package that calls ros_isolated_test_all() or the ros_isolated_add_* macros
# itself works unchanged (the wrapper is defined once; the macros name our RUNNER).
#
# Anything else is left untouched, silently, with nothing found and nothing cached: a
# plain CMake package, a vendored third-party project, googletest built inside a package,
# the second project() call of a package (already done, or opted out).
#
# One status line per package says that its tests are isolated and by which runner.
# Off: -DROS_ISOLATED_TEST_ALL=OFF (for one package: a colcon.meta entry, or that
# package's cached value); the package's own ros_isolated_test_all() or macros still
# apply then.

# Whether this project() call is to be isolated: "yes", "off" (an ament_cmake package
# that opted out) or "" (not ours to touch). A function: nothing it reads stays behind,
# and it keeps the policies it is defined with (ours) whatever the project asked for (a
# vendored project may still say cmake_minimum_required(VERSION 2.8)). What it decides
# runs under the package's own policies, as if the package had asked for it: ament's
# functions keep the policies they are defined with too.
cmake_policy(PUSH)
cmake_policy(VERSION 3.15)
function(_ros_isolated_test_project_include_decision var)
  set(${var} "" PARENT_SCOPE)
  get_property(_wrapped GLOBAL PROPERTY _ROS_ISOLATED_TEST_ALL)
  if(_wrapped)
    return()  # a project() before this one, or the package itself, did it already
  endif()
  set(_manifest "${CMAKE_CURRENT_SOURCE_DIR}/package.xml")
  if(NOT EXISTS "${_manifest}")
    return()
  endif()
  file(READ "${_manifest}" _xml)
  if(NOT _xml MATCHES "<build_type[^>]*>[ \t\r\n]*ament_cmake[ \t\r\n]*</build_type>")
    return()
  endif()
  if(DEFINED BUILD_TESTING AND NOT BUILD_TESTING)
    return()  # no tests to isolate (colcon build --cmake-args -DBUILD_TESTING=OFF)
  endif()
  if(DEFINED ROS_ISOLATED_TEST_ALL AND NOT ROS_ISOLATED_TEST_ALL)
    set(${var} "off" PARENT_SCOPE)
  else()
    set(${var} "yes" PARENT_SCOPE)
  endif()
endfunction()
cmake_policy(POP)

_ros_isolated_test_project_include_decision(_ros_isolated_test_project_include)

if(_ros_isolated_test_project_include MATCHES "^off$")
  get_property(_ros_isolated_test_said GLOBAL PROPERTY _ROS_ISOLATED_TEST_ALL_OFF_SAID)
  if(NOT _ros_isolated_test_said)
    set_property(GLOBAL PROPERTY _ROS_ISOLATED_TEST_ALL_OFF_SAID TRUE)
    message(STATUS "ros_isolated_test: tests of ${PROJECT_NAME} are NOT isolated "
      "(ROS_ISOLATED_TEST_ALL is ${ROS_ISOLATED_TEST_ALL}): only its own "
      "ros_isolated_test_all() or ros_isolated_add_* calls would isolate them")
  endif()
  unset(_ros_isolated_test_said)
elseif(_ros_isolated_test_project_include MATCHES "^yes$")
  # Found here, in the directory scope of project(), as the package would find it: its
  # own find_package(ament_cmake) later meets ament's include guards and keeps our wrapper.
  if(NOT COMMAND ament_add_test)
    find_package(ament_cmake_test QUIET)
  endif()
  if(COMMAND ament_add_test)
    # This very installation's package, whatever else CMAKE_PREFIX_PATH holds.
    find_package(ros_isolated_test CONFIG QUIET
      PATHS "${CMAKE_CURRENT_LIST_DIR}" NO_DEFAULT_PATH)
    if(NOT ros_isolated_test_FOUND)
      message(FATAL_ERROR "ros_isolated_test (CMAKE_PROJECT_INCLUDE): cannot isolate the "
        "tests of ${PROJECT_NAME}: ${ros_isolated_test_NOT_FOUND_MESSAGE} Or configure "
        "without it: -DROS_ISOLATED_TEST_ALL=OFF.")
    endif()
    ros_isolated_test_all()
    message(STATUS "ros_isolated_test: tests of ${PROJECT_NAME} are isolated, each on a "
      "ROS_DOMAIN_ID of its own, run by ${ros_isolated_test_RUNNER} (CMAKE_PROJECT_INCLUDE; "
      "-DROS_ISOLATED_TEST_ALL=OFF turns it off)")
  endif()
  # Not found: an ament_cmake package without ament_cmake_test fails on its own
  # find_package(ament_cmake), with ament's message rather than ours.
endif()
unset(_ros_isolated_test_project_include)

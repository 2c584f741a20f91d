# Zero edits: every test an ament_cmake package registers runs on a ROS_DOMAIN_ID of its
# own, without a line of the package changed. Give this file to CMake as
#
#   colcon build --cmake-args -DCMAKE_PROJECT_INCLUDE=$(ros-isolated-test cmake-include)
#
# CMake (3.15 and newer) includes it right after every project() call of the build, in
# that call's directory scope. In an ament_cmake package (a package.xml beside the
# project() call whose <export> holds <build_type>ament_cmake</build_type>, read as markup:
# a comment says nothing) it finds ament_cmake_test before the package does and calls
# ros_isolated_test_all(): every later ament_add_test (and so ament_add_gtest,
# ament_add_gmock, ament_add_pytest_test, add_launch_test, ...) without a RUNNER of its own,
# or with upstream's isolated runner (ament_cmake_ros's run_test_isolated.py), runs through
# ros-isolated-test; a test with any other RUNNER keeps it. ament's include guards keep the
# wrapper when the package itself finds ament_cmake later; a package that calls
# ros_isolated_test_all() or the ros_isolated_add_* macros itself works unchanged (the
# wrapper is defined once; the macros name our RUNNER).
#
# Anything else is left untouched, silently, with nothing found and nothing cached: a
# plain CMake package, a vendored third-party project, googletest built inside a package,
# the second project() call of a package (already done, or opted out).
#
# Configuring says, once all tests are registered (CMake 3.19 and newer), how many tests
# of the package are isolated and how many of them were taken over from upstream's
# runner, and names each test that is not and why (a RUNNER of its own, a plain
# add_test()). With BUILD_TESTING OFF it says nothing unless the package registers tests
# anyway (an ament_add_test outside if(BUILD_TESTING)): those are isolated too, and said
# to be; where no runner can be found then, they are named as NOT isolated instead of
# failing a build that was not meant to test.
# In a split (ROS_ISOLATED_TEST_SHARD=I/N when ctest runs) ctest does not start the
# other shares' tests (ros_isolated_test_share.cmake).
# Off: -DROS_ISOLATED_TEST_ALL=OFF (for one package: a colcon.meta entry, or that
# package's cached value); the package's own ros_isolated_test_all() or macros still
# apply then.

# Whether this project() call is to be isolated: "yes", "off" (an ament_cmake package
# that opted out) or "" (not ours to touch). A function: nothing it reads stays behind,
# and it keeps the policies it is defined with (ours) whatever the project asked for (a
# vendored project may still say cmake_minimum_required(VERSION 2.8)). What it decides
# runs under the package's own policies, as if the package had asked for it: ament's
# functions keep the policies they are defined with too.
include("${CMAKE_CURRENT_LIST_DIR}/ros_isolated_test_package.cmake")
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
  _ros_isolated_test_manifest_is_ament_cmake(_ament_cmake "${_manifest}")
  if(NOT _ament_cmake)
    return()
  endif()
  if(DEFINED ROS_ISOLATED_TEST_ALL AND NOT ROS_ISOLATED_TEST_ALL)
    set(${var} "off" PARENT_SCOPE)
  else()
    set(${var} "yes" PARENT_SCOPE)
  endif()
endfunction()

# BUILD_TESTING OFF and no runner to be found: at the end of the package's directory,
# the tests it registered anyway, named as NOT isolated (${why}: what is missing).
function(_ros_isolated_test_project_include_unisolated why)
  set_property(GLOBAL PROPERTY _ROS_ISOLATED_TEST_UNISOLATED_WHY "${why}")
  set_property(GLOBAL PROPERTY _ROS_ISOLATED_TEST_UNISOLATED_PROJECT "${PROJECT_NAME}")
  if(NOT CMAKE_VERSION VERSION_LESS 3.19)
    cmake_language(DEFER DIRECTORY "${CMAKE_CURRENT_SOURCE_DIR}"
      CALL _ros_isolated_test_project_include_say_unisolated "${CMAKE_CURRENT_SOURCE_DIR}")
  endif()
endfunction()

function(_ros_isolated_test_project_include_say_unisolated root)
  _ros_isolated_test_tests_below(_tests _discovered "${root}")
  if(NOT _tests)
    return()
  endif()
  get_property(_why GLOBAL PROPERTY _ROS_ISOLATED_TEST_UNISOLATED_WHY)
  get_property(_project GLOBAL PROPERTY _ROS_ISOLATED_TEST_UNISOLATED_PROJECT)
  string(REPLACE ";" ", " _tests "${_tests}")
  message(STATUS "ros_isolated_test: NOT isolated, tests of ${_project} registered although "
    "BUILD_TESTING is OFF: ${_tests}; no runner was found: ${_why}")
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
    if(ros_isolated_test_FOUND)
      set_property(GLOBAL PROPERTY _ROS_ISOLATED_TEST_ALL_HOW
        "CMAKE_PROJECT_INCLUDE; -DROS_ISOLATED_TEST_ALL=OFF turns it off")
      ros_isolated_test_all()
    elseif(DEFINED BUILD_TESTING AND NOT BUILD_TESTING)
      # A build not meant to test needs no runner: only a test registered anyway is said.
      _ros_isolated_test_project_include_unisolated("${ros_isolated_test_NOT_FOUND_MESSAGE}")
    else()
      message(FATAL_ERROR "ros_isolated_test (CMAKE_PROJECT_INCLUDE): cannot isolate the "
        "tests of ${PROJECT_NAME}: ${ros_isolated_test_NOT_FOUND_MESSAGE} Or configure "
        "without it: -DROS_ISOLATED_TEST_ALL=OFF.")
    endif()
  endif()
  # Not found: an ament_cmake package without ament_cmake_test fails on its own
  # find_package(ament_cmake), with ament's message rather than ours.
endif()
unset(_ros_isolated_test_project_include)

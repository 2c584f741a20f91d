# ros_isolated_test_all([RERUNS n] [RESOURCES spec]): one line that puts every test of the
# package on our RUNNER; with RERUNS, each of them runs again up to n times when it fails
# (every attempt kept in its result file), unless its own ENV sets ROS_ISOLATED_TEST_RERUNS;
# with RESOURCES (e.g. cpu=2,mem=4G, or a CMake list "cpu=2;mem=4G"), each of them holds
# those machine resources with its domain ID (waiting until they are free), unless its own
# ENV sets ROS_ISOLATED_TEST_RESOURCES. A test with a RUNNER of its own gets neither.
#
# ament_add_gtest, ament_add_gmock, ament_add_pytest_test, add_launch_test and third-party
# macros all register their tests through ament_add_test, whose RUNNER defaults to ament's
# run_test.py. CMake lets a command be defined again and keeps the previous definition
# callable as _<name>, so redefining ament_add_test to add our RUNNER (when the call names
# none) reaches them all without editing any call.
#
# Limitations (CMake keeps ONE previous definition only):
# - It is global from the call on: every later ament_add_test in every directory of the
#   project is wrapped; tests added before the call are not.
# - Calling it again is harmless (nothing is redefined a second time).
# - If another package has already redefined ament_add_test (so _ament_add_test exists),
#   wrapping it again would make that definition call itself forever: this is refused
#   with an error; use the ros_isolated_add_* macros or RUNNER "${ros_isolated_test_RUNNER}"
#   instead.
# - If another package redefines ament_add_test AFTER the call, _ament_add_test becomes our
#   wrapper, which would then call itself forever: the wrapper notices being entered again
#   and stops with an error. Two wrappers of ament_add_test cannot be combined in either
#   order; use the ros_isolated_add_* macros instead of ros_isolated_test_all().
# - If ament_add_test.cmake is loaded again after the call (ament_cmake_test found anew in a
#   scope that did not see it found), the fresh definition replaces ours: tests added after
#   that run through run_test.py again.

macro(ros_isolated_test_all)
  if(NOT COMMAND ament_add_test)
    # A macro, so what find_package() sets stays in the caller's scope.
    find_package(ament_cmake_test REQUIRED)
  endif()
  _ros_isolated_test_all_options(${ARGN})
  _ros_isolated_test_wrap_ament_add_test()
endmacro()

# RERUNS and RESOURCES of ros_isolated_test_all(), checked and kept for the tests added
# from now on (a later call replaces only what it names).
function(_ros_isolated_test_all_options)
  # The parser of the ros_isolated_add_* macros: a RESOURCES list means the same here.
  _ros_isolated_test_parse(_unknown _rit_RERUNS _rit_RESOURCES _missing ${ARGN})
  if(_unknown)
    message(FATAL_ERROR "ros_isolated_test_all(): unknown argument(s) "
      "'${_unknown}'; it takes RERUNS <n> and RESOURCES <spec> only")
  endif()
  _ros_isolated_test_env(_checked "${_missing}" "${_rit_RERUNS}" "${_rit_RESOURCES}")
  foreach(_keyword RERUNS RESOURCES)
    if(NOT "${_rit_${_keyword}}" STREQUAL "")
      set_property(GLOBAL PROPERTY _ROS_ISOLATED_TEST_ALL_${_keyword} "${_rit_${_keyword}}")
    endif()
  endforeach()
endfunction()

# Defines the wrapper. A function, not a macro: a macro would substitute its own ${ARGN}
# into the body of the function defined here.
function(_ros_isolated_test_wrap_ament_add_test)
  get_property(_wrapped GLOBAL PROPERTY _ROS_ISOLATED_TEST_ALL)
  if(_wrapped)
    return()
  endif()
  if(COMMAND _ament_add_test)
    message(FATAL_ERROR "ros_isolated_test_all(): ament_add_test was already redefined by "
      "another CMake package, and CMake keeps only one earlier definition, so it cannot be "
      "wrapped again. Use the ros_isolated_add_* macros, or pass "
      "RUNNER \"\${ros_isolated_test_RUNNER}\" to ament_add_test, instead.")
  endif()
  set_property(GLOBAL PROPERTY _ROS_ISOLATED_TEST_ALL TRUE)

  function(ament_add_test testname)
    # _ament_add_test never calls ament_add_test again, so entering twice means it is this
    # very wrapper (see the limitations above): without the guard, CMake recurses until
    # its depth limit, with an error that names neither cause nor fix.
    get_property(_entered GLOBAL PROPERTY _ROS_ISOLATED_TEST_ALL_ENTERED)
    if(_entered)
      message(FATAL_ERROR "ros_isolated_test_all(): ament_add_test(${testname}) reached "
        "the wrapper of ros_isolated_test_all() twice, because another CMake package "
        "redefined ament_add_test after ros_isolated_test_all() was called (CMake keeps "
        "only one earlier definition, so that one now calls this wrapper, and the wrapper "
        "itself). Two wrappers of ament_add_test cannot be combined: instead of "
        "ros_isolated_test_all(), use the ros_isolated_add_* macros, or pass "
        "RUNNER \"\${ros_isolated_test_RUNNER}\" to ament_add_test; where ros-isolated-test's "
        "CMAKE_PROJECT_INCLUDE called it, configure this package with "
        "-DROS_ISOLATED_TEST_ALL=OFF.")
    endif()
    set_property(GLOBAL PROPERTY _ROS_ISOLATED_TEST_ALL_ENTERED TRUE)
    # The same keywords as ament_add_test itself, so exactly the words it would read as
    # RUNNER are read as RUNNER here.
    cmake_parse_arguments(_rit
      "GENERATE_RESULT_FOR_RETURN_CODE_ZERO;SKIP_TEST"
      "OUTPUT_FILE;RESULT_FILE;RUNNER;SKIP_RETURN_CODE;TIMEOUT;WORKING_DIRECTORY"
      "APPEND_ENV;APPEND_LIBRARY_DIRS;COMMAND;ENV"
      ${ARGN})
    # RERUNS and RESOURCES of ros_isolated_test_all() first: a variable the call's own ENV
    # sets comes later and wins (ament_add_test passes ENV on as --env, where the last
    # value wins).
    get_property(_reruns GLOBAL PROPERTY _ROS_ISOLATED_TEST_ALL_RERUNS)
    get_property(_resources GLOBAL PROPERTY _ROS_ISOLATED_TEST_ALL_RESOURCES)
    _ros_isolated_test_env(_default_env "" "${_reruns}" "${_resources}")
    if(_rit_RUNNER)
      # Another runner: RERUNS and RESOURCES are ours, not its.
      _ament_add_test("${testname}" ${ARGN})
    else()
      _ros_isolated_test_runner(_runner)
      # Last, so it also replaces an empty RUNNER, which ament_add_test reads as "default".
      _ament_add_test("${testname}" ${_default_env} ${ARGN} RUNNER "${_runner}")
    endif()
    set_property(GLOBAL PROPERTY _ROS_ISOLATED_TEST_ALL_ENTERED FALSE)
  endfunction()
endfunction()

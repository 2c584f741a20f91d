# ros_isolated_test_all([RERUNS n] [RESOURCES spec]): one line that puts every test of the
# package on our RUNNER (each with ctest's SKIP_RETURN_CODE 77 unless it has a skip code
# of its own: a test of another share of a split that reaches the RUNNER is shown as
# skipped; ctest does not even start one it was told about: ros_isolated_test_share.cmake);
# with RERUNS, each of them runs again up to n times when it fails
# (every attempt kept in its result file), unless its own ENV sets ROS_ISOLATED_TEST_RERUNS;
# with RESOURCES (e.g. cpu=2,mem=4G, or a CMake list "cpu=2;mem=4G"), each of them holds
# those machine resources with its domain ID (waiting until they are free), unless its own
# ENV sets ROS_ISOLATED_TEST_RESOURCES. A test that keeps a RUNNER of its own gets neither;
# one taken over from upstream's isolated runner (below) gets both.
#
# ament_add_gtest, ament_add_gmock, ament_add_pytest_test, add_launch_test and third-party
# macros all register their tests through ament_add_test, whose RUNNER defaults to ament's
# run_test.py. CMake lets a command be defined again and keeps the previous definition
# callable as _<name>, so redefining ament_add_test to add our RUNNER (when the call names
# none) reaches them all without editing any call.
#
# A test whose RUNNER is upstream's isolated runner (ament_cmake_ros's run_test_isolated.py,
# Jazzy's or Kilted's: ament_add_ros_isolated_*, or add_launch_test(... RUNNER
# "${ament_cmake_ros_DIR}/run_test_isolated.py")) asked for isolation: it runs through ours
# instead, which takes the same arguments (taken over), unless its own ENV or APPEND_ENV
# sets ROS_DOMAIN_ID (upstream's runner would run it there; ours would refuse it). Any other
# RUNNER is kept.
#
# At the end of the project's directory, one status line says how many tests of the
# package are isolated (and how many of them were taken over from upstream's runner), and
# one more names every test that is not, and why: a RUNNER of its own, or registered by a
# plain add_test() (no RUNNER, no result file contract: left as it is). Tests that ctest
# discovers only when it runs (gtest_discover_tests) are named as not isolated too. With
# CMake older than 3.19 (no deferred calls) the line is said at once, without the counts.
#
# Limitations (CMake keeps ONE previous definition only):
# - It is global from the call on: every later ament_add_test in every directory of the
#   project is wrapped; tests added before the call are not (the status line names them).
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
#   that run through run_test.py again (the status line names them).

include("${CMAKE_CURRENT_LIST_DIR}/ros_isolated_test_package.cmake")
# A split machine starts only its own share's tests: each test put on our RUNNER is listed.
include("${CMAKE_CURRENT_LIST_DIR}/ros_isolated_test_share.cmake")

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
    _ros_isolated_test_runner(_runner)
    _ros_isolated_test_runner_kind(_kind "${_rit_RUNNER}" "${_runner}" "${_rit_ENV}"
      "${_rit_APPEND_ENV}")
    if(_kind MATCHES "^(ours|upstream)$")
      get_property(_before DIRECTORY PROPERTY TESTS)
      # Last, so it also replaces an empty RUNNER, which ament_add_test reads as "default",
      # and upstream's (cmake_parse_arguments keeps the last value).
      _ament_add_test("${testname}" ${_default_env} ${ARGN} RUNNER "${_runner}")
      _ros_isolated_test_skip_codes("${_before}")
      _ros_isolated_test_share_register("${testname}" "${_rit_RESULT_FILE}")
    else()
      # Another runner: RERUNS and RESOURCES are ours, not its.
      _ament_add_test("${testname}" ${ARGN})
    endif()
    _ros_isolated_test_record("${testname}" "${_kind}" "${_rit_RUNNER}")
    set_property(GLOBAL PROPERTY _ROS_ISOLATED_TEST_ALL_ENTERED FALSE)
  endfunction()
  _ros_isolated_test_schedule_summary()
endfunction()

# Our own policies for what follows, whatever the package asked for (see
# ros_isolated_test_package.cmake).
cmake_policy(PUSH)
cmake_policy(VERSION 3.15)

# ${var}: how the wrapper treats a test whose RUNNER is ${runner} ("" for none), ours
# being ${ours}, its ENV ${env} and APPEND_ENV ${append_env}: "ours" (none, or ours),
# "upstream" (ament_cmake_ros's run_test_isolated.py: taken over), "upstream_domain_ENV" or
# "upstream_domain_APPEND_ENV" (upstream's, but that keyword sets ROS_DOMAIN_ID: kept, as
# upstream's runner would run it there and ours would refuse it) or "other" (kept).
function(_ros_isolated_test_runner_kind var runner ours env append_env)
  if(runner STREQUAL "")
    set(${var} "ours" PARENT_SCOPE)
    return()
  endif()
  get_filename_component(_runner "${runner}" REALPATH)
  get_filename_component(_ours "${ours}" REALPATH)
  if(_runner STREQUAL _ours)
    set(${var} "ours" PARENT_SCOPE)
    return()
  endif()
  _ros_isolated_test_upstream_runner(_upstream "${runner}")
  if(NOT _upstream)
    set(${var} "other" PARENT_SCOPE)
    return()
  endif()
  set(${var} "upstream" PARENT_SCOPE)
  foreach(_keyword IN ITEMS APPEND_ENV ENV)
    string(TOLOWER "${_keyword}" _list)
    foreach(_assignment IN LISTS ${_list})
      if(_assignment MATCHES "^ROS_DOMAIN_ID=")
        set(${var} "upstream_domain_${_keyword}" PARENT_SCOPE)
      endif()
    endforeach()
  endforeach()
endfunction()

# ${var}: TRUE when ${runner} is upstream's isolated runner, the run_test_isolated.py in
# the cmake folder of the package ament_cmake_ros (its package.xml names it; without one,
# the folder does), Jazzy's (domain_coordinator) or Kilted's (rmw_test_fixture). Judged
# by what the file is, as given and with links resolved (a --symlink-install links the
# installed file into the package's sources): its name and the package it comes from,
# wherever that is installed.
function(_ros_isolated_test_upstream_runner var runner)
  set(${var} FALSE PARENT_SCOPE)
  get_filename_component(_given "${runner}" ABSOLUTE)
  get_filename_component(_resolved "${runner}" REALPATH)
  foreach(_path IN ITEMS "${_given}" "${_resolved}")
    get_filename_component(_name "${_path}" NAME)
    get_filename_component(_folder "${_path}" DIRECTORY)
    get_filename_component(_folder_name "${_folder}" NAME)
    get_filename_component(_package "${_folder}" DIRECTORY)
    if(NOT _name STREQUAL "run_test_isolated.py" OR NOT _folder_name STREQUAL "cmake")
      continue()
    endif()
    if(EXISTS "${_package}/package.xml")
      _ros_isolated_test_manifest_name(_package_name "${_package}/package.xml")
    else()
      get_filename_component(_package_name "${_package}" NAME)
    endif()
    if(_package_name STREQUAL "ament_cmake_ros")
      set(${var} TRUE PARENT_SCOPE)
      return()
    endif()
  endforeach()
endfunction()

# Remembers what the wrapper did with test ${testname} (${kind} as
# _ros_isolated_test_runner_kind says), for the status line.
function(_ros_isolated_test_record testname kind runner)
  if(kind STREQUAL "ours")
    set_property(GLOBAL APPEND PROPERTY _ROS_ISOLATED_TEST_ALL_ISOLATED "${testname}")
  elseif(kind STREQUAL "upstream")
    set_property(GLOBAL APPEND PROPERTY _ROS_ISOLATED_TEST_ALL_ISOLATED "${testname}")
    set_property(GLOBAL APPEND PROPERTY _ROS_ISOLATED_TEST_ALL_TAKEN_OVER "${testname}")
  else()
    get_filename_component(_file "${runner}" NAME)
    if(kind MATCHES "^upstream_domain_(.*)$")
      set(_why "upstream's ${_file}, kept: its ${CMAKE_MATCH_1} sets ROS_DOMAIN_ID")
    else()
      set(_why "its own RUNNER ${_file}")
    endif()
    set_property(GLOBAL APPEND PROPERTY _ROS_ISOLATED_TEST_ALL_KEPT "${testname}")
    set_property(GLOBAL PROPERTY "_ROS_ISOLATED_TEST_ALL_KEPT_${testname}" "${_why}")
  endif()
endfunction()

# Says the status line at the end of the project's directory (with CMake 3.19 and newer),
# once all its tests are registered; at once, without counts, with an older CMake.
function(_ros_isolated_test_schedule_summary)
  get_property(_how GLOBAL PROPERTY _ROS_ISOLATED_TEST_ALL_HOW)
  if(NOT _how)
    set(_how "ros_isolated_test_all()")
  endif()
  _ros_isolated_test_runner(_runner)
  string(CONCAT _isolated "tests of ${PROJECT_NAME} are isolated, each on a ROS_DOMAIN_ID "
    "of its own, run by ${_runner} (${_how})")
  if(CMAKE_VERSION VERSION_LESS 3.19)
    message(STATUS "ros_isolated_test: ${_isolated}")
    return()
  endif()
  set_property(GLOBAL PROPERTY _ROS_ISOLATED_TEST_ALL_SAY "${_isolated}")
  set_property(GLOBAL PROPERTY _ROS_ISOLATED_TEST_ALL_PROJECT "${PROJECT_NAME}")
  set_property(GLOBAL PROPERTY _ROS_ISOLATED_TEST_ALL_ROOT "${PROJECT_SOURCE_DIR}")
  cmake_language(DEFER DIRECTORY "${PROJECT_SOURCE_DIR}" CALL _ros_isolated_test_summary)
endfunction()

# The status line: how many tests of the project are isolated (how many of them taken
# over from upstream's runner), then every test that is not, and why. Silent when
# BUILD_TESTING is OFF and no test was registered anyway.
function(_ros_isolated_test_summary)
  get_property(_root GLOBAL PROPERTY _ROS_ISOLATED_TEST_ALL_ROOT)
  get_property(_project GLOBAL PROPERTY _ROS_ISOLATED_TEST_ALL_PROJECT)
  get_property(_said GLOBAL PROPERTY _ROS_ISOLATED_TEST_ALL_SAY)
  get_property(_isolated GLOBAL PROPERTY _ROS_ISOLATED_TEST_ALL_ISOLATED)
  get_property(_taken_over GLOBAL PROPERTY _ROS_ISOLATED_TEST_ALL_TAKEN_OVER)
  get_property(_kept GLOBAL PROPERTY _ROS_ISOLATED_TEST_ALL_KEPT)
  _ros_isolated_test_tests_below(_tests _discovered "${_root}")
  # Our own TEST_INCLUDE_FILES script (a split's) discovers no test.
  _ros_isolated_test_share_foreign_includes(_discovered ${_discovered})
  set(_testing_off FALSE)
  if(DEFINED BUILD_TESTING AND NOT BUILD_TESTING)
    set(_testing_off TRUE)
    if(NOT _tests AND NOT _discovered)
      return()
    endif()
  endif()
  set(_count 0)
  set(_taken 0)
  set(_not "")
  set(_not_count 0)
  foreach(_test IN LISTS _tests)
    if(_test IN_LIST _isolated)
      math(EXPR _count "${_count} + 1")
      if(_test IN_LIST _taken_over)
        math(EXPR _taken "${_taken} + 1")
      endif()
      continue()
    endif()
    if(_test IN_LIST _kept)
      get_property(_why GLOBAL PROPERTY "_ROS_ISOLATED_TEST_ALL_KEPT_${_test}")
    else()
      set(_why "a plain add_test(), not ament_add_test(): no RUNNER to replace")
    endif()
    list(APPEND _not "${_test} (${_why})")
    math(EXPR _not_count "${_not_count} + 1")
  endforeach()
  _ros_isolated_test_plural(_counted ${_count} "test")
  set(_line "ros_isolated_test: ${_said}: ${_counted}")
  if(_taken GREATER 0)
    string(APPEND _line ", ${_taken} of them taken over from upstream's run_test_isolated.py")
  endif()
  if(_testing_off)
    string(APPEND _line " (registered although BUILD_TESTING is OFF)")
  endif()
  message(STATUS "${_line}")
  if(_not_count GREATER 0)
    _ros_isolated_test_plural(_counted ${_not_count} "test")
    string(REPLACE ";" ", " _not "${_not}")
    message(STATUS "ros_isolated_test: NOT isolated, ${_counted} of ${_project}: ${_not}")
  endif()
  if(_discovered)
    string(REPLACE ";" ", " _discovered "${_discovered}")
    message(STATUS "ros_isolated_test: tests of ${_project} that ctest discovers when it "
      "runs (TEST_INCLUDE_FILES, e.g. gtest_discover_tests, in ${_discovered}) are NOT "
      "isolated")
  endif()
endfunction()

# ${var}: "<count> <noun>", or its plural ("1 test", "2 tests").
function(_ros_isolated_test_plural var count noun)
  if(count EQUAL 1)
    set(${var} "1 ${noun}" PARENT_SCOPE)
  else()
    set(${var} "${count} ${noun}s" PARENT_SCOPE)
  endif()
endfunction()

cmake_policy(POP)

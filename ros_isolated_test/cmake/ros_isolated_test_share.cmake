# A split machine starts only its own share's tests (ROS_ISOLATED_TEST_SHARD=I/N).
#
# Configuring: every test the zero-edit include, ros_isolated_test_all() or a
# ros_isolated_add_* macro puts on our RUNNER is listed, with the result file its RUNNER
# is given, in <package build>/ros_isolated_test_share/tests.txt, and its directory gets a
# TEST_INCLUDE_FILES script (ros_isolated_test_share/include.cmake) that ctest reads when it
# loads the directory, before the directory's add_test() calls.
#
# Testing: with ROS_ISOLATED_TEST_SHARD blank or unset the script does nothing (no
# process). Set, it runs ros_isolated_test.ament.shard once per package (one
# process, not one per test), which places each listed test by the identity and plan its
# RUNNER would use, removes the stale result files of the other shares' tests, leaves the
# machine's record and prints those tests; each is marked DISABLED as ctest's add_test()
# registers it, only when its command names that package and result file (what the RUNNER
# is told). ctest lists them "Not Run (Disabled)"; no RUNNER starts for them. A bad share
# or durations file disables nothing: every RUNNER then fails with the one-line error, as
# ever. With CMake older than 3.18 (no cmake_language(EVAL)) nothing is disabled either:
# each RUNNER decides for its test and exits 77 (skipped) for another share's.

if(COMMAND _ros_isolated_test_share_apply)
  return()
endif()

set(_ROS_ISOLATED_TEST_SHARE_SCRIPT "${CMAKE_CURRENT_LIST_FILE}")

# Our own policies for what follows, whatever the package asked for (see
# ros_isolated_test_package.cmake).
cmake_policy(PUSH)
cmake_policy(VERSION 3.15)

# Configuring: lists test ${testname} of ${PROJECT_NAME}, whose RUNNER writes ${result}
# (empty: ament_add_test's default for it), and gives its directory the include.
function(_ros_isolated_test_share_register testname result)
  if(CMAKE_VERSION VERSION_LESS 3.18)
    return()
  endif()
  if("${result}" STREQUAL "")
    set(result "${AMENT_TEST_RESULTS_DIR}/${PROJECT_NAME}/${testname}.xml")
  endif()
  if(NOT IS_ABSOLUTE "${result}")
    get_filename_component(result "${result}" ABSOLUTE BASE_DIR "${CMAKE_CURRENT_BINARY_DIR}")
  endif()
  if("${testname}${result}" MATCHES "[\t\n;]")
    return()  # not one line of the list: its RUNNER decides for it
  endif()
  _ros_isolated_test_share_python(_python)
  if(NOT _python)
    return()
  endif()
  set(_folder "${PROJECT_BINARY_DIR}/ros_isolated_test_share")
  set(_list "${_folder}/tests.txt")
  set(_include "${_folder}/include.cmake")
  get_property(_started GLOBAL PROPERTY _ROS_ISOLATED_TEST_SHARE_LISTS)
  list(FIND _started "${_list}" _known)
  if(_known EQUAL -1)
    # First test of this package in this configure run: the list starts afresh.
    set_property(GLOBAL APPEND PROPERTY _ROS_ISOLATED_TEST_SHARE_LISTS "${_list}")
    file(WRITE "${_list}" "")
    file(WRITE "${_include}"
      "include(\"${_ROS_ISOLATED_TEST_SHARE_SCRIPT}\")\n"
      "_ros_isolated_test_share_apply([==[\n${PROJECT_NAME}]==] [==[\n${_list}]==] "
      "[==[\n${_python}]==])\n")
  endif()
  file(APPEND "${_list}" "${testname}\t${result}\n")
  set_property(GLOBAL PROPERTY "_ROS_ISOLATED_TEST_SHARE_LISTED_${_list}_${testname}" TRUE)
  get_property(_includes DIRECTORY PROPERTY TEST_INCLUDE_FILES)
  list(FIND _includes "${_include}" _known)
  if(_known EQUAL -1)
    set_property(DIRECTORY APPEND PROPERTY TEST_INCLUDE_FILES "${_include}")
  endif()
endfunction()

# Configuring, after a ros_isolated_add_* macro called ${command} (its arguments in ARGN):
# lists each test of this directory not in ${before} that ros_isolated_test_all()'s
# wrapper did not list already, with the result file ${command} gives its RUNNER by default
# (or the RESULT_FILE the call names). A guess is safe: ctest disables a test only when
# its command names that very file.
function(_ros_isolated_test_share_register_new before command)
  cmake_parse_arguments(_rit "" "RESULT_FILE" "" ${ARGN})
  set(_suffix ".xml")
  if(command MATCHES "^ament_add_g(test|mock)$")
    set(_suffix ".gtest.xml")
  elseif(command MATCHES "^(ament_add_pytest_test|add_launch_test)$")
    set(_suffix ".xunit.xml")
  endif()
  set(_list "${PROJECT_BINARY_DIR}/ros_isolated_test_share/tests.txt")
  get_property(_tests DIRECTORY PROPERTY TESTS)
  foreach(_test IN LISTS _tests)
    list(FIND before "${_test}" _known)
    get_property(_listed GLOBAL PROPERTY "_ROS_ISOLATED_TEST_SHARE_LISTED_${_list}_${_test}")
    if(NOT _known EQUAL -1 OR _listed)
      continue()
    endif()
    set(_result "${_rit_RESULT_FILE}")
    if("${_result}" STREQUAL "")
      set(_result "${AMENT_TEST_RESULTS_DIR}/${PROJECT_NAME}/${_test}${_suffix}")
    endif()
    _ros_isolated_test_share_register("${_test}" "${_result}")
  endforeach()
endfunction()

# ${var}: those of the directories in ARGN whose TEST_INCLUDE_FILES hold a script other
# than ours (gtest_discover_tests' and the like: tests ctest discovers when it runs).
function(_ros_isolated_test_share_foreign_includes var)
  set(_foreign "")
  foreach(_directory IN LISTS ARGN)
    get_property(_includes DIRECTORY "${_directory}" PROPERTY TEST_INCLUDE_FILES)
    foreach(_include IN LISTS _includes)
      if(NOT _include MATCHES "/ros_isolated_test_share/include\\.cmake$")
        list(APPEND _foreign "${_directory}")
        break()
      endif()
    endforeach()
  endforeach()
  set(${var} "${_foreign}" PARENT_SCOPE)
endfunction()

# ${var}: the Python of the ros-isolated-test command (its shebang), which imports this
# very installation; else the one ament runs the RUNNER with; else empty.
function(_ros_isolated_test_share_python var)
  get_property(_python GLOBAL PROPERTY _ROS_ISOLATED_TEST_SHARE_PYTHON SET)
  if(_python)
    get_property(_python GLOBAL PROPERTY _ROS_ISOLATED_TEST_SHARE_PYTHON)
    set(${var} "${_python}" PARENT_SCOPE)
    return()
  endif()
  set(_python "")
  if(ROS_ISOLATED_TEST_EXECUTABLE AND EXISTS "${ROS_ISOLATED_TEST_EXECUTABLE}")
    file(STRINGS "${ROS_ISOLATED_TEST_EXECUTABLE}" _first LIMIT_COUNT 1)
    if(_first MATCHES "^#![ ]*([^ ]+)$")
      set(_python "${CMAKE_MATCH_1}")
      if(_python MATCHES "/(env|sh|bash)$")
        set(_python "")  # "#!/usr/bin/env python3", pip's "#!/bin/sh" form: not read here
      endif()
    endif()
  endif()
  if(NOT _python AND TARGET Python3::Interpreter)
    get_target_property(_python Python3::Interpreter LOCATION)
  endif()
  if(NOT _python AND Python3_EXECUTABLE)
    set(_python "${Python3_EXECUTABLE}")
  endif()
  if(NOT _python OR NOT EXISTS "${_python}")
    set(_python "")
  endif()
  set_property(GLOBAL PROPERTY _ROS_ISOLATED_TEST_SHARE_PYTHON "${_python}")
  set(${var} "${_python}" PARENT_SCOPE)
endfunction()

# Testing (ctest reads this through a directory's include.cmake): the package's plan,
# once, and add_test() made to disable the other shares' tests as it registers them.
function(_ros_isolated_test_share_apply package list python)
  if("$ENV{ROS_ISOLATED_TEST_SHARD}" MATCHES "^[ \t\r\n]*$" OR CMAKE_VERSION VERSION_LESS 3.18)
    return()
  endif()
  get_property(_done GLOBAL PROPERTY "_ROS_ISOLATED_TEST_SHARE_DONE_${list}")
  if(NOT _done)
    set_property(GLOBAL PROPERTY "_ROS_ISOLATED_TEST_SHARE_DONE_${list}" TRUE)
    execute_process(
      COMMAND "${python}" -m ros_isolated_test.ament.shard "${package}" "${list}"
      OUTPUT_VARIABLE _out
      ERROR_VARIABLE _error
      RESULT_VARIABLE _rc)
    if(NOT _rc STREQUAL "0")
      string(STRIP "${_error}" _error)
      message("${_error}\nros-isolated-test: no test of ${package} was left out by the "
        "split (${python} exited ${_rc}): each RUNNER decides for its own test")
      return()
    endif()
    string(REPLACE "\n" ";" _lines "${_out}")
    foreach(_line IN LISTS _lines)
      if(_line MATCHES "^([^\t]+)\t(.+)$")
        set_property(GLOBAL PROPERTY "_ROS_ISOLATED_TEST_SHARE_OFF_${CMAKE_MATCH_1}"
          "${package}\t${CMAKE_MATCH_2}")
      endif()
    endforeach()
  endif()
  get_property(_defined GLOBAL PROPERTY _ROS_ISOLATED_TEST_SHARE_ADD_TEST)
  if(_defined)
    return()
  endif()
  set_property(GLOBAL PROPERTY _ROS_ISOLATED_TEST_SHARE_ADD_TEST TRUE)
  # ctest's own add_test(), called again with exactly the same words (each a bracket
  # argument: a ';' or an empty word stays what it was), then DISABLED for a test of
  # another share whose command says so: --package-name <package> and its result file.
  function(add_test _rit_name)
    set(_rit_code "_add_test(")
    math(EXPR _rit_last "${ARGC} - 1")
    foreach(_rit_at RANGE 0 ${_rit_last})
      set(_rit_word "${ARGV${_rit_at}}")
      set(_rit_eq "==")
      while(_rit_word MATCHES "]${_rit_eq}]")
        string(APPEND _rit_eq "=")
      endwhile()
      string(APPEND _rit_code " [${_rit_eq}[\n${_rit_word}]${_rit_eq}]")
    endforeach()
    cmake_language(EVAL CODE "${_rit_code})")
    get_property(_rit_off GLOBAL PROPERTY "_ROS_ISOLATED_TEST_SHARE_OFF_${_rit_name}")
    if(NOT _rit_off MATCHES "^([^\t]*)\t(.*)$")
      return()
    endif()
    set(_rit_package "${CMAKE_MATCH_1}")
    set(_rit_result "${CMAKE_MATCH_2}")
    list(FIND ARGN "--package-name" _rit_at)
    if(_rit_at EQUAL -1)
      return()
    endif()
    math(EXPR _rit_at "${_rit_at} + 1")
    list(LENGTH ARGN _rit_count)
    if(NOT _rit_at LESS _rit_count)
      return()
    endif()
    list(GET ARGN ${_rit_at} _rit_named)
    list(FIND ARGN "${_rit_result}" _rit_found)
    if(_rit_named STREQUAL _rit_package AND NOT _rit_found EQUAL -1)
      set_tests_properties("${_rit_name}" PROPERTIES DISABLED TRUE)
    endif()
  endfunction()
endfunction()

cmake_policy(POP)

# ros_isolated_add_*: the ament and launch_testing test macros with ros-isolated-test as
# RUNNER. Each test they register gets ctest's SKIP_RETURN_CODE 77 unless it has a skip
# code of its own: in a split over machines (ROS_ISOLATED_TEST_SHARD=I/N) the RUNNER exits
# 77 for a test of another share, which ctest then shows as skipped. Each is also listed
# for ros_isolated_test_share.cmake, so that ctest does not start the other shares' tests.
# Each takes exactly the arguments of the macro it wraps, and two more:
# RERUNS <n> runs a failed test again up to n times, every attempt kept in its result file
# (ENV ROS_ISOLATED_TEST_RERUNS=<n>, which the RUNNER reads);
# RESOURCES <spec> (e.g. RESOURCES cpu=2,mem=4G,gpu=1, or a CMake list "cpu=2;gpu=1")
# makes the test hold those machine resources with its domain ID, waiting until every
# other runner on the machine has left enough of them free
# (ENV ROS_ISOLATED_TEST_RESOURCES=<spec>, which the RUNNER checks).
# Our RUNNER comes first, so a RUNNER the call names itself comes later and wins
# (cmake_parse_arguments keeps the last value).

include("${CMAKE_CURRENT_LIST_DIR}/ros_isolated_test_share.cmake")

# The RUNNER script's path, wherever find_package(ros_isolated_test) was called.
function(_ros_isolated_test_runner var)
  get_property(_runner GLOBAL PROPERTY ROS_ISOLATED_TEST_RUNNER)
  if(NOT _runner)
    message(FATAL_ERROR "ros_isolated_test: no RUNNER script is known; call "
      "find_package(ros_isolated_test REQUIRED) before the ros_isolated_* macros")
  endif()
  set(${var} "${_runner}" PARENT_SCOPE)
endfunction()

# What every ros_isolated_add_* macro passes to the macro it wraps after the arguments
# that one takes by position, in ${var}: RUNNER <our RUNNER>, the call's other arguments,
# and its RERUNS <n> and RESOURCES <spec> turned into
# ENV ROS_ISOLATED_TEST_RERUNS=<n> ROS_ISOLATED_TEST_RESOURCES=<spec>.
# Last: ament_add_test passes ENV on as --env, where the last value of a variable wins.
function(_ros_isolated_test_arguments var)
  _ros_isolated_test_runner(_runner)
  _ros_isolated_test_parse(_arguments _reruns _resources _missing ${ARGN})
  _ros_isolated_test_env(_env "${_missing}" "${_reruns}" "${_resources}")
  set(${var} RUNNER "${_runner}" ${_arguments} ${_env} PARENT_SCOPE)
endfunction()

# RERUNS <n> and RESOURCES <spec> taken out of ARGN: their values in ${reruns_var} and
# ${resources_var}, the other words (in order) in ${rest_var}, and in ${missing_var} the
# keywords given without a value. As cmake_parse_arguments would, a later value wins,
# but RESOURCES also takes every name=amount word right after its value: a macro's ARGN
# splits a CMake list (RESOURCES "gpu=1;cpu=1") into words, which would otherwise hold
# only gpu=1 and append cpu=1 to the test's COMMAND. They are one request, joined by
# commas, the separator the RUNNER reads. Any name counts (GPU=1 too): the RUNNER says
# what is wrong with it, where in the COMMAND it would pass unnoticed.
function(_ros_isolated_test_parse rest_var reruns_var resources_var missing_var)
  set(_rest "")
  set(_value_RERUNS "")
  set(_value_RESOURCES "")
  set(_missing "")
  set(_expect "")
  set(_more FALSE)
  foreach(_word IN LISTS ARGN)
    if(_more AND _word MATCHES "^ *[A-Za-z_][A-Za-z0-9_-]* *=")
      string(APPEND _value_RESOURCES ",${_word}")
      continue()
    endif()
    set(_more FALSE)
    if(_word STREQUAL "RERUNS" OR _word STREQUAL "RESOURCES")
      if(_expect)
        list(APPEND _missing ${_expect})
      endif()
      set(_expect "${_word}")
      set(_value_${_word} "")
    elseif(_expect)
      set(_value_${_expect} "${_word}")
      list(REMOVE_ITEM _missing ${_expect})
      if(_expect STREQUAL "RESOURCES")
        set(_more TRUE)
      endif()
      set(_expect "")
    else()
      list(APPEND _rest "${_word}")
    endif()
  endforeach()
  if(_expect)
    list(APPEND _missing ${_expect})
  endif()
  set(${rest_var} "${_rest}" PARENT_SCOPE)
  set(${reruns_var} "${_value_RERUNS}" PARENT_SCOPE)
  set(${resources_var} "${_value_RESOURCES}" PARENT_SCOPE)
  set(${missing_var} "${_missing}" PARENT_SCOPE)
endfunction()

# ENV ROS_ISOLATED_TEST_RERUNS=<reruns> ROS_ISOLATED_TEST_RESOURCES=<resources> in ${var},
# each checked, for those given: a non-empty value, or an empty one whose keyword is in
# ${missing} (cmake_parse_arguments' KEYWORDS_MISSING_VALUES: "RERUNS" with no value).
function(_ros_isolated_test_env var missing reruns resources)
  set(_env "")
  # list(FIND), not IN_LIST: a package whose cmake_minimum_required is below 3.3 runs
  # these functions under its own policies (the zero-edit include), without CMP0057.
  list(FIND missing "RERUNS" _reruns_missing)
  list(FIND missing "RESOURCES" _resources_missing)
  if(NOT reruns STREQUAL "" OR NOT _reruns_missing EQUAL -1)
    _ros_isolated_test_check_reruns("${reruns}")
    list(APPEND _env "ROS_ISOLATED_TEST_RERUNS=${reruns}")
  endif()
  if(NOT resources STREQUAL "" OR NOT _resources_missing EQUAL -1)
    _ros_isolated_test_check_resources("${resources}")
    list(APPEND _env "ROS_ISOLATED_TEST_RESOURCES=${resources}")
  endif()
  if(_env)
    set(_env ENV ${_env})
  endif()
  set(${var} "${_env}" PARENT_SCOPE)
endfunction()

# Stops configuring when RERUNS is no whole number: the test would fail at every run.
function(_ros_isolated_test_check_reruns value)
  if(NOT value MATCHES "^[0-9]+$")
    message(FATAL_ERROR "ros_isolated_test: RERUNS '${value}' is not a number of reruns; "
      "pass a whole number, 0 or more (e.g. RERUNS 2)")
  endif()
endfunction()

# Stops configuring when RESOURCES is clearly no request (empty, no name=amount): the test
# would fail at every run. The RUNNER checks the rest (names, amounts, the capacity).
function(_ros_isolated_test_check_resources value)
  if(NOT value MATCHES "=")
    message(FATAL_ERROR "ros_isolated_test: RESOURCES '${value}' is not a request of "
      "resources; pass name=amount pairs joined by commas (e.g. RESOURCES cpu=2,mem=4G,gpu=1)")
  endif()
endfunction()

# Gives each test of this directory not in ${before} (the directory's TESTS before a test
# was added) ctest's SKIP_RETURN_CODE 77, unless it has a skip code already (ament's
# SKIP_RETURN_CODE, or 0 for SKIP_TEST). The RUNNER exits 77 for a test of another share
# of a split (ROS_ISOLATED_TEST_SHARD), which ctest then shows as skipped, never failed
# or passed; a test it ran that exits 77 fails (exit 1), so 77 is never the test's own.
function(_ros_isolated_test_skip_codes before)
  get_property(_tests DIRECTORY PROPERTY TESTS)
  foreach(_test IN LISTS _tests)
    list(FIND before "${_test}" _known)
    if(NOT _known EQUAL -1)
      continue()
    endif()
    get_test_property("${_test}" SKIP_RETURN_CODE _code)
    if("${_code}" STREQUAL "NOTFOUND")
      set_tests_properties("${_test}" PROPERTIES SKIP_RETURN_CODE 77)
    endif()
  endforeach()
endfunction()

# Macros, not functions: a macro runs in the caller's scope, so what find_package() sets
# when a macro finds ament_cmake_gtest, ament_cmake_pytest, ... outlives the call, and the
# next call neither finds the package again nor loads its files a second time. Their own
# variables carry the _ros_isolated_test prefix, as they land in the caller's scope too.

# The one wrapper behind every ros_isolated_add_* macro: finds <package> unless <command>
# is known already, then calls <command> with <first> (and for ament_add_pytest_test the
# path after it), our RUNNER, and the call's other arguments, which the macro left in
# _ros_isolated_test_argn: a macro handing its ARGN to another macro would have CMake
# read the escapes in it twice. CMake 3.15 cannot call a command named by a variable
# (cmake_language(CALL) is 3.18), hence the one call per command below.
macro(_ros_isolated_test_add _ros_isolated_test_command _ros_isolated_test_package
    _ros_isolated_test_first)
  if(NOT COMMAND ${_ros_isolated_test_command})
    find_package(${_ros_isolated_test_package} REQUIRED)
  endif()
  _ros_isolated_test_arguments(_ros_isolated_test_arguments ${_ros_isolated_test_argn})
  get_property(_ros_isolated_test_before DIRECTORY PROPERTY TESTS)
  set(_ros_isolated_test_kind ${_ros_isolated_test_command})
  if(_ros_isolated_test_kind MATCHES "^ament_add_gtest$")
    ament_add_gtest("${_ros_isolated_test_first}" ${_ros_isolated_test_arguments})
  elseif(_ros_isolated_test_kind MATCHES "^ament_add_gmock$")
    ament_add_gmock("${_ros_isolated_test_first}" ${_ros_isolated_test_arguments})
  elseif(_ros_isolated_test_kind MATCHES "^ament_add_pytest_test$")
    ament_add_pytest_test("${_ros_isolated_test_first}" "${ARGN}"
      ${_ros_isolated_test_arguments})
  elseif(_ros_isolated_test_kind MATCHES "^add_launch_test$")
    # add_launch_test passes arguments it does not know (RUNNER) on to ament_add_test.
    add_launch_test("${_ros_isolated_test_first}" ${_ros_isolated_test_arguments})
  else()
    ament_add_test("${_ros_isolated_test_first}" ${_ros_isolated_test_arguments})
  endif()
  _ros_isolated_test_skip_codes("${_ros_isolated_test_before}")
  # Listed for a split (ros_isolated_test_share.cmake), unless ros_isolated_test_all()'s
  # wrapper of ament_add_test, which sees the result file given, listed it already.
  _ros_isolated_test_share_register_new("${_ros_isolated_test_before}"
    ${_ros_isolated_test_command} ${_ros_isolated_test_arguments})
endmacro()

# ros_isolated_add_test(testname COMMAND ... [RERUNS n] [RESOURCES spec]
#                       [any ament_add_test argument])
macro(ros_isolated_add_test _ros_isolated_test_name)
  set(_ros_isolated_test_argn ${ARGN})
  _ros_isolated_test_add(ament_add_test ament_cmake_test "${_ros_isolated_test_name}")
endmacro()

# ros_isolated_add_gtest(target source... [RERUNS n] [RESOURCES spec]
#                        [any ament_add_gtest argument])
macro(ros_isolated_add_gtest _ros_isolated_test_target)
  set(_ros_isolated_test_argn ${ARGN})
  _ros_isolated_test_add(ament_add_gtest ament_cmake_gtest "${_ros_isolated_test_target}")
endmacro()

# ros_isolated_add_gmock(target source... [RERUNS n] [RESOURCES spec]
#                        [any ament_add_gmock argument])
macro(ros_isolated_add_gmock _ros_isolated_test_target)
  set(_ros_isolated_test_argn ${ARGN})
  _ros_isolated_test_add(ament_add_gmock ament_cmake_gmock "${_ros_isolated_test_target}")
endmacro()

# ros_isolated_add_pytest_test(testname path [RERUNS n] [RESOURCES spec]
#                              [any ament_add_pytest_test argument])
macro(ros_isolated_add_pytest_test _ros_isolated_test_name _ros_isolated_test_path)
  set(_ros_isolated_test_argn ${ARGN})
  _ros_isolated_test_add(ament_add_pytest_test ament_cmake_pytest
    "${_ros_isolated_test_name}" "${_ros_isolated_test_path}")
endmacro()

# ros_isolated_add_launch_test(file [RERUNS n] [RESOURCES spec] [any add_launch_test argument])
macro(ros_isolated_add_launch_test _ros_isolated_test_file)
  set(_ros_isolated_test_argn ${ARGN})
  _ros_isolated_test_add(add_launch_test launch_testing_ament_cmake "${_ros_isolated_test_file}")
endmacro()

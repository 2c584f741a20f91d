# What a package is, read for the zero-edit include and ros_isolated_test_all(): its
# manifest (package.xml: its name, whether it is an ament_cmake package) and the tests it
# registered. Functions only; included by ros_isolated_test_all.cmake and the include.
#
# The manifest is read as markup, not searched as text: a comment, a CDATA section or a
# processing instruction is no element, so a <build_type> inside a comment says nothing.
# What counts is a <build_type> in an <export> element, whose `condition` (REP 149), when
# it has one of the form `$VARIABLE == value` (or !=) and the variable is set, is
# evaluated as colcon evaluates it; any other condition, or one on an unset variable, is
# taken to hold (a package declaring catkin for ROS 1 and ament_cmake for ROS 2 is an
# ament_cmake package wherever ROS_VERSION is not set).

include_guard(GLOBAL)

# Our own policies, whatever the package asked for: these functions keep the policies
# they are defined with (a vendored project may still say cmake_minimum_required(2.8)).
cmake_policy(PUSH)
cmake_policy(VERSION 3.15)

# ${var}: the manifest at ${path} with every comment and processing instruction blanked
# out and every CDATA section turned into plain text (its < and > escaped), so that what
# looks like an element is one.
function(_ros_isolated_test_manifest_markup var path)
  file(READ "${path}" _text)
  set(_markup "")
  while(TRUE)
    # Whichever comes first: inside one, the others' openings are plain text.
    string(FIND "${_text}" "<!--" _at_comment)
    string(FIND "${_text}" "<![CDATA[" _at_cdata)
    string(FIND "${_text}" "<?" _at_instruction)
    set(_at -1)
    foreach(_kind comment cdata instruction)
      if(NOT _at_${_kind} EQUAL -1 AND (_at EQUAL -1 OR _at_${_kind} LESS _at))
        set(_at ${_at_${_kind}})
        set(_first ${_kind})
      endif()
    endforeach()
    if(_at EQUAL -1)
      string(APPEND _markup "${_text}")
      break()
    endif()
    if(_first STREQUAL "comment")
      set(_open 4)
      set(_close "-->")
    elseif(_first STREQUAL "cdata")
      set(_open 9)
      set(_close "]]>")
    else()
      set(_open 2)
      set(_close "?>")
    endif()
    string(SUBSTRING "${_text}" 0 ${_at} _before)
    string(APPEND _markup "${_before} ")
    math(EXPR _inside "${_at} + ${_open}")
    string(SUBSTRING "${_text}" ${_inside} -1 _text)
    string(FIND "${_text}" "${_close}" _end)
    if(_end EQUAL -1)
      break()  # never closed: the rest is no markup (and no well-formed manifest)
    endif()
    if(_first STREQUAL "cdata")
      string(SUBSTRING "${_text}" 0 ${_end} _data)
      string(REPLACE "<" "&lt;" _data "${_data}")
      string(REPLACE ">" "&gt;" _data "${_data}")
      string(APPEND _markup "${_data}")
    endif()
    string(LENGTH "${_close}" _length)
    math(EXPR _after "${_end} + ${_length}")
    string(SUBSTRING "${_text}" ${_after} -1 _text)
  endwhile()
  set(${var} "${_markup}" PARENT_SCOPE)
endfunction()

# The first <${element}> in ${markup}: ${found_var} TRUE when there is one, its text
# (blanks at its ends removed) in ${var}, its attributes in ${attributes_var} and the
# markup after it in ${rest_var}. The element is matched by its name, with or without
# attributes; an empty one (<x/>) is passed over, as it has no text.
function(_ros_isolated_test_manifest_element found_var var attributes_var rest_var element
    markup)
  set(${found_var} FALSE PARENT_SCOPE)
  set(${var} "" PARENT_SCOPE)
  set(${attributes_var} "" PARENT_SCOPE)
  set(${rest_var} "" PARENT_SCOPE)
  set(_text "${markup}")
  while(TRUE)
    string(REGEX MATCH "<${element}([ \t\r\n/][^>]*)?>" _tag "${_text}")
    if(_tag STREQUAL "")
      return()
    endif()
    set(_attributes "${CMAKE_MATCH_1}")
    string(FIND "${_text}" "${_tag}" _at)
    string(LENGTH "${_tag}" _length)
    math(EXPR _inside "${_at} + ${_length}")
    string(SUBSTRING "${_text}" ${_inside} -1 _text)
    if(NOT _tag MATCHES "/>$")
      break()
    endif()
  endwhile()
  string(REGEX MATCH "</${element}[ \t\r\n]*>" _end_tag "${_text}")
  if(_end_tag STREQUAL "")
    return()  # never closed
  endif()
  string(FIND "${_text}" "${_end_tag}" _end)
  string(SUBSTRING "${_text}" 0 ${_end} _content)
  string(STRIP "${_content}" _content)
  string(LENGTH "${_end_tag}" _length)
  math(EXPR _after "${_end} + ${_length}")
  string(SUBSTRING "${_text}" ${_after} -1 _rest)
  set(${found_var} TRUE PARENT_SCOPE)
  set(${var} "${_content}" PARENT_SCOPE)
  set(${attributes_var} "${_attributes}" PARENT_SCOPE)
  set(${rest_var} "${_rest}" PARENT_SCOPE)
endfunction()

# ${var}: the package's name (its <name>), or "" when ${path} names none.
function(_ros_isolated_test_manifest_name var path)
  _ros_isolated_test_manifest_markup(_markup "${path}")
  _ros_isolated_test_manifest_element(_found _name _attributes _rest "name" "${_markup}")
  set(${var} "${_name}" PARENT_SCOPE)
endfunction()

# ${var}: FALSE when ${condition} (a REP 149 condition attribute) is known not to hold
# here, else TRUE.
function(_ros_isolated_test_manifest_condition var condition)
  set(${var} TRUE PARENT_SCOPE)
  set(_word "[$]?[A-Za-z0-9_.-]+")
  set(_blank "[ \t\r\n]*")
  if(NOT condition MATCHES "^${_blank}(${_word})${_blank}(==|!=)${_blank}(${_word})${_blank}$")
    return()  # and/or, parentheses, <, >: not evaluated here
  endif()
  set(_operator "${CMAKE_MATCH_2}")
  set(_left "${CMAKE_MATCH_1}")
  set(_right "${CMAKE_MATCH_3}")
  foreach(_side _left _right)
    if(${_side} MATCHES "^[$](.*)$")
      if(NOT DEFINED ENV{${CMAKE_MATCH_1}})
        return()  # unknown here
      endif()
      set(${_side} "$ENV{${CMAKE_MATCH_1}}")
    endif()
  endforeach()
  if(_left STREQUAL _right)
    set(_equal TRUE)
  else()
    set(_equal FALSE)
  endif()
  if(_operator STREQUAL "!=")
    if(_equal)
      set(_equal FALSE)
    else()
      set(_equal TRUE)
    endif()
  endif()
  set(${var} ${_equal} PARENT_SCOPE)
endfunction()

# ${var}: TRUE when the manifest at ${path} exports <build_type>ament_cmake</build_type>
# (outside comments, with no condition known to be false), else FALSE.
function(_ros_isolated_test_manifest_is_ament_cmake var path)
  set(${var} FALSE PARENT_SCOPE)
  _ros_isolated_test_manifest_markup(_markup "${path}")
  while(TRUE)
    _ros_isolated_test_manifest_element(_found _export _attributes _markup "export"
      "${_markup}")
    if(NOT _found)
      break()
    endif()
    while(TRUE)
      _ros_isolated_test_manifest_element(_found _type _attributes _export "build_type"
        "${_export}")
      if(NOT _found)
        break()
      endif()
      set(_holds TRUE)
      if(_attributes MATCHES "(^|[ \t\r\n])condition[ \t\r\n]*=[ \t\r\n]*(\"([^\"]*)\"|'([^']*)')")
        _ros_isolated_test_manifest_condition(_holds "${CMAKE_MATCH_3}${CMAKE_MATCH_4}")
      endif()
      if(_type STREQUAL "ament_cmake" AND _holds)
        set(${var} TRUE PARENT_SCOPE)
        return()
      endif()
    endwhile()
  endwhile()
endfunction()

# ${tests_var}: every test registered in ${directory} and the directories below it; in
# ${discovered_var} the directories below that also hand ctest files listing more tests
# when it runs (TEST_INCLUDE_FILES: gtest_discover_tests), tests this cannot see.
function(_ros_isolated_test_tests_below tests_var discovered_var directory)
  get_property(_tests DIRECTORY "${directory}" PROPERTY TESTS)
  get_property(_includes DIRECTORY "${directory}" PROPERTY TEST_INCLUDE_FILES)
  set(_discovered "")
  if(_includes)
    set(_discovered "${directory}")
  endif()
  get_property(_below DIRECTORY "${directory}" PROPERTY SUBDIRECTORIES)
  foreach(_directory IN LISTS _below)
    _ros_isolated_test_tests_below(_more _more_discovered "${_directory}")
    list(APPEND _tests ${_more})
    list(APPEND _discovered ${_more_discovered})
  endforeach()
  set(${tests_var} "${_tests}" PARENT_SCOPE)
  set(${discovered_var} "${_discovered}" PARENT_SCOPE)
endfunction()

cmake_policy(POP)

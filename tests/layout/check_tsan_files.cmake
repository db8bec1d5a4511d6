# The TSan build compiles only KINEMA_THREAD_TEST_FILES of kinema_tests (tests/CMakeLists.txt;
# the CLI tests not at all: it builds no program): a test the tsan preset selects by name, put
# in another file of kinema_tests, would silently not run there. Fails naming each such test
# and its file.
#   cmake -DSOURCE_DIR=<repo> "-DOTHER_FILES=<file>,<file>,..." -P check_tsan_files.cmake
cmake_minimum_required(VERSION 3.25)
file(READ "${SOURCE_DIR}/CMakePresets.json" presets)
string(JSON count LENGTH "${presets}" testPresets)
math(EXPR last "${count} - 1")
set(selects "")
foreach(k RANGE ${last})
  string(JSON name GET "${presets}" testPresets ${k} name)
  if(name STREQUAL "tsan")
    string(JSON selects GET "${presets}" testPresets ${k} filter include name)
  endif()
endforeach()
if(selects STREQUAL "")
  message(FATAL_ERROR "CMakePresets.json has no tsan test preset with a name filter")
endif()

string(REPLACE "," ";" files "${OTHER_FILES}")
set(misplaced "")
foreach(file IN LISTS files)
  file(READ "${SOURCE_DIR}/tests/${file}" text)
  string(REPLACE ";" "," text "${text}")  # a ';' in a name would split the list of matches
  # A name may be adjacent literals ("a " "b"): every piece, then the pieces joined.
  string(REGEX MATCHALL "TEST_CASE\\(([ \t\r\n]*\"[^\"]*\")+" cases "${text}")
  foreach(c IN LISTS cases)
    string(REGEX REPLACE "\"[ \t\r\n]*\"" "" joined "${c}")
    string(REGEX REPLACE "^TEST_CASE\\([ \t\r\n]*\"(.*)\"$" "\\1" test "${joined}")
    if("kinema.${test}" MATCHES "${selects}")
      string(APPEND misplaced "\n  ${file}: ${test}")
    endif()
  endforeach()
endforeach()
if(NOT misplaced STREQUAL "")
  message(FATAL_ERROR "tests the TSan run selects (${selects}) in files it does not compile; "
                      "move them or list their file in KINEMA_THREAD_TEST_FILES:${misplaced}")
endif()
message(STATUS "every test of kinema_tests the TSan run selects is in a file it compiles")

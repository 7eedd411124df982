# The `fuzz` ctest of the main (gcc) build: tests/fuzz/run_fuzzers.sh builds
# the libFuzzer targets with clang in BUILD/fuzz-build and runs each for
# DISPMVS_FUZZ_SECONDS from the committed corpus; any crash, sanitizer report
# or failed property check fails the test. It needs clang++ and the libFuzzer
# and sanitizer runtimes (Debian: clang, libclang-rt-14-dev); without them the
# test is left out and the rest of the build is unaffected.

set(DISPMVS_FUZZ_SECONDS 30 CACHE STRING
    "Seconds each libFuzzer target runs in the fuzz ctest (0: no fuzz ctest)")
find_program(DISPMVS_FUZZ_CXX NAMES clang++ clang++-14
             DOC "clang++ that builds the libFuzzer targets of the fuzz ctest")

# Whether `cxx` can link a libFuzzer target with the sanitizers we use: clang
# alone is not enough, the runtimes come in a separate package.
function(dispmvs_probe_libfuzzer cxx result)
  set(_dir ${CMAKE_BINARY_DIR}/CMakeFiles/dispmvs_fuzz_probe)
  file(WRITE ${_dir}/probe.cc
       "#include <cstddef>\n#include <cstdint>\n"
       "extern \"C\" int LLVMFuzzerTestOneInput(const uint8_t*, size_t) { return 0; }\n")
  execute_process(
    COMMAND ${cxx} -fsanitize=fuzzer,address,undefined probe.cc -o probe
    WORKING_DIRECTORY ${_dir}
    RESULT_VARIABLE _status OUTPUT_QUIET ERROR_VARIABLE _error)
  if(_status EQUAL 0)
    set(${result} "" PARENT_SCOPE)
  else()
    string(REGEX REPLACE "\n.*" "" _first_line "${_error}")
    set(${result} "${cxx} cannot link a libFuzzer target (${_first_line})" PARENT_SCOPE)
  endif()
endfunction()

set(_why_not "")
if(NOT DISPMVS_FUZZ_SECONDS GREATER 0)
  set(_why_not "DISPMVS_FUZZ_SECONDS is ${DISPMVS_FUZZ_SECONDS}")
elseif(NOT DISPMVS_FUZZ_CXX)
  set(_why_not "clang++ not found")
else()
  dispmvs_probe_libfuzzer(${DISPMVS_FUZZ_CXX} _why_not)
endif()

if(_why_not)
  message(STATUS "dispmvs: no fuzz test: ${_why_not}; "
                 "install clang and libclang-rt-14-dev (.ci/install_deps.sh) to get it")
  return()
endif()

# The clang build takes about 2.5 min on two cores, then 7 targets run in 4
# rounds; the limit leaves room for a slower machine.
math(EXPR _timeout "600 + 4 * ${DISPMVS_FUZZ_SECONDS}")
message(STATUS "dispmvs: fuzz test with ${DISPMVS_FUZZ_CXX}, ${DISPMVS_FUZZ_SECONDS} s per target")
set(_environment
  DISPMVS_FUZZ_CXX=${DISPMVS_FUZZ_CXX}
  DISPMVS_FUZZ_BUILD_DIR=${CMAKE_BINARY_DIR}/fuzz-build
  DISPMVS_FUZZ_FRESH=1  # from the committed corpus alone, every run alike
  DISPMVS_FUZZ_JOBS=2)
add_test(NAME fuzz_readers COMMAND ${PROJECT_SOURCE_DIR}/tests/fuzz/run_fuzzers.sh
                                   ${DISPMVS_FUZZ_SECONDS})
set_tests_properties(fuzz_readers PROPERTIES
  LABELS fuzz
  ENVIRONMENT "${_environment}"
  # The clang build uses both cores, then two targets run at a time: keep
  # other tests off the machine meanwhile.
  PROCESSORS 2
  TIMEOUT ${_timeout})

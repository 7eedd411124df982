# The fuzz ctests of the main (gcc) build: tests/fuzz/run_fuzzers.sh builds
# the libFuzzer targets with clang in BUILD/fuzz-build and runs them.
#  * fuzz_readers (label fuzz, in the default run): `run_fuzzers.sh replay`,
#    every committed input and a fixed number of mutations from a fixed seed,
#    so that its verdict depends on the tree alone.
#  * fuzz_campaign (label fuzz_campaign, only when DISPMVS_FUZZ_CAMPAIGN_SECONDS
#    is set above 0): `run_fuzzers.sh campaign`, random seeds for that long per
#    target, to look for new bugs on purpose.
# Any crash, sanitizer report or failed property check fails them. They need
# clang++ and the libFuzzer and sanitizer runtimes (Debian: clang,
# libclang-rt-14-dev); without them the tests are left out and the rest of
# the build is unaffected.

option(DISPMVS_FUZZ_CTEST "Register the fuzz_readers ctest (needs clang)" ON)
set(DISPMVS_FUZZ_CAMPAIGN_SECONDS 0 CACHE STRING
    "Seconds per target of the fuzz_campaign ctest (0: no such test)")
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
if(NOT DISPMVS_FUZZ_CTEST AND NOT DISPMVS_FUZZ_CAMPAIGN_SECONDS GREATER 0)
  set(_why_not "DISPMVS_FUZZ_CTEST is OFF")
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

set(_environment
  DISPMVS_FUZZ_CXX=${DISPMVS_FUZZ_CXX}
  DISPMVS_FUZZ_BUILD_DIR=${CMAKE_BINARY_DIR}/fuzz-build
  DISPMVS_FUZZ_JOBS=2)
if(DISPMVS_FUZZ_CTEST)
  message(STATUS "dispmvs: fuzz test with ${DISPMVS_FUZZ_CXX}: committed inputs and fixed-seed runs")
  add_test(NAME fuzz_readers COMMAND ${PROJECT_SOURCE_DIR}/tests/fuzz/run_fuzzers.sh replay)
  set_tests_properties(fuzz_readers PROPERTIES
    LABELS fuzz
    ENVIRONMENT "${_environment}"
    # The clang build uses both cores, then two targets run at a time: keep
    # other tests off the machine meanwhile.
    PROCESSORS 2
    RESOURCE_LOCK dispmvs_fuzz_build
    # About 2.5 min of clang build and 2 min of fuzzing on two idle cores;
    # room for a slower or busier machine.
    TIMEOUT 900)
endif()
if(DISPMVS_FUZZ_CAMPAIGN_SECONDS GREATER 0)
  math(EXPR _timeout "600 + 4 * ${DISPMVS_FUZZ_CAMPAIGN_SECONDS}")
  add_test(NAME fuzz_campaign COMMAND ${PROJECT_SOURCE_DIR}/tests/fuzz/run_fuzzers.sh campaign
                                      ${DISPMVS_FUZZ_CAMPAIGN_SECONDS})
  set_tests_properties(fuzz_campaign PROPERTIES
    LABELS fuzz_campaign
    ENVIRONMENT "${_environment};DISPMVS_FUZZ_FRESH=1"
    PROCESSORS 2
    RESOURCE_LOCK dispmvs_fuzz_build
    TIMEOUT ${_timeout})
endif()

# ctest `dispmvs_install`: `cmake --install` into a temporary prefix, then the
# installed programs run the example, and dispmvs_colmap uses the weights it
# finds beside itself (it prints their path), also after the prefix is moved.
#   cmake -DBUILD_DIR=<build> -DWORK_DIR=<scratch> -P install_test.cmake

file(REMOVE_RECURSE "${WORK_DIR}")
file(MAKE_DIRECTORY "${WORK_DIR}")
set(prefix "${WORK_DIR}/prefix")

execute_process(COMMAND "${CMAKE_COMMAND}" --install "${BUILD_DIR}" --prefix "${prefix}"
  RESULT_VARIABLE status OUTPUT_QUIET ERROR_VARIABLE errors)
if(NOT status EQUAL 0)
  message(FATAL_ERROR "cmake --install failed (${status}): ${errors}")
endif()
foreach(file bin/dispmvs_colmap bin/dispmvs_eval bin/dispmvs_report bin/dispmvs_synth bin/dispmvs_train
             bin/dispmvs_make_example share/dispmvs/models/dispmvs_small.safetensors
             share/dispmvs/models/dispmvs_small_paper.safetensors share/dispmvs/models/README.md)
  if(NOT EXISTS "${prefix}/${file}")
    message(FATAL_ERROR "not installed: ${prefix}/${file}")
  endif()
endforeach()

# Runs the installed dispmvs_colmap of `root` on a fresh example and checks
# which weights it used.
function(run_installed root name)
  set(ws "${WORK_DIR}/${name}")
  execute_process(COMMAND "${root}/bin/dispmvs_make_example" --output_path "${ws}" --seed 1
    RESULT_VARIABLE status OUTPUT_QUIET ERROR_VARIABLE errors)
  if(NOT status EQUAL 0)
    message(FATAL_ERROR "installed dispmvs_make_example failed: ${errors}")
  endif()
  execute_process(COMMAND "${root}/bin/dispmvs_colmap" --workspace_path "${ws}"
                          --max_image_size 64 --threads 1
    RESULT_VARIABLE status OUTPUT_VARIABLE out ERROR_VARIABLE errors)
  if(NOT status EQUAL 0)
    message(FATAL_ERROR "installed dispmvs_colmap failed (${status}):\n${out}${errors}")
  endif()
  string(FIND "${out}" "weights ${root}/share/dispmvs/models/dispmvs_small.safetensors\n" at)
  if(at EQUAL -1)
    message(FATAL_ERROR "the installed program did not use the installed weights:\n${out}")
  endif()
  if(NOT out MATCHES "summary: fusion: [1-9][0-9]* points from 7 image")
    message(FATAL_ERROR "no fused points:\n${out}")
  endif()
endfunction()

run_installed("${prefix}" example)
# A prefix moved elsewhere keeps its weights: they are found relative to the
# program, not through a path compiled in.
file(RENAME "${prefix}" "${WORK_DIR}/moved")
run_installed("${WORK_DIR}/moved" moved_example)
message(STATUS "installed, ran, moved and ran again: ok")

# Command-line tests of dispmvs_colmap, run by ctest as
#   cmake -DPROGRAM=<dispmvs_colmap> -DWORK_DIR=<scratch dir> -DCASE=<name> -P <this file>
# Each case runs the program and checks its exit status and output; any
# mismatch is a FATAL_ERROR (the test fails).
#
# The "plan_*" cases build a tiny dense workspace by hand (text sparse model,
# empty image files) whose plan is known in advance:
#   PINHOLE camera, identity rotations, centres at x = 0, 1, 2, 3 for
#   a.png, sub/b.png, c.png, d.png; points (depth = z for every image):
#     P1 (0.5, 0, 4) seen by a, b       P2 (1, 0, 5) seen by a, b, c
#     P3 (1.5, 0, 6) seen by a, b, c    P4 (1, 0, 8) seen by a, b
#   Depth ranges (COLMAP's rule, percentiles 0.01 / 0.99 of the sorted depths,
#   stretch 0.25): a, b: depths 4 5 6 8 -> [0.75 * 4, 1.25 * 8] = [3, 10];
#   c: depths 5 6 -> [3.75, 7.5]; d sees nothing -> fallback, the union [3, 10].
#   Shared points: a-b 4, a-c 2, b-c 2; the pairs' triangulation angles
#   (75th percentile over shared points) are about 11, 23 and 11 degrees. So
#   __auto__ gives a: b, c; b: a, c; c: a, b (tie broken by id); d: nothing
#   (skipped) from the sparse points, so its sources come from the poses:
#   the fallback hint [3, 10] is sampled, and the nearer a camera the more
#   of d's frustum it sees (colmap_io/view_selection.h): c, b, a. A 60 degree
#   minimum leaves nobody any source.
#
# "plan_no_points" is the same workspace without any point: no image has a
# hint (d_min=none), every __auto__ source list comes from the poses (sampled
# at 2 to 100 times the typical baseline 1), nearest cameras first.
# "example_no_points" runs the program on the embedded example with its
# sparse points dropped (-DMAKE_EXAMPLE, -DDROP_POINTS).
# "stereo_pair" and "stereo_pair_explicit" keep two neighbouring views of the
# embedded example (patch-match.cfg: view_02.png <-> view_03.png), so each
# reference has one source map and --min_num_consistent's default (2) cannot
# be met: the default falls back to 1 with a warning, an explicit 2 is
# refused before any work.

cmake_minimum_required(VERSION 3.18)

foreach(var PROGRAM WORK_DIR CASE)
  if(NOT DEFINED ${var})
    message(FATAL_ERROR "dispmvs_colmap_cli_test: -D${var}=... is required")
  endif()
endforeach()

set(tab "\t")

function(make_workspace root)
  file(REMOVE_RECURSE "${root}")
  file(MAKE_DIRECTORY "${root}/images/sub" "${root}/sparse")
  foreach(name a.png sub/b.png c.png d.png)
    file(WRITE "${root}/images/${name}" "")
  endforeach()
  file(WRITE "${root}/sparse/cameras.txt"
    "# Camera list\n"
    "1 PINHOLE 100 100 100 100 50 50\n")
  # points2D "X Y POINT3D_ID" (projections of the points above).
  file(WRITE "${root}/sparse/images.txt"
    "# Image list\n"
    "1 1 0 0 0 0 0 0 1 a.png\n"
    "62.5 50 1 70 50 2 75 50 3 62.5 50 4\n"
    "2 1 0 0 0 -1 0 0 1 sub/b.png\n"
    "37.5 50 1 50 50 2 58.3333 50 3 50 50 4\n"
    "3 1 0 0 0 -2 0 0 1 c.png\n"
    "30 50 2 41.6667 50 3\n"
    "4 1 0 0 0 -3 0 0 1 d.png\n"
    "\n")
  file(WRITE "${root}/sparse/points3D.txt"
    "# 3D point list\n"
    "1 0.5 0 4 255 0 0 0.5 1 0 2 0\n"
    "2 1 0 5 0 255 0 0.5 1 1 2 1 3 0\n"
    "3 1.5 0 6 0 0 255 0.5 1 2 2 2 3 1\n"
    "4 1 0 8 9 9 9 0.5 1 3 2 3\n")
endfunction()

# Runs the program with ARGN; sets rc, out, err in the caller.
macro(run_program)
  execute_process(COMMAND "${PROGRAM}" ${ARGN}
    RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
endmacro()

function(expect_rc expected)
  if(NOT rc EQUAL expected)
    message(FATAL_ERROR "exit status ${rc}, expected ${expected}\nstdout:\n${out}\nstderr:\n${err}")
  endif()
endfunction()

function(expect_contains text fragment)
  string(FIND "${text}" "${fragment}" position)
  if(position EQUAL -1)
    message(FATAL_ERROR "output lacks \"${fragment}\"\nstdout:\n${out}\nstderr:\n${err}")
  endif()
endfunction()

# The embedded example reduced to the stereo pair view_02.png <-> view_03.png.
function(make_stereo_pair root)
  if(NOT DEFINED MAKE_EXAMPLE)
    message(FATAL_ERROR "dispmvs_colmap_cli_test: -DMAKE_EXAMPLE=... is required for ${CASE}")
  endif()
  file(REMOVE_RECURSE "${root}")
  execute_process(COMMAND "${MAKE_EXAMPLE}" --output_path "${root}" --seed 1
    RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  expect_rc(0)
  file(WRITE "${root}/stereo/patch-match.cfg"
    "view_02.png\nview_03.png\nview_03.png\nview_02.png\n")
endfunction()

# The vertex count of a binary PLY (from its text header); sets `vertices`.
function(read_ply_vertex_count path)
  if(NOT EXISTS "${path}")
    message(FATAL_ERROR "${path} was not written\nstdout:\n${out}\nstderr:\n${err}")
  endif()
  file(STRINGS "${path}" header LIMIT_INPUT 1024 REGEX "^element vertex [0-9]+$")
  if(NOT header MATCHES "^element vertex ([0-9]+)$")
    message(FATAL_ERROR "${path} has no vertex count in its header")
  endif()
  set(vertices "${CMAKE_MATCH_1}" PARENT_SCOPE)
endfunction()

# A failure must be one "error: ..." line on stderr and nothing on stdout.
function(expect_error_line fragment)
  expect_rc(1)
  if(NOT err MATCHES "^error: [^\n]+\n$")
    message(FATAL_ERROR "stderr is not one \"error: ...\" line:\n${err}")
  endif()
  if(NOT out STREQUAL "")
    message(FATAL_ERROR "unexpected stdout on failure:\n${out}")
  endif()
  expect_contains("${err}" "${fragment}")
endfunction()

set(ws "${WORK_DIR}/ws")

if(CASE STREQUAL "help")
  run_program(--help)
  expect_rc(0)
  expect_contains("${out}" "--workspace_path")
  expect_contains("${out}" "--max_num_src_images")
  expect_contains("${out}" "patch-match.cfg")
  expect_contains("${out}" "--mode")
  expect_contains("${out}" "--shard")
  expect_contains("${out}" "no sparse points at all")
  expect_contains("${out}" "from the camera poses")
  # Boost wraps option descriptions: compare them as one line.
  string(REGEX REPLACE " *\n *" " " flat "${out}")
  expect_contains("${flat}" "(a stereo pair: 1 each) needs what it has, at least 1, with a warning")
  expect_contains("${flat}" "no reference can meet stops the run before any work")
elseif(CASE STREQUAL "missing_workspace_option")
  run_program()
  expect_error_line("--workspace_path is required")
elseif(CASE STREQUAL "bad_workspace_path")
  run_program(--workspace_path "${WORK_DIR}/does_not_exist")
  expect_error_line("does_not_exist: workspace folder does not exist")
elseif(CASE STREQUAL "bad_option_values")
  foreach(bad "--max_num_src_images=-3" "--max_num_src_images=0")
    run_program(--workspace_path "${WORK_DIR}" ${bad})
    expect_error_line("--max_num_src_images must be at least 1")
  endforeach()
  run_program(--workspace_path "${WORK_DIR}" --min_triangulation_angle nan)
  expect_error_line("--min_triangulation_angle must be a finite number")
  run_program(--workspace_path "${WORK_DIR}" --depth_stretch_ratio 1.5)
  expect_error_line("--depth_stretch_ratio")
  run_program(--workspace_path "${WORK_DIR}" --depth_min_percentile 0.9 --depth_max_percentile 0.1)
  expect_error_line("--depth_min_percentile must not exceed")
  run_program(--workspace_path "${WORK_DIR}" --max_num_src_images abc)
  expect_error_line("max_num_src_images")
  run_program(--workspace_path "${WORK_DIR}" --no_such_option)
  expect_error_line("no_such_option")
  run_program(--workspace_path "${WORK_DIR}" --mode guess)
  expect_error_line("--mode must be")
  run_program(--workspace_path "${WORK_DIR}" --mode export)
  expect_error_line("--mode export needs --export_path")
  run_program(--workspace_path "${WORK_DIR}" --depth_min 2)
  expect_error_line("--depth_min and --depth_max must be given together")
  run_program(--workspace_path "${WORK_DIR}" --depth_min 5 --depth_max 2)
  expect_error_line("--depth_min must be smaller")
  foreach(bad 0.5 nan)
    run_program(--workspace_path "${WORK_DIR}" --depth_range_widening ${bad})
    expect_error_line("--depth_range_widening")
  endforeach()
  run_program(--workspace_path "${WORK_DIR}" --device tpu)
  expect_error_line("--device")
  run_program(--workspace_path "${WORK_DIR}" --max_depth_error -1)
  expect_error_line("--max_depth_error must be")
elseif(CASE STREQUAL "plan_auto")
  make_workspace("${ws}")
  run_program(--mode plan --workspace_path "${ws}")
  expect_rc(0)
  expect_contains("${out}" "a.png${tab}d_min=3${tab}d_max=10${tab}points=4${tab}sources=sub/b.png,c.png\n")
  expect_contains("${out}" "sub/b.png${tab}d_min=3${tab}d_max=10${tab}points=4${tab}sources=a.png,c.png\n")
  expect_contains("${out}" "c.png${tab}d_min=3.75${tab}d_max=7.5${tab}points=2${tab}sources=a.png,sub/b.png\n")
  expect_contains("${out}" "d.png${tab}d_min=3${tab}d_max=10${tab}points=0${tab}fallback${tab}poses${tab}sources=c.png,sub/b.png,a.png\n")
  expect_contains("${out}" "# planning without sparse points: 1 of 4 reference image(s) see none (d.png); their depth-range hint is the union")
  # --max_num_src_images caps __auto__.
  run_program(--mode plan --workspace_path "${ws}" --max_num_src_images 1)
  expect_rc(0)
  expect_contains("${out}" "a.png${tab}d_min=3${tab}d_max=10${tab}points=4${tab}sources=sub/b.png\n")
  expect_contains("${out}" "c.png${tab}d_min=3.75${tab}d_max=7.5${tab}points=2${tab}sources=a.png\n")
  expect_contains("${out}" "d.png${tab}d_min=3${tab}d_max=10${tab}points=0${tab}fallback${tab}poses${tab}sources=c.png\n")
  # A triangulation angle nobody reaches leaves every image without sources.
  run_program(--mode plan --workspace_path "${ws}" --min_triangulation_angle 60)
  expect_rc(0)
  expect_contains("${out}" "a.png${tab}d_min=3${tab}d_max=10${tab}points=4${tab}sources=(none")
  expect_contains("${out}" "d.png${tab}d_min=3${tab}d_max=10${tab}points=0${tab}fallback${tab}poses${tab}sources=(none")
  # --depth_range_widening x gives [d_min / x, d_max * x] to every hint,
  # the fallback and the user's included.
  run_program(--mode plan --workspace_path "${ws}" --depth_range_widening 2)
  expect_rc(0)
  expect_contains("${out}" "a.png${tab}d_min=1.5${tab}d_max=20${tab}points=4${tab}sources=sub/b.png,c.png\n")
  expect_contains("${out}" "c.png${tab}d_min=1.875${tab}d_max=15${tab}points=2${tab}sources=a.png,sub/b.png\n")
  expect_contains("${out}" "d.png${tab}d_min=1.5${tab}d_max=20${tab}points=0${tab}fallback")
  run_program(--mode plan --workspace_path "${ws}" --depth_range_widening 4 --depth_min 2 --depth_max 8)
  expect_rc(0)
  expect_contains("${out}" "c.png${tab}d_min=0.5${tab}d_max=32${tab}points=2${tab}user")
elseif(CASE STREQUAL "plan_config")
  make_workspace("${ws}")
  file(WRITE "${ws}/stereo/patch-match.cfg"
    "# hand written\r\n"
    "c.png\r\n"
    "__all__\r\n"
    "a.png\r\n"
    "c.png, sub/b.png\r\n"
    "sub/b.png\r\n"
    "__auto__, 1\r\n")
  run_program(--mode plan --workspace_path "${ws}")
  expect_rc(0)
  expect_contains("${out}" "c.png${tab}d_min=3.75${tab}d_max=7.5${tab}points=2${tab}sources=a.png,sub/b.png,d.png\n")
  expect_contains("${out}" "a.png${tab}d_min=3${tab}d_max=10${tab}points=4${tab}sources=c.png,sub/b.png\n")
  expect_contains("${out}" "sub/b.png${tab}d_min=3${tab}d_max=10${tab}points=4${tab}sources=a.png\n")
  # d.png is not a reference in this config.
  string(FIND "${out}" "d.png${tab}" position)
  if(NOT position EQUAL -1)
    message(FATAL_ERROR "d.png planned although the config does not list it:\n${out}")
  endif()
elseif(CASE STREQUAL "plan_errors")
  make_workspace("${ws}")
  file(WRITE "${ws}/stereo/patch-match.cfg" "a.png\nghost.png\n")
  run_program(--mode plan --workspace_path "${ws}")
  expect_error_line("patch-match.cfg: source image \"ghost.png\"")
  file(WRITE "${ws}/stereo/patch-match.cfg" "a.png\n__auto__, zero\n")
  run_program(--mode plan --workspace_path "${ws}")
  expect_error_line("patch-match.cfg: line 2")
  file(REMOVE "${ws}/stereo/patch-match.cfg")
  # A missing image is reported and left out of every source list.
  file(REMOVE "${ws}/images/c.png")
  run_program(--mode plan --workspace_path "${ws}")
  expect_rc(0)
  expect_contains("${out}" "warning: image file missing, not used: c.png\n")
  expect_contains("${out}" "a.png${tab}d_min=3${tab}d_max=10${tab}points=4${tab}sources=sub/b.png\n")
  # Weights that do not exist stop the run before any view is written.
  run_program(--workspace_path "${ws}" --model_path "${WORK_DIR}/no_weights.safetensors")
  expect_error_line("cannot use the weights")
  # Shards need the photometric mode.
  run_program(--workspace_path "${ws}" --shard 0/2)
  expect_error_line("--shard and --image_list split the photometric pass")
  run_program(--mode photometric --workspace_path "${ws}" --shard 2/2)
  expect_error_line("--shard must be K/N")
  run_program(--mode plan --workspace_path "${ws}" --shard 1/2)
  expect_rc(0)
  expect_contains("${out}" "sub/b.png${tab}")
  string(FIND "${out}" "a.png${tab}" position)
  if(NOT position EQUAL -1)
    message(FATAL_ERROR "shard 1/2 planned a.png:\n${out}")
  endif()
  file(WRITE "${WORK_DIR}/list.txt" "d.png\n")
  run_program(--mode plan --workspace_path "${ws}" --image_list "${WORK_DIR}/list.txt")
  expect_rc(0)
  expect_contains("${out}" "1 stereo problems")
  file(WRITE "${WORK_DIR}/list.txt" "ghost.png\n")
  run_program(--mode plan --workspace_path "${ws}" --image_list "${WORK_DIR}/list.txt")
  expect_error_line("ghost.png")
  file(REMOVE_RECURSE "${ws}/sparse")
  run_program(--mode plan --workspace_path "${ws}")
  expect_error_line("sparse folder of the workspace does not exist")
elseif(CASE STREQUAL "plan_no_points")
  make_workspace("${ws}")
  file(WRITE "${ws}/sparse/points3D.txt" "# 3D point list\n")
  file(WRITE "${ws}/sparse/images.txt"
    "# Image list\n"
    "1 1 0 0 0 0 0 0 1 a.png\n\n"
    "2 1 0 0 0 -1 0 0 1 sub/b.png\n\n"
    "3 1 0 0 0 -2 0 0 1 c.png\n\n"
    "4 1 0 0 0 -3 0 0 1 d.png\n\n")
  run_program(--mode plan --workspace_path "${ws}")
  expect_rc(0)
  expect_contains("${out}" "# 4 images, 0 sparse points")
  expect_contains("${out}" "# planning without sparse points (the sparse model has no 3-D points): 4 of 4 reference image(s) see none (a.png, sub/b.png, c.png, d.png); no depth-range hint")
  expect_contains("${out}" "chosen from the camera poses")
  expect_contains("${out}" "sampled at depths 2 to 100, guessed from the baselines")
  # Centres at x = 0 and 3 have no tie: nearest first.
  expect_contains("${out}" "a.png${tab}d_min=none${tab}d_max=none${tab}points=0${tab}poses${tab}sources=sub/b.png,c.png,d.png\n")
  expect_contains("${out}" "d.png${tab}d_min=none${tab}d_max=none${tab}points=0${tab}poses${tab}sources=c.png,sub/b.png,a.png\n")
  run_program(--mode plan --workspace_path "${ws}" --max_num_src_images 2)
  expect_rc(0)
  expect_contains("${out}" "a.png${tab}d_min=none${tab}d_max=none${tab}points=0${tab}poses${tab}sources=sub/b.png,c.png\n")
  # The user's range is the hint and what the selection samples.
  run_program(--mode plan --workspace_path "${ws}" --depth_min 2 --depth_max 8)
  expect_rc(0)
  expect_contains("${out}" "a.png${tab}d_min=2${tab}d_max=8${tab}points=0${tab}user${tab}poses${tab}sources=sub/b.png,c.png,d.png\n")
  expect_contains("${out}" "depth-range hint from --depth_min/--depth_max")
  # Explicit lists are used as written; __auto__ entries still use the poses.
  file(WRITE "${ws}/stereo/patch-match.cfg" "a.png\nc.png, d.png\nd.png\n__auto__, 1\n")
  run_program(--mode plan --workspace_path "${ws}")
  expect_rc(0)
  expect_contains("${out}" "a.png${tab}d_min=none${tab}d_max=none${tab}points=0${tab}sources=c.png,d.png\n")
  expect_contains("${out}" "d.png${tab}d_min=none${tab}d_max=none${tab}points=0${tab}poses${tab}sources=c.png\n")
  expect_contains("${out}" "the __auto__ sources of 1 image(s) are chosen from the camera poses")
  # All centres equal: nothing triangulates, nobody gets a source.
  file(REMOVE "${ws}/stereo/patch-match.cfg")
  file(WRITE "${ws}/sparse/images.txt"
    "# Image list\n"
    "1 1 0 0 0 0 0 0 1 a.png\n\n"
    "2 1 0.9961947 0 0.0871557 0 0 0 1 sub/b.png\n\n")
  run_program(--mode plan --workspace_path "${ws}")
  expect_rc(0)
  expect_contains("${out}" "a.png${tab}d_min=none${tab}d_max=none${tab}points=0${tab}poses${tab}sources=(none")
elseif(CASE STREQUAL "example_no_points")
  foreach(var MAKE_EXAMPLE DROP_POINTS)
    if(NOT DEFINED ${var})
      message(FATAL_ERROR "dispmvs_colmap_cli_test: -D${var}=... is required for ${CASE}")
    endif()
  endforeach()
  file(REMOVE_RECURSE "${ws}")
  execute_process(COMMAND "${MAKE_EXAMPLE}" --output_path "${ws}" --seed 1
                          --ground_truth_sampling colmap-dense
    RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  expect_rc(0)
  execute_process(COMMAND "${DROP_POINTS}" "${ws}/sparse"
    RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  expect_rc(0)

  # (a) The plan: no hint anywhere, the example's `__auto__, 4` from the poses.
  run_program(--mode plan --workspace_path "${ws}")
  expect_rc(0)
  expect_contains("${out}" "0 sparse points")
  expect_contains("${out}" "(the sparse model has no 3-D points): 7 of 7 reference image(s) see none")
  # The example's views view_00 .. view_06 are taken along a path around the
  # scene, so every view's first source must be a neighbour on that path,
  # and each gets at least 3 of its 4 sources (the two ends of the path see
  # less of the far ones).
  string(REGEX MATCHALL "view_0[0-9].png${tab}d_min=none${tab}d_max=none${tab}points=0${tab}poses${tab}sources=[^\n]+\n"
         lines "${out}")
  list(LENGTH lines count)
  if(NOT count EQUAL 7)
    message(FATAL_ERROR "expected 7 references with pose-chosen sources, got ${count}:\n${out}")
  endif()
  foreach(line IN LISTS lines)
    if(NOT line MATCHES "^view_0([0-9]).png${tab}.*sources=view_0([0-9]).png,[^,\n]+,[^,\n]+")
      message(FATAL_ERROR "fewer than 3 sources: ${line}\n${out}")
    endif()
    math(EXPR step "${CMAKE_MATCH_1} - ${CMAKE_MATCH_2}")
    if(NOT (step EQUAL 1 OR step EQUAL -1))
      message(FATAL_ERROR "first source is not a neighbour on the path: ${line}")
    endif()
  endforeach()
  # The first reference, for the runs below.
  string(REGEX MATCH "\n([^#\n${tab}][^\n${tab}]*)${tab}d_min=none" first "${out}")
  set(reference "${CMAKE_MATCH_1}")
  if(reference STREQUAL "")
    message(FATAL_ERROR "no reference line in the plan:\n${out}")
  endif()

  # (b) The paper's weights (init = random, shipped beside the default ones)
  # need a hint, so the run stops before any work with a message naming the
  # options.
  run_program(--workspace_path "${ws}" --threads 2 --model_path "${PAPER_MODEL}")
  expect_error_line("--depth_min and --depth_max")
  expect_contains("${err}" "model v2")
  file(GLOB written "${ws}/stereo/depth_maps/*.dispmvs.*")
  if(written)
    message(FATAL_ERROR "maps written although the run failed: ${written}")
  endif()

  # (b2) The default weights are model v2's (init = match): without any
  # hint, one view runs.
  file(WRITE "${WORK_DIR}/list.txt" "${reference}\n")
  run_program(--mode photometric --workspace_path "${ws}" --image_list "${WORK_DIR}/list.txt"
              --max_image_size 160 --threads 2)
  expect_rc(0)
  expect_contains("${out}" "plan: planning without sparse points")
  expect_contains("${out}" "photometric: 1 done")
  if(NOT EXISTS "${ws}/stereo/depth_maps/${reference}.dispmvs.photometric.bin")
    message(FATAL_ERROR "no depth map for ${reference} without a hint:\n${out}")
  endif()
  # Remove its maps so that (c) computes the view again.
  file(GLOB maps "${ws}/stereo/*/${reference}.dispmvs.*")
  file(REMOVE ${maps})

  # (c) With a user range (the scene's depths are 3 to 10), one view runs.
  file(WRITE "${WORK_DIR}/list.txt" "${reference}\n")
  run_program(--mode photometric --workspace_path "${ws}" --depth_min 2 --depth_max 12
              --image_list "${WORK_DIR}/list.txt" --max_image_size 160 --threads 2)
  expect_rc(0)
  expect_contains("${out}" "plan: planning without sparse points")
  expect_contains("${out}" "depth-range hint from --depth_min/--depth_max")
  expect_contains("${out}" "photometric: 1 done")
  if(NOT EXISTS "${ws}/stereo/depth_maps/${reference}.dispmvs.photometric.bin")
    message(FATAL_ERROR "no depth map for ${reference}:\n${out}")
  endif()
elseif(CASE STREQUAL "stereo_pair")
  # One source map per reference, the default asks for 2: the run says so
  # before the network starts, uses 1 for both references and fuses points.
  make_stereo_pair("${ws}")
  run_program(--workspace_path "${ws}" --max_image_size 160 --threads 1)
  expect_rc(0)
  set(warning "warning: --min_num_consistent is 2 by default, but 2 of 2 reference image(s) have fewer source views with depth maps (view_02.png, view_03.png): using 1 for them; pass --min_num_consistent to choose the value yourself\n")
  expect_contains("${out}" "${warning}")
  string(FIND "${out}" "${warning}" warning_at)
  string(FIND "${out}" "photometric: network" network_at)
  if(network_at EQUAL -1 OR NOT warning_at LESS network_at)
    message(FATAL_ERROR "the warning does not come before the network runs:\n${out}")
  endif()
  expect_contains("${out}" "photometric: 2 done")
  expect_contains("${out}" "geometric: 2 done")
  string(FIND "${out}" "has 0 points" position)
  if(NOT position EQUAL -1)
    message(FATAL_ERROR "empty cloud:\n${out}")
  endif()
  read_ply_vertex_count("${ws}/fused.ply")
  if(NOT vertices GREATER 0)
    message(FATAL_ERROR "fused.ply has ${vertices} points\n${out}")
  endif()
  file(READ "${ws}/fused.ply" fallback_ply HEX)
  file(SHA256 "${ws}/stereo/depth_maps/view_02.png.dispmvs.geometric.bin" fallback_map)

  # The fallback is exactly an explicit 1, which needs no word.
  run_program(--mode fuse --workspace_path "${ws}" --min_num_consistent 1)
  expect_rc(0)
  string(FIND "${out}" "warning:" position)
  if(NOT position EQUAL -1)
    message(FATAL_ERROR "warning with an explicit value the pair meets:\n${out}")
  endif()
  file(READ "${ws}/fused.ply" explicit_ply HEX)
  file(SHA256 "${ws}/stereo/depth_maps/view_02.png.dispmvs.geometric.bin" explicit_map)
  if(NOT fallback_ply STREQUAL explicit_ply OR NOT fallback_map STREQUAL explicit_map)
    message(FATAL_ERROR "the fallback differs from --min_num_consistent 1")
  endif()

  # An empty cloud is not a failure, but it is said, with the options that
  # decide it.
  run_program(--mode fuse --workspace_path "${ws}" --max_depth_error 1e-12)
  expect_rc(0)
  expect_contains("${out}" "summary: fusion: 0 points from 2 image(s)\n")
  expect_contains("${out}" "warning: ${ws}/fused.ply has 0 points: no pixel of the 2 image(s) with depth maps agreed with enough of its sources (--min_num_consistent 2, lowered for 2 reference image(s) as warned above; agreeing = within --max_reproj_error and --max_depth_error, at --min_confidence or more); the geometric lines above show the share each image kept\n")
elseif(CASE STREQUAL "stereo_pair_explicit")
  # An explicit value no reference can meet: refused before any work, in
  # both modes that filter, naming the option and what to pass.
  make_stereo_pair("${ws}")
  foreach(mode full fuse)
    run_program(--mode ${mode} --workspace_path "${ws}" --min_num_consistent 2 --threads 1)
    expect_error_line("--min_num_consistent 2 cannot be met: no reference image has that many source views with depth maps (at most 1, as in a stereo pair), so the geometric filter and fusion would keep no pixel; pass --min_num_consistent 1 or less, or leave it out")
  endforeach()
  file(GLOB written "${ws}/stereo/*/*.dispmvs.*" "${ws}/fused.ply")
  if(written)
    message(FATAL_ERROR "files written although the run was refused: ${written}")
  endif()
  # Modes without the filter are not refused (the plan, here).
  run_program(--mode plan --workspace_path "${ws}" --min_num_consistent 2)
  expect_rc(0)
  # Sources that are no references have no maps: with view_03.png as the
  # only reference, no value but 0 keeps anything, even by default.
  file(WRITE "${ws}/stereo/patch-match.cfg" "view_03.png\nview_02.png\n")
  run_program(--workspace_path "${ws}" --threads 1)
  expect_error_line("no reference image has a source view with a depth map of its own")
  expect_contains("${err}" "--min_num_consistent 0")
else()
  message(FATAL_ERROR "unknown CASE ${CASE}")
endif()

# ctest `report_in_browser`: dispmvs_colmap writes the run report of the
# example, and a real headless browser (Debian's Chromium) loads it: the page
# parses to the end, shows every picture the report embedded, logs no
# failed resource or script error, and renders to a non-blank screenshot
# (kept as WORK_DIR/report.png to look at).
#   cmake -DCOLMAP=<dispmvs_colmap> -DMAKE_EXAMPLE=<dispmvs_make_example>
#         -DCHROMIUM=<chromium> -DWORK_DIR=<scratch> -P report_browser_test.cmake

file(REMOVE_RECURSE "${WORK_DIR}")
file(MAKE_DIRECTORY "${WORK_DIR}")
set(ws "${WORK_DIR}/ws")
execute_process(COMMAND "${MAKE_EXAMPLE}" --output_path "${ws}" --seed 1
  RESULT_VARIABLE status OUTPUT_QUIET)
execute_process(COMMAND "${COLMAP}" --workspace_path "${ws}" --max_image_size 64 --threads 1
  RESULT_VARIABLE status OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT status EQUAL 0 OR NOT EXISTS "${ws}/dispmvs_report.html")
  message(FATAL_ERROR "dispmvs_colmap did not write its report (${status}):\n${out}${err}")
endif()
file(READ "${ws}/dispmvs_report.html" html)
string(REGEX MATCHALL "<img " written "${html}")
list(LENGTH written num_written)

set(browser "${CHROMIUM}" --headless --no-sandbox --disable-gpu --hide-scrollbars
            --user-data-dir=${WORK_DIR}/profile --enable-logging=stderr --v=0)
execute_process(COMMAND ${browser} --dump-dom "file://${ws}/dispmvs_report.html"
  RESULT_VARIABLE status OUTPUT_VARIABLE dom ERROR_VARIABLE log TIMEOUT 120)
if(NOT status EQUAL 0)
  message(FATAL_ERROR "chromium --dump-dom failed (${status}):\n${log}")
endif()
string(REGEX MATCHALL "<img " shown "${dom}")
list(LENGTH shown num_shown)
if(NOT num_shown EQUAL num_written OR num_written LESS 40)
  message(FATAL_ERROR "the report embeds ${num_written} pictures, the browser shows ${num_shown}")
endif()
if(NOT dom MATCHES "</table>" OR NOT dom MATCHES "</body></html>[ \n]*$")
  message(FATAL_ERROR "the page did not load to its end:\n${dom}")
endif()
if(log MATCHES "Uncaught|Failed to load resource|ERR_INVALID_URL|CONSOLE")
  message(FATAL_ERROR "the browser reported errors:\n${log}")
endif()

execute_process(COMMAND ${browser} --window-size=1300,1200 --screenshot=${WORK_DIR}/report.png
                        "file://${ws}/dispmvs_report.html"
  RESULT_VARIABLE status OUTPUT_QUIET ERROR_VARIABLE log TIMEOUT 120)
if(NOT status EQUAL 0 OR NOT EXISTS "${WORK_DIR}/report.png")
  message(FATAL_ERROR "chromium --screenshot failed (${status}):\n${log}")
endif()
file(SIZE "${WORK_DIR}/report.png" bytes)
# A blank 1300x1200 page compresses to a few KB; pictures make it far larger.
if(bytes LESS 100000)
  message(FATAL_ERROR "the screenshot is nearly blank (${bytes} bytes)")
endif()
message(STATUS "${num_shown} pictures shown; screenshot ${WORK_DIR}/report.png (${bytes} bytes)")

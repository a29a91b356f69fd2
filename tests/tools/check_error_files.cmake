# Errors name the file they are about (docs/robustness.md, "Errors"): the
# tools print `tool: ERROR '<file>': <detail>` from the file a dsm::Error
# carries, with standard input named '<stdin>' rather than the temporary copy
# it is read through.
#
#   cmake -DCHECK=<check> -DDSM_INFO=<dsm-info> -DDSM_MERGE=<dsm-merge> -DDSM_LOOKUP=<dsm-lookup>
#         -DDSM_CONVERT=<dsm-convert> -DMAKE_SAMPLE_MAP=<make_sample_map> -DWORK_DIR=<fresh dir>
#         -P check_error_files.cmake
#
# Checks: merge_damaged_input merge_output convert_damaged_stdin convert_output lookup_damaged_stdin
#         info_damaged_stdin.
cmake_minimum_required(VERSION 3.25)

foreach(var CHECK DSM_INFO DSM_MERGE DSM_LOOKUP DSM_CONVERT MAKE_SAMPLE_MAP WORK_DIR)
  if(NOT DEFINED ${var})
    message(FATAL_ERROR "check_error_files.cmake: -D${var}=... is required")
  endif()
endforeach()

include("${CMAKE_CURRENT_LIST_DIR}/check_common.cmake")

function(run program label)
  run_tool("${program}" "${label}" ${ARGN})
endfunction()

# run_with_input(input program label args...): the tool with `input` on standard input.
function(run_with_input input program label)
  execute_process(COMMAND ${program} ${ARGN} INPUT_FILE "${input}"
    RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  set(RC "${rc}" PARENT_SCOPE)
  set(OUT "${out}" PARENT_SCOPE)
  set(ERR "${err}" PARENT_SCOPE)
  set(LAST_COMMAND "${label} ${ARGN} < ${input}" PARENT_SCOPE)
endfunction()

# The one line on standard error names standard input, never its copy.
function(expect_stdin_error_line tool detail)
  expect_rc(1)
  expect_error_line("${tool}: ERROR '<stdin>': ${detail}")
  string(FIND "${ERR}" "/proc/self/fd" at)
  if(NOT at EQUAL -1)
    fail("expected standard input to be named '<stdin>', not its temporary copy")
  endif()
endfunction()

file(REMOVE_RECURSE "${WORK_DIR}")
file(MAKE_DIRECTORY "${WORK_DIR}")
set(SAMPLE "${WORK_DIR}/sample.dsm")
set(DAMAGED "${WORK_DIR}/damaged.dsm")
execute_process(COMMAND ${MAKE_SAMPLE_MAP} "${SAMPLE}" RESULT_VARIABLE rc ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "make_sample_map failed (${rc}): ${err}")
endif()
execute_process(COMMAND ${MAKE_SAMPLE_MAP} --corrupt "${SAMPLE}" "${DAMAGED}" RESULT_VARIABLE rc ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "make_sample_map --corrupt failed (${rc}): ${err}")
endif()
set(OUTPUT "${WORK_DIR}/out.dsm")

if(CHECK STREQUAL "merge_damaged_input")
  # The second input opens but one of its tiles cannot be read: the error is about it.
  run("${DSM_MERGE}" dsm-merge "${SAMPLE}" "${DAMAGED}" -o "${OUTPUT}")
  expect_rc(1)
  expect_error_line("dsm-merge: ERROR '${DAMAGED}': level 0 tile ")
  expect_no_file("${OUTPUT}")

elseif(CHECK STREQUAL "merge_output")
  # An output that cannot be written is named, not an input.
  run("${DSM_MERGE}" dsm-merge "${SAMPLE}" "${SAMPLE}" -o "${WORK_DIR}/none/out.dsm")
  expect_rc(1)
  expect_error_line("dsm-merge: ERROR '${WORK_DIR}/none/out.dsm': cannot write in the directory")

elseif(CHECK STREQUAL "convert_damaged_stdin")
  # The export names the pixel it was converting, then the tile that failed.
  run_with_input("${DAMAGED}" "${DSM_CONVERT}" dsm-convert - "${WORK_DIR}/out.exr")
  expect_stdin_error_line(dsm-convert "level 0 pixel ")
  expect_contains(ERR "'<stdin>' level 0 tile ")
  expect_no_file("${WORK_DIR}/out.exr")
  # A map that is not an EXR, given as the EXR to import.
  run_with_input("${SAMPLE}" "${DSM_CONVERT}" dsm-convert - "${OUTPUT}")
  expect_stdin_error_line(dsm-convert "not an OpenEXR file")
  expect_no_file("${OUTPUT}")

elseif(CHECK STREQUAL "convert_output")
  run("${DSM_CONVERT}" dsm-convert "${SAMPLE}" "${WORK_DIR}/none/out.exr")
  expect_rc(1)
  expect_error_line("dsm-convert: ERROR '${WORK_DIR}/none/out.exr': cannot write in the directory")

elseif(CHECK STREQUAL "lookup_damaged_stdin")
  # Every pixel centre of level 0 (48 x 32) in raster space reaches the damaged tile.
  set(queries "")
  foreach(y RANGE 0 31)
    foreach(x RANGE 0 47)
      string(APPEND queries "${x}.5 ${y}.5 100\n")
    endforeach()
  endforeach()
  file(WRITE "${WORK_DIR}/queries.txt" "${queries}")
  run_with_input("${DAMAGED}" "${DSM_LOOKUP}" dsm-lookup - -s raster -l 0 --input "${WORK_DIR}/queries.txt")
  expect_stdin_error_line(dsm-lookup "level 0 tile ")

elseif(CHECK STREQUAL "info_damaged_stdin")
  run_with_input("${DAMAGED}" "${DSM_INFO}" dsm-info --verify -)
  expect_stdin_error_line(dsm-info "level 0 tile ")

else()
  message(FATAL_ERROR "check_error_files.cmake: unknown CHECK '${CHECK}'")
endif()

# Runs dsm-merge (with dsm-build for its inputs) and checks one behaviour
# (docs/dsm-merge.md).
#
#   cmake -DCHECK=<check> -DDSM_MERGE=<dsm-merge> -DDSM_BUILD=<dsm-build> -DDSM_INFO=<dsm-info>
#         -DEXAMPLES_DIR=<examples/> -DWORK_DIR=<fresh dir> -DVERSION=<project version>
#         -P check_dsm_merge.cmake
#
# Checks: stitch2 stitch3 product product_layers overlap hole mismatch help version usage missing.
# Builds use examples/leaves.json at 48 x 40 (tiles of 16) with 4 samples per pixel.
cmake_minimum_required(VERSION 3.25)

foreach(var CHECK DSM_MERGE DSM_BUILD DSM_INFO EXAMPLES_DIR WORK_DIR VERSION)
  if(NOT DEFINED ${var})
    message(FATAL_ERROR "check_dsm_merge.cmake: -D${var}=... is required")
  endif()
endforeach()

include("${CMAKE_CURRENT_LIST_DIR}/check_common.cmake")

function(run)
  run_tool("${DSM_MERGE}" dsm-merge ${ARGN})
endfunction()

# build(name args...): dsm-build of the example scene into WORK_DIR/name.dsm.
function(build name)
  execute_process(COMMAND ${DSM_BUILD} "${EXAMPLES_DIR}/leaves.json" -o "${WORK_DIR}/${name}.dsm"
                          -r 48x40 --spp 4 -t 16 -j 1 -q ${ARGN}
    RESULT_VARIABLE rc ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "dsm-build ${name} failed (${rc}): ${err}")
  endif()
endfunction()

function(expect_one_error_line prefix)
  expect_error_line("${prefix}")
endfunction()

function(expect_same_bytes a b)
  execute_process(COMMAND ${CMAKE_COMMAND} -E compare_files "${a}" "${b}" RESULT_VARIABLE different)
  if(different)
    fail("expected '${a}' and '${b}' to be identical")
  endif()
endfunction()

function(expect_valid_map path)
  execute_process(COMMAND ${DSM_INFO} --verify "${path}"
    RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "dsm-info --verify '${path}' failed (${rc}):\n${out}\n${err}")
  endif()
endfunction()

file(REMOVE_RECURSE "${WORK_DIR}")
file(MAKE_DIRECTORY "${WORK_DIR}")
set(OUTPUT_MAP "${WORK_DIR}/out.dsm")

if(CHECK STREQUAL "stitch2")
  # Two parts split on a tile boundary, with counts and zlib level 3 (found
  # from the parts' tiles).
  build(full --counts -z 3)
  build(left --counts -z 3 --region 0,0,16,40)
  build(right --counts -z 3 --region 16,0,48,40)
  run(--mode stitch "${WORK_DIR}/right.dsm" "${WORK_DIR}/left.dsm" -o "${OUTPUT_MAP}")
  expect_rc(0)
  expect_contains(OUT "wrote '${OUTPUT_MAP}' (stitch of 2 maps)")
  expect_same_bytes("${OUTPUT_MAP}" "${WORK_DIR}/full.dsm")

elseif(CHECK STREQUAL "stitch3")
  # Three parts not aligned to tiles: a tile takes pixels from several parts.
  build(full)
  build(a --region 0,0,21,40)
  build(b --region 21,0,48,17)
  build(c --region 21,17,48,40)
  run(--mode stitch "${WORK_DIR}/b.dsm" "${WORK_DIR}/c.dsm" "${WORK_DIR}/a.dsm" --output "${OUTPUT_MAP}" -q)
  expect_rc(0)
  expect_empty(OUT)
  expect_same_bytes("${OUTPUT_MAP}" "${WORK_DIR}/full.dsm")

elseif(CHECK STREQUAL "product")
  build(one)
  build(two --seed 7)
  run("${WORK_DIR}/one.dsm" "${WORK_DIR}/two.dsm" -o "${OUTPUT_MAP}" --tolerance 0.05)
  expect_rc(0)
  expect_contains(OUT "(product of 2 maps)")
  expect_contains(OUT "error bound")
  expect_valid_map("${OUTPUT_MAP}")
  execute_process(COMMAND ${DSM_INFO} --json "${OUTPUT_MAP}" OUTPUT_VARIABLE json RESULT_VARIABLE rc)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "dsm-info --json failed")
  endif()
  string(JSON metadata ERROR_VARIABLE error GET "${json}" metadata)
  if(error)
    message(FATAL_ERROR "dsm-info --json has no metadata: ${error}\n${json}")
  endif()
  string(FIND "${metadata}" "\"mode\"" at_mode)
  string(FIND "${metadata}" "input_error_bound" at_bound)
  if(at_mode EQUAL -1 OR at_bound EQUAL -1)
    message(FATAL_ERROR "the merged map's metadata lacks merge.mode or merge.input_error_bound:\n${metadata}")
  endif()

elseif(CHECK STREQUAL "product_layers")
  # Layers are kept when every input has them (spec/merge.md, "Layers").
  build(one -l 3)
  build(two -l 3 --seed 7)
  build(flat)
  run("${WORK_DIR}/one.dsm" "${WORK_DIR}/two.dsm" -o "${OUTPUT_MAP}")
  expect_rc(0)
  expect_contains(OUT "3 channels, 3 layers,")
  expect_valid_map("${OUTPUT_MAP}")
  execute_process(COMMAND ${DSM_INFO} "${OUTPUT_MAP}" OUTPUT_VARIABLE info RESULT_VARIABLE rc)
  expect_matches(info "MTSM layers +3")
  expect_contains(info "restarted from the inputs' layers")
  run("${WORK_DIR}/one.dsm" "${WORK_DIR}/flat.dsm" -o "${WORK_DIR}/single.dsm")
  expect_rc(0)
  if(OUT MATCHES "channels, [0-9]+ layers")
    fail("a product with a one-layer input has one layer, yet the summary says:\n${OUT}")
  endif()
  execute_process(COMMAND ${DSM_INFO} "${WORK_DIR}/single.dsm" OUTPUT_VARIABLE info RESULT_VARIABLE rc)
  expect_matches(info "MTSM layers +1")
  expect_contains(info "light-centre product only")

elseif(CHECK STREQUAL "overlap")
  build(left --region 0,0,30,40)
  build(right --region 20,0,48,40)
  run(--mode stitch "${WORK_DIR}/left.dsm" "${WORK_DIR}/right.dsm" -o "${OUTPUT_MAP}")
  expect_rc(1)
  expect_one_error_line("dsm-merge: ERROR: 1 pair of regions overlap: ")
  expect_contains(ERR "region 0,0,30,40 and '${WORK_DIR}/right.dsm' region 20,0,48,40 share 20,0,30,40")
  expect_no_file("${OUTPUT_MAP}")

elseif(CHECK STREQUAL "hole")
  build(left --region 0,0,20,40)
  build(right --region 30,0,48,40)
  run(--mode stitch "${WORK_DIR}/left.dsm" "${WORK_DIR}/right.dsm" -o "${OUTPUT_MAP}")
  expect_rc(1)
  expect_one_error_line("dsm-merge: ERROR: the regions leave 400 of 1920 pixels uncovered, in 1 rectangle")
  expect_contains(ERR "20,0,30,40")
  expect_no_file("${OUTPUT_MAP}")

elseif(CHECK STREQUAL "mismatch")
  build(one)
  execute_process(COMMAND ${DSM_BUILD} "${EXAMPLES_DIR}/leaves.json" -o "${WORK_DIR}/small.dsm"
                          -r 32x40 --spp 4 -t 16 -j 1 -q RESULT_VARIABLE rc)
  run("${WORK_DIR}/one.dsm" "${WORK_DIR}/small.dsm" -o "${OUTPUT_MAP}")
  expect_rc(1)
  expect_one_error_line("dsm-merge: ERROR '${WORK_DIR}/small.dsm': the size is 32x40 but 48x40 in '${WORK_DIR}/one.dsm'")
  expect_no_file("${OUTPUT_MAP}")

elseif(CHECK STREQUAL "help")
  run(--help)
  expect_rc(0)
  expect_contains(OUT "--mode")
  expect_contains(OUT "--tolerance")
  expect_empty(ERR)

elseif(CHECK STREQUAL "version")
  run(--version)
  expect_rc(0)
  expect_contains(OUT "dsm-merge ${VERSION}")

elseif(CHECK STREQUAL "usage")
  run("${WORK_DIR}/x.dsm")
  expect_rc(2)
  expect_contains(ERR "--output")
  run("${WORK_DIR}/x.dsm" -o "${OUTPUT_MAP}" --mode sum)
  expect_rc(2)
  run("${WORK_DIR}/x.dsm" -o "${OUTPUT_MAP}" --mode stitch --tolerance 0.1)
  expect_rc(2)
  expect_contains(ERR "product only")
  run("${WORK_DIR}/x.dsm" -o "${OUTPUT_MAP}" --tolerance -1)
  expect_rc(2)
  expect_no_file("${OUTPUT_MAP}")

elseif(CHECK STREQUAL "missing")
  run("${WORK_DIR}/missing.dsm" -o "${OUTPUT_MAP}")
  expect_rc(1)
  expect_one_error_line("dsm-merge: ERROR '${WORK_DIR}/missing.dsm': ")
  expect_no_file("${OUTPUT_MAP}")

else()
  message(FATAL_ERROR "check_dsm_merge.cmake: unknown CHECK '${CHECK}'")
endif()

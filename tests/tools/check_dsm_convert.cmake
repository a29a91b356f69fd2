# Runs dsm-convert, and the third-party OpenEXR tools on its output, for one
# behaviour.
#
#   cmake -DCHECK=<check> -DDSM_CONVERT=<dsm-convert> -DHELPER=<exr_check_helper>
#         -DEXRHEADER=<exrheader> -DEXRINFO=<exrinfo> -DOIIOTOOL=<oiiotool>
#         -DWORK_DIR=<fresh dir> -DVERSION=<project version> -P check_dsm_convert.cmake
#
# Checks: exrheader exrinfo flatten flatten_rgb roundtrip roundtrip_tiled deepen messy
#         no_z stdin help version usage missing
cmake_minimum_required(VERSION 3.25)

foreach(var CHECK DSM_CONVERT HELPER WORK_DIR VERSION)
  if(NOT DEFINED ${var})
    message(FATAL_ERROR "check_dsm_convert.cmake: -D${var}=... is required")
  endif()
endforeach()

include("${CMAKE_CURRENT_LIST_DIR}/check_common.cmake")

function(run)
  run_tool("${DSM_CONVERT}" dsm-convert ${ARGN})
endfunction()
function(helper)
  run_tool("${HELPER}" exr_check_helper ${ARGN})
endfunction()
function(third_party program)
  if(NOT program OR NOT EXISTS "${program}")
    message(FATAL_ERROR "third-party tool not found: '${program}'")
  endif()
  run_tool("${program}" "${program}" ${ARGN})
endfunction()

# The one-line error convention: "dsm-convert: ERROR '<file>': ...".
function(expect_one_error_line file)
  expect_error_line("dsm-convert: ERROR '${file}': ")
endfunction()

file(REMOVE_RECURSE "${WORK_DIR}")
file(MAKE_DIRECTORY "${WORK_DIR}")
set(MAP "${WORK_DIR}/map.dsm")
set(EXR "${WORK_DIR}/map.exr")

macro(export_map kind)
  helper(make-map "${MAP}" ${kind})
  expect_rc(0)
  run("${MAP}" "${EXR}" ${ARGN})
  expect_rc(0)
  expect_contains(OUT "wrote '${EXR}'")
endmacro()

if(CHECK STREQUAL "exrheader")
  export_map(rgb)
  third_party("${EXRHEADER}" "${EXR}")
  expect_rc(0)
  expect_contains(OUT "deepscanline")
  expect_contains(OUT "worldToCamera")
  expect_contains(OUT "worldToNDC")
  expect_contains(OUT "dsm:worldToLight")
  expect_contains(OUT "zip, individual scanlines")
  foreach(channel Z ZBack A AR AG AB R G B)
    expect_matches(OUT "\n +${channel}, 32-bit floating-point")
  endforeach()

elseif(CHECK STREQUAL "exrinfo")
  export_map(mono --tiled --exr-tile-size 16)
  third_party("${EXRINFO}" -v "${EXR}")
  expect_rc(0)
  expect_contains(OUT "deeptile")
  expect_empty(ERR)

elseif(CHECK STREQUAL "flatten" OR CHECK STREQUAL "flatten_rgb")
  if(CHECK STREQUAL "flatten")
    export_map(mono)
    third_party("${OIIOTOOL}" "${EXR}" --flatten -o "${WORK_DIR}/flat.exr")
  else()
    # OpenImageIO 2.4's flatten composites every channel, A included, with the
    # mean of the accumulated AR, AG, AB instead of each channel's own alpha
    # (spec/exr-interop.md): check A, the mean visibility, on its own.
    export_map(rgb)
    third_party("${OIIOTOOL}" "${EXR}" --ch Z,ZBack,A --flatten -o "${WORK_DIR}/flat.exr")
  endif()
  expect_rc(0)
  helper(flat-alpha "${MAP}" "${WORK_DIR}/flat.exr")
  message(STATUS "${OUT}")
  expect_rc(0)

elseif(CHECK STREQUAL "roundtrip" OR CHECK STREQUAL "roundtrip_tiled")
  set(options)
  if(CHECK STREQUAL "roundtrip_tiled")
    set(options --tiled)
  endif()
  export_map(rgb ${options})
  run("${EXR}" "${WORK_DIR}/back.dsm")
  expect_rc(0)
  expect_contains(OUT "camera from dsm attributes")
  helper(compare "${MAP}" "${WORK_DIR}/back.dsm" 2)
  message(STATUS "dsm -> exr -> dsm: ${OUT}")
  expect_rc(0)

elseif(CHECK STREQUAL "deepen")
  helper(make-flat "${WORK_DIR}/flat.exr")
  expect_rc(0)
  third_party("${OIIOTOOL}" "${WORK_DIR}/flat.exr" --deepen -o "${WORK_DIR}/deep.exr")
  expect_rc(0)
  run("${WORK_DIR}/deep.exr" "${WORK_DIR}/deep.dsm")
  expect_rc(1)  # oiiotool records no camera
  expect_one_error_line("${WORK_DIR}/deep.exr")
  expect_contains(ERR "no light camera")
  run("${WORK_DIR}/deep.exr" "${WORK_DIR}/deep.dsm" --fov 60)
  expect_rc(0)
  helper(check-deepened "${WORK_DIR}/flat.exr" "${WORK_DIR}/deep.dsm")
  message(STATUS "${OUT}")
  expect_rc(0)

elseif(CHECK STREQUAL "messy")
  helper(make-messy "${WORK_DIR}/messy.exr")
  expect_rc(0)
  run("${WORK_DIR}/messy.exr" "${WORK_DIR}/messy.dsm" --ortho-width 2)
  expect_rc(0)
  helper(check-messy "${WORK_DIR}/messy.dsm")
  message(STATUS "${OUT}")
  expect_rc(0)

elseif(CHECK STREQUAL "no_z")
  helper(make-no-z "${WORK_DIR}/noz.exr")
  expect_rc(0)
  third_party("${EXRHEADER}" "${WORK_DIR}/noz.exr")  # a valid deep image for OpenEXR
  expect_rc(0)
  run("${WORK_DIR}/noz.exr" "${WORK_DIR}/noz.dsm" --fov 60)
  expect_rc(1)
  expect_one_error_line("${WORK_DIR}/noz.exr")
  expect_contains(ERR "no Z channel")
  if(EXISTS "${WORK_DIR}/noz.dsm")
    fail("a failed conversion left an output file")
  endif()

elseif(CHECK STREQUAL "stdin")
  export_map(mono)
  execute_process(COMMAND "${DSM_CONVERT}" - "${WORK_DIR}/back.dsm"
    INPUT_FILE "${EXR}" RESULT_VARIABLE RC OUTPUT_VARIABLE OUT ERROR_VARIABLE ERR)
  set(LAST_COMMAND "dsm-convert - back.dsm < map.exr")
  expect_rc(0)
  execute_process(COMMAND "${DSM_CONVERT}" - "${WORK_DIR}/x.dsm"
    INPUT_FILE "${MAP}" RESULT_VARIABLE RC OUTPUT_VARIABLE OUT ERROR_VARIABLE ERR)
  set(LAST_COMMAND "dsm-convert - x.dsm < map.dsm")
  expect_rc(1)
  expect_one_error_line("<stdin>")
  expect_contains(ERR "not an OpenEXR file")

elseif(CHECK STREQUAL "help")
  run(--help)
  expect_rc(0)
  expect_contains(OUT "--max-deviation")
  expect_contains(OUT "--camera-from")
  expect_empty(ERR)

elseif(CHECK STREQUAL "version")
  run(--version)
  expect_rc(0)
  expect_contains(OUT "dsm-convert ${VERSION}")

elseif(CHECK STREQUAL "usage")
  foreach(args "a.dsm;b.png" "a.exr;b.exr" "a.dsm;b.exr;--tolerance;0.1" "a.exr;b.dsm;--tiled"
               "a.exr;b.dsm;--fov;60;--ortho-width;2" "a.dsm" "a.dsm;b.exr;--max-deviation;-1" "a.exr;b.dsm;--fov;180")
    run(${args})
    expect_rc(2)
    expect_contains(ERR "dsm-convert: ")
  endforeach()

elseif(CHECK STREQUAL "missing")
  run("${WORK_DIR}/nothing.dsm" "${WORK_DIR}/out.exr")
  expect_rc(1)
  expect_one_error_line("${WORK_DIR}/nothing.dsm")
  run("${WORK_DIR}/nothing.exr" "${WORK_DIR}/out.dsm")
  expect_rc(1)
  expect_one_error_line("${WORK_DIR}/nothing.exr")
  file(GLOB left "${WORK_DIR}/*")
  if(left)
    fail("failed conversions left files: ${left}")
  endif()

else()
  message(FATAL_ERROR "unknown CHECK '${CHECK}'")
endif()

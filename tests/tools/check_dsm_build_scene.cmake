# Runs dsm-build on hostile scenes and checks that each is refused at once with
# one short line (spec/scene.md §1.1-1.3, docs/robustness.md "Scenes").
#
#   cmake -DCHECK=<check> -DDSM_BUILD=<dsm-build> -DWORK_DIR=<fresh dir> -P check_dsm_build_scene.cmake
#
# Checks: endless_stdin max_scene_mb max_scene_mb_usage deep_nesting long_key hairball_curl tiny_step
# vdb_module (with -DWITH_OPENVDB=ON|OFF).
# Every run has a timeout: before these limits some of them never ended.
cmake_minimum_required(VERSION 3.25)

foreach(var CHECK DSM_BUILD WORK_DIR)
  if(NOT DEFINED ${var})
    message(FATAL_ERROR "check_dsm_build_scene.cmake: -D${var}=... is required")
  endif()
endforeach()

include("${CMAKE_CURRENT_LIST_DIR}/check_common.cmake")

file(REMOVE_RECURSE "${WORK_DIR}")
file(MAKE_DIRECTORY "${WORK_DIR}")
set(MAP "${WORK_DIR}/out.dsm")
set(SCENE "${WORK_DIR}/scene.json")
set(LIGHT [=["light": {"type": "spot", "position": [0, 0, -5], "direction": [0, 0, 1], "resolution": 8}]=])

# build(input args...): dsm-build with standard input from `input`, stopped
# after 30 seconds, with the environment variables BUILD_ENV lists
# (NAME=value...) when it is set; sets RC, OUT, ERR and LAST_COMMAND.
function(build input)
  set(env)
  if(BUILD_ENV)
    set(env ${CMAKE_COMMAND} -E env ${BUILD_ENV})
  endif()
  execute_process(COMMAND ${env} ${DSM_BUILD} ${ARGN} INPUT_FILE "${input}" TIMEOUT 30
    RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  set(RC "${rc}" PARENT_SCOPE)
  set(OUT "${out}" PARENT_SCOPE)
  set(ERR "${err}" PARENT_SCOPE)
  set(LAST_COMMAND "${BUILD_ENV} dsm-build ${ARGN} < ${input}" PARENT_SCOPE)
endfunction()

# A refused scene: status 1, one line starting with `prefix` and at most 600
# bytes long, and no map.
function(expect_refused prefix)
  expect_rc(1)
  expect_empty(OUT)
  expect_error_line("${prefix}")
  string(LENGTH "${ERR}" length)
  if(length GREATER 600)
    fail("the error line is ${length} bytes long")
  endif()
  if(EXISTS "${MAP}")
    fail("a map was written")
  endif()
endfunction()

if(CHECK STREQUAL "endless_stdin")
  # `dsm-build - < /dev/zero` once read into memory without end.
  build(/dev/zero - -o "${MAP}" -q --max-scene-mb 1)
  expect_refused("dsm-build: ERROR scene '<stdin>': is more than the limit of 1048576 bytes")

elseif(CHECK STREQUAL "max_scene_mb")
  # A 1.5 MiB scene (a long comment) is refused under a 1 MiB limit, read under 2 MiB.
  string(REPEAT "x" 1572864 comment)
  file(WRITE "${SCENE}" "{\"_comment\": \"${comment}\", ${LIGHT}, \"objects\": []}")
  build(/dev/null "${SCENE}" -o "${MAP}" -q --max-scene-mb 1)
  expect_refused("dsm-build: ERROR scene '${SCENE}': is 1572")
  expect_contains(ERR "bytes, more than the limit of 1048576")
  build(/dev/null "${SCENE}" -o "${MAP}" -q --spp 1 --max-scene-mb 2)
  expect_rc(0)
  build("${SCENE}" - -o "${MAP}.2" -q --max-scene-mb 1)
  expect_rc(1)
  expect_error_line("dsm-build: ERROR scene '<stdin>': is more than the limit of 1048576 bytes")

elseif(CHECK STREQUAL "max_scene_mb_usage")
  foreach(value 0 -1 1048577 1.5 nan)
    build(/dev/null "${SCENE}" -o "${MAP}" --max-scene-mb ${value})
    expect_rc(2)
    expect_error_line("dsm-build: --max-scene-mb: ")
  endforeach()

elseif(CHECK STREQUAL "deep_nesting")
  # 100,000 levels once overflowed the stack while the message was formatted.
  string(REPEAT "[" 100000 open)
  string(REPEAT "]" 100000 close)
  file(WRITE "${SCENE}" "{\"light\": ${open}${close}, \"objects\": []}")
  build(/dev/null "${SCENE}" -o "${MAP}")
  expect_refused("dsm-build: ERROR scene '${SCENE}': /light/0/0/0/")
  expect_contains(ERR ": nested deeper than 64 levels\n")

elseif(CHECK STREQUAL "long_key")
  # A 2 MiB unknown key once gave a 4 MiB line.
  string(REPEAT "k" 2097152 key)
  file(WRITE "${SCENE}" "{${LIGHT}, \"objects\": [{\"type\": \"sphere\", \"radius\": 1, \"${key}\": 1}]}")
  build(/dev/null "${SCENE}" -o "${MAP}")
  expect_refused("dsm-build: ERROR scene '${SCENE}': /objects/0/kkkk")
  expect_contains(ERR "...: unknown key \"kkkk")

elseif(CHECK STREQUAL "hairball_curl")
  # A curl of 1e160 once made the hair generator loop forever.
  file(WRITE "${SCENE}" "{${LIGHT}, \"objects\": [{\"type\": \"hair\", \"hairball\": {\"count\": 3, \"curl\": 1e160}}]}")
  build(/dev/null "${SCENE}" -o "${MAP}")
  expect_refused("dsm-build: ERROR scene '${SCENE}': /objects/0/hairball/curl: expected a number in [0, 1000000], got 1e+160")

elseif(CHECK STREQUAL "tiny_step")
  # A step of 1e-300 once dropped the volume silently (exit 0).
  file(WRITE "${SCENE}" "{${LIGHT}, \"objects\": [{\"type\": \"volume\", \"bounds\": [[-1, -1, -1], [1, 1, 1]],
    \"density\": {\"type\": \"homogeneous\", \"value\": 1}, \"step\": 1e-300}]}")
  build(/dev/null "${SCENE}" -o "${MAP}")
  expect_refused("dsm-build: ERROR scene '${SCENE}': /objects/0/step: expected a number in [1e-12, 1e+12], got 1e-300")

elseif(CHECK STREQUAL "vdb_module")
  # OpenVDB is loaded only when a scene reads a VDB file, from a module of its
  # own (libdsm/build/src/vdb_module.h): dsm-build does not link it, a missing
  # or broken module is a one-line error naming the file, and the module
  # built beside dsm-build is found without help. The grid file's bytes are not
  # a VDB file, so even the module found refuses it, after reading it.
  set(grid "${WORK_DIR}/cloud.vdb")
  file(WRITE "${grid}" "not a vdb file at all")
  file(WRITE "${SCENE}" "{${LIGHT}, \"objects\": [{\"type\": \"volume\", \"bounds\": [[-1, -1, -1], [1, 1, 1]],
    \"density\": {\"type\": \"vdb\", \"file\": \"cloud.vdb\"}}]}")
  find_program(READELF readelf)
  if(READELF)
    execute_process(COMMAND ${READELF} -d ${DSM_BUILD} OUTPUT_VARIABLE dynamic RESULT_VARIABLE rc)
    if(NOT rc EQUAL 0 OR NOT dynamic MATCHES "NEEDED")
      fail("readelf -d ${DSM_BUILD} did not list its libraries")
    endif()
    if(dynamic MATCHES "openvdb")
      fail("dsm-build links OpenVDB:\n${dynamic}")
    endif()
  endif()
  if(NOT WITH_OPENVDB)
    build(/dev/null "${SCENE}" -o "${MAP}")
    expect_refused("dsm-build: ERROR ")
    expect_contains(ERR "VDB file '${grid}': this libdsm was built without OpenVDB")
    return()
  endif()
  set(BUILD_ENV "DSM_VDB_MODULE=${WORK_DIR}/missing/libdsm_vdb.so")
  build(/dev/null "${SCENE}" -o "${MAP}")
  expect_refused("dsm-build: ERROR ")
  expect_contains(ERR "VDB file '${grid}': the OpenVDB module libdsm_vdb.so was not found (looked for ${WORK_DIR}/missing/libdsm_vdb.so; DSM_VDB_MODULE may name it)")
  set(BUILD_ENV "DSM_VDB_MODULE=${SCENE}")
  build(/dev/null "${SCENE}" -o "${MAP}")
  expect_refused("dsm-build: ERROR ")
  expect_contains(ERR "VDB file '${grid}': the OpenVDB module '${SCENE}' does not load: ")
  unset(BUILD_ENV)
  build(/dev/null "${SCENE}" -o "${MAP}")
  expect_refused("dsm-build: ERROR ")
  expect_contains(ERR "VDB file '${grid}': ")
  if(ERR MATCHES "OpenVDB module")
    fail("the module built beside dsm-build was not found")
  endif()

else()
  message(FATAL_ERROR "check_dsm_build_scene.cmake: unknown CHECK '${CHECK}'")
endif()

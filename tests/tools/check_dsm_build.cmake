# Runs dsm-build and checks one behaviour (docs/dsm-build.md).
#
#   cmake -DCHECK=<check> -DDSM_BUILD=<dsm-build> -DDSM_INFO=<dsm-info>
#         -DEXAMPLES_DIR=<examples/> -DWORK_DIR=<fresh dir> -DVERSION=<project version>
#         -P check_dsm_build.cmake
#
# Checks: build area_light_defaults deterministic stdin help version bad_value missing json_error build_error.
# Builds use examples/leaves.json (an RGB map) at 64 x 64 with 4 samples per pixel.
cmake_minimum_required(VERSION 3.25)

foreach(var CHECK DSM_BUILD DSM_INFO EXAMPLES_DIR WORK_DIR VERSION)
  if(NOT DEFINED ${var})
    message(FATAL_ERROR "check_dsm_build.cmake: -D${var}=... is required")
  endif()
endforeach()

include("${CMAKE_CURRENT_LIST_DIR}/check_common.cmake")

# run(args...): runs dsm-build; sets RC, OUT, ERR and LAST_COMMAND in the caller.
function(run)
  run_tool("${DSM_BUILD}" dsm-build ${ARGN})
endfunction()

# Exactly one line on stderr, starting with the given prefix.
function(expect_one_error_line prefix)
  expect_error_line("${prefix}")
endfunction()

# dsm-info --verify accepts the file.
function(expect_valid_map path)
  execute_process(COMMAND ${DSM_INFO} --verify "${path}"
    RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0 OR NOT out STREQUAL "${path}: OK\n")
    message(FATAL_ERROR "dsm-info --verify '${path}' failed (${rc}):\n${out}\n${err}")
  endif()
endfunction()

# map_json(path out): dsm-info --json of the map, into `out` in the caller.
function(map_json path out)
  execute_process(COMMAND ${DSM_INFO} --json "${path}" RESULT_VARIABLE rc OUTPUT_VARIABLE json)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "dsm-info --json '${path}' failed")
  endif()
  set(${out} "${json}" PARENT_SCOPE)
endfunction()

file(REMOVE_RECURSE "${WORK_DIR}")
file(MAKE_DIRECTORY "${WORK_DIR}")
set(SCENE "${EXAMPLES_DIR}/leaves.json")
set(MAP "${WORK_DIR}/leaves.dsm")

if(CHECK STREQUAL "build")
  set(stats "${WORK_DIR}/stats.json")
  run("${SCENE}" -o "${MAP}" -r 64 --spp 4 --stats-json "${stats}")
  expect_rc(0)
  # The summary on standard output (progress goes to standard error).
  expect_contains(OUT "dsm-build: wrote '${MAP}'\n")
  expect_matches(OUT "\n  time +[0-9.]+ s wall; thread time: sampling [0-9.]+ s, sweep [0-9.]+ s, compression [0-9.]+ s; writing [0-9.]+ s\n")
  expect_matches(OUT "\n  share +sampling [0-9.]+%, sweep [0-9.]+%, compression [0-9.]+% of thread time\n")
  expect_matches(OUT "\n  samples +[0-9]+ \\([0-9]+ per second of wall time\\)\n")
  expect_matches(OUT "\n  vertices +[0-9.]+ per pixel \\(max [0-9]+\\), tolerance 0\\.125\n")
  expect_matches(OUT "\n  file +[0-9.]+ (B|KiB|MiB|GiB), [0-9.]+x smaller than the raw per-sample data \\([0-9.]+ (B|KiB|MiB|GiB)\\)\n")
  expect_valid_map("${MAP}")
  # What dsm-info reads back.
  map_json("${MAP}" info)
  json_expect("${info}" 64 width)
  json_expect("${info}" 64 height)
  json_expect("${info}" 3 channels)
  json_expect("${info}" perspective camera projection)
  json_expect("${info}" gaussian filter type)
  string(JSON levels LENGTH "${info}" levels)
  if(NOT levels EQUAL 7)
    fail("expected a full pyramid of 7 levels, got ${levels}")
  endif()
  json_expect("${info}" 4 metadata settings spp)
  json_expect("${info}" 64 metadata settings resolution 0)
  json_expect("${info}" 1 metadata settings seed)
  json_expect("${info}" libdsm metadata software)
  json_expect("${info}" "${SCENE}" metadata scene)
  # The statistics file: every documented key, with its type.
  if(NOT EXISTS "${stats}")
    fail("no --stats-json file")
  endif()
  file(READ "${stats}" s)
  json_expect("${s}" "${MAP}" output)
  foreach(key wall_seconds sampling_seconds crossing_seconds sweep_seconds compression_seconds writing_seconds samples pixels
              vertices mean_vertices_per_pixel max_vertices_per_pixel tolerance file_bytes raw_bytes sample_vertices)
    json_expect_type("${s}" NUMBER ${key})
  endforeach()
  string(JSON keys LENGTH "${s}")
  if(NOT keys EQUAL 16)
    fail("expected 16 keys in the statistics, got ${keys}")
  endif()
  json_expect("${s}" 4096 pixels)
  json_expect("${s}" 0.125 tolerance)
  file(SIZE "${MAP}" size)
  json_expect("${s}" "${size}" file_bytes)
  string(JSON samples GET "${s}" samples)
  if(samples LESS 16384)
    fail("expected at least 64 * 64 * 4 samples, got ${samples}")
  endif()
  string(JSON vertices GET "${s}" vertices)
  string(JSON levelVertices GET "${info}" levels 0 vertices)
  if(NOT vertices EQUAL levelVertices)
    fail("--stats-json vertices ${vertices} but level 0 holds ${levelVertices}")
  endif()

elseif(CHECK STREQUAL "area_light_defaults")
  # A scene with an area light gets the soft-shadow defaults (2 layers with
  # counts, a box of width 1, 0.125 / sqrt(spp), 0.125 at 1 sample per pixel); options given are kept.
  set(area "${EXAMPLES_DIR}/area-light.json")
  foreach(case IN ITEMS "auto;2;ON;box;1.0;0.125" "given;1;OFF;gaussian;2.0;0.25")  # CMake reads JSON booleans as ON/OFF
    list(POP_FRONT case how layers counts filter width tolerance)
    if(how STREQUAL "auto")
      run("${area}" -o "${MAP}" -r 8 --spp 1 -q)
    else()
      run("${area}" -o "${MAP}" -r 8 --spp 1 -q --mtsm-layers 1 --filter gaussian --tolerance 0.25)
    endif()
    expect_rc(0)
    map_json("${MAP}" info)
    json_expect("${info}" ${layers} max_layers)
    json_expect("${info}" ${counts} has_counts)
    json_expect("${info}" ${filter} filter type)
    json_expect("${info}" ${width} filter width)
    json_expect("${info}" ${tolerance} levels 0 tolerance)
    json_expect("${info}" ${layers} metadata settings mtsm_layers)
  endforeach()

elseif(CHECK STREQUAL "level_tolerance_factor")
  # Each coarser level's tolerance is the previous one's times the factor, and
  # its stated bound adds that tolerance: 0.5 (the default) keeps every bound
  # within 2 x tolerance, 1 lets it grow by one tolerance per level. (CMake's
  # EQUAL compares as doubles; halving 0.1 is exact.)
  foreach(case IN ITEMS "default;0.1;0.05;0.025" "1;0.1;0.1;0.1")
    list(POP_FRONT case factor)
    if(factor STREQUAL "default")
      run("${SCENE}" -o "${MAP}" -r 32 --spp 1 -e 0.1 -q)
    else()
      run("${SCENE}" -o "${MAP}" -r 32 --spp 1 -e 0.1 -q --level-tolerance-factor ${factor})
    endif()
    expect_rc(0)
    map_json("${MAP}" info)
    set(level 0)
    foreach(expected IN LISTS case)
      string(JSON tolerance GET "${info}" levels ${level} tolerance)
      if(NOT tolerance EQUAL expected)
        fail("factor ${factor}: level ${level} tolerance ${tolerance}, expected ${expected}")
      endif()
      math(EXPR level "${level} + 1")
    endforeach()
    string(JSON stated GET "${info}" levels 2 error_bound)
    if(factor STREQUAL "1" AND NOT (stated GREATER 0.2999999 AND stated LESS 0.3000001))
      fail("factor 1: level 2 states the bound ${stated}, expected 3 x 0.1")
    endif()
    if(factor STREQUAL "default" AND NOT (stated GREATER 0.1749999 AND stated LESS 0.1750001))
      fail("default factor: level 2 states the bound ${stated}, expected 0.1 + 0.05 + 0.025")
    endif()
  endforeach()

elseif(CHECK STREQUAL "deterministic")
  # One thread or two, quiet or not: the same bytes. Another seed: other bytes.
  set(one "${WORK_DIR}/one.dsm")
  set(two "${WORK_DIR}/two.dsm")
  set(other "${WORK_DIR}/other.dsm")
  run("${SCENE}" -o "${one}" -r 48 --spp 4 -t 16 -j 1)
  expect_rc(0)
  run("${SCENE}" -o "${two}" -r 48 --spp 4 -t 16 -j 2 -q)
  expect_rc(0)
  expect_empty(OUT)
  expect_empty(ERR)
  run("${SCENE}" -o "${other}" -r 48 --spp 4 -t 16 -j 2 -q --seed 2)
  expect_rc(0)
  file(SHA256 "${one}" a)
  file(SHA256 "${two}" b)
  file(SHA256 "${other}" c)
  if(NOT a STREQUAL b)
    fail("-j 1 and -j 2 gave different files")
  endif()
  if(a STREQUAL c)
    fail("--seed 2 gave the same file as --seed 1")
  endif()

elseif(CHECK STREQUAL "stdin")
  # "-" reads the scene from standard input.
  execute_process(COMMAND ${DSM_BUILD} - -o "${MAP}" -r 16 --spp 1 -q INPUT_FILE "${SCENE}"
    RESULT_VARIABLE RC OUTPUT_VARIABLE OUT ERROR_VARIABLE ERR)
  set(LAST_COMMAND "dsm-build - -o ${MAP} -r 16 --spp 1 -q < ${SCENE}")
  expect_rc(0)
  expect_valid_map("${MAP}")
  # Errors name the scene <stdin>.
  set(bad "${WORK_DIR}/bad.json")
  file(WRITE "${bad}" "{\"light\": {}, \"objects\": []}\n")
  execute_process(COMMAND ${DSM_BUILD} - -o "${MAP}.2" -q INPUT_FILE "${bad}"
    RESULT_VARIABLE RC OUTPUT_VARIABLE OUT ERROR_VARIABLE ERR)
  expect_rc(1)
  expect_one_error_line("dsm-build: ERROR scene '<stdin>': /light: ")
  expect_no_file("${MAP}.2")

elseif(CHECK STREQUAL "help")
  run(--help)
  expect_rc(0)
  expect_empty(ERR)
  expect_contains(OUT "Usage")
  foreach(option --output --resolution --spp --tolerance --filter --filter-width --mip-levels --tile-size
                 --level-tolerance-factor --mtsm-layers --counts --region --threads --seed --zlib-level --quiet --stats-json --version)
    expect_contains(OUT "${option}")
  endforeach()

elseif(CHECK STREQUAL "version")
  run(--version)
  expect_rc(0)
  expect_empty(ERR)
  if(NOT OUT STREQUAL "dsm-build ${VERSION}\n")
    fail("expected 'dsm-build ${VERSION}'")
  endif()

elseif(CHECK STREQUAL "bad_value")
  # Values dsm-build checks itself: status 2, one line, nothing built.
  foreach(args IN ITEMS "--tolerance;abc" "--tolerance;-1" "--region;1,2" "--region;0,0,8,x" "-r;64x" "-r;16x8x"
                        "--mip-levels;0" "--mip-levels;1.5" "--level-tolerance-factor;0" "--level-tolerance-factor;nan" "--spp;0" "--filter-width;0" "--mtsm-layers;0")
    run("${SCENE}" -o "${MAP}" ${args})
    expect_rc(2)
    expect_empty(OUT)
    expect_one_error_line("dsm-build: ")
    expect_no_file("${MAP}")
  endforeach()
  run("${SCENE}" -o "${MAP}" --tolerance abc)
  expect_contains(ERR "--tolerance")
  run("${SCENE}" -o "${MAP}" --region 1,2)
  expect_contains(ERR "--region expects X0,Y0,X1,Y1, got '1,2'")

elseif(CHECK STREQUAL "missing")
  set(missing "${WORK_DIR}/no such scene.json")
  set(stats "${WORK_DIR}/stats.json")
  run("${missing}" -o "${MAP}" --stats-json "${stats}")
  expect_rc(1)
  expect_empty(OUT)
  expect_one_error_line("dsm-build: ERROR scene '${missing}': ")
  expect_no_file("${MAP}")
  expect_no_file("${stats}")

elseif(CHECK STREQUAL "json_error")
  # A value of the wrong kind: the message names the file and the JSON path.
  set(bad "${WORK_DIR}/bad.json")
  file(WRITE "${bad}" [=[{
  "light": {"type": "distant", "position": [0, 0, 5], "direction": [0, 0, -1], "extent": 2},
  "objects": [
    {"type": "quad", "u": [1, 0, 0], "v": [0, 1, 0]},
    {"type": "sphere", "radius": "large"}
  ]
}
]=])
  run("${bad}" -o "${MAP}")
  expect_rc(1)
  expect_empty(OUT)
  expect_one_error_line("dsm-build: ERROR scene '${bad}': /objects/1/radius: ")
  expect_no_file("${MAP}")
  # Invalid JSON: the message names the file, line and column.
  file(WRITE "${bad}" "{\"light\": {\"type\": \"spot\",,}}\n")
  run("${bad}" -o "${MAP}")
  expect_rc(1)
  expect_one_error_line("dsm-build: ERROR scene '${bad}': /light: invalid JSON: ")
  expect_contains(ERR "line 1, column")
  expect_no_file("${MAP}")
  # An existing file is left alone by a failed build.
  file(WRITE "${MAP}" "previous contents")
  run("${bad}" -o "${MAP}")
  expect_rc(1)
  file(READ "${MAP}" contents)
  if(NOT contents STREQUAL "previous contents")
    fail("a failed build changed the existing output file")
  endif()

elseif(CHECK STREQUAL "build_error")
  # Options the library rejects: status 1, one line naming the output, nothing built.
  foreach(args IN ITEMS "--region;0,0,100,100" "--tile-size;3")
    run("${SCENE}" -o "${MAP}" -r 16 ${args})
    expect_rc(1)
    expect_empty(OUT)
    expect_one_error_line("dsm-build: ERROR ")
    expect_contains(ERR "'${MAP}'")
    expect_no_file("${MAP}")
  endforeach()
  # No temporary file is left behind either.
  file(GLOB left "${WORK_DIR}/*")
  if(left)
    fail("files left after failed builds: ${left}")
  endif()

else()
  message(FATAL_ERROR "check_dsm_build.cmake: unknown check '${CHECK}'")
endif()

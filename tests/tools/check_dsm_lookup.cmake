# Runs dsm-lookup and checks one behaviour.
#
#   cmake -DCHECK=<check> -DDSM_LOOKUP=<dsm-lookup> -DMAKE_SAMPLE_MAP=<make_sample_map>
#         -DLOOKUP_REFERENCE=<lookup_reference> [-DPYTHON=<python3>] [-DDSM_BUILD=<dsm-build>]
#         -DWORK_DIR=<fresh dir> -DVERSION=<project version> -P check_dsm_lookup.cmake
#
# Two maps, and for the soft_* checks (--area-light) a third built here:
#  - mono.dsm (lookup_reference --write-mono): 8 x 8, tiles of 4, 2 levels,
#    exact (tolerance 0), orthographic, light = world + (1, -2, 0.5), raster =
#    (lx, 8 - ly). Pixel (i, j): V = 1 up to z = 1, linear down to k/16 at
#    z = 2, then k/16, with k = (5i + 3j + ij) % 16. Its answers are computed
#    here from that formula (all are dyadic fractions, printed exactly by %.9g).
#  - rgb.dsm (make_sample_map): 48 x 32 RGB, perspective, tolerance 0.01.
#    Its answers are compared with lookup_reference, which prints what
#    dsm::LookupContext returns, and at a few pixels with the values
#    make_sample_map writes.
#  - soft.dsm (dsm-build, see build_soft_map): a spot light at height 10
#    looking down, fov 60, area_radius 1, over a plane at height 0 with an
#    opaque square of half-size 1 at height 5; 64 x 64, 16 spp, 2 layers. By
#    similar triangles a receiver on the plane is in the umbra for |x|, |z| < 1
#    (every light ray crosses the square), in the penumbra for 1 < |x| < 3
#    (z = 0), lit beyond. Values are compared with lookup_reference --soft.
cmake_minimum_required(VERSION 3.25)

foreach(var CHECK DSM_LOOKUP MAKE_SAMPLE_MAP LOOKUP_REFERENCE WORK_DIR VERSION)
  if(NOT DEFINED ${var})
    message(FATAL_ERROR "check_dsm_lookup.cmake: -D${var}=... is required")
  endif()
endforeach()

include("${CMAKE_CURRENT_LIST_DIR}/check_common.cmake")

# at_the_depth(out args...): the args, plus --bias 0 for a point lookup that
# gives no --bias. The checks compare answers at the queried depth itself;
# the default automatic bias has its own check (auto_bias).
function(at_the_depth out)
  set(args ${ARGN})
  set(given FALSE)
  foreach(a IN LISTS args)
    if(a MATCHES "^(--bias|-b|--area-light|--help|--version)" OR a STREQUAL "-h")
      set(given TRUE)
    endif()
  endforeach()
  if(NOT given)
    list(APPEND args --bias 0)
  endif()
  set(${out} "${args}" PARENT_SCOPE)
endfunction()

# run(args...): runs dsm-lookup; sets RC, OUT, ERR and LAST_COMMAND in the caller.
function(run)
  at_the_depth(args ${ARGN})
  run_tool("${DSM_LOOKUP}" dsm-lookup ${args})
endfunction()

# run_with_input(file args...): the same with standard input from a file.
function(run_with_input input)
  at_the_depth(args ${ARGN})
  execute_process(COMMAND "${DSM_LOOKUP}" ${args} INPUT_FILE "${input}"
    RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  set(RC "${rc}" PARENT_SCOPE)
  set(OUT "${out}" PARENT_SCOPE)
  set(ERR "${err}" PARENT_SCOPE)
  set(LAST_COMMAND "dsm-lookup ${ARGN} < ${input}" PARENT_SCOPE)
endfunction()

# query(text args...): dsm-lookup ARGS --input <file holding text>.
set(_query_count 0)
function(query text)
  math(EXPR n "${_query_count} + 1")
  set(_query_count ${n} PARENT_SCOPE)
  set(file "${WORK_DIR}/queries_${n}.txt")
  file(WRITE "${file}" "${text}")
  at_the_depth(args ${ARGN})
  execute_process(COMMAND "${DSM_LOOKUP}" ${args} --input "${file}"
    RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  set(RC "${rc}" PARENT_SCOPE)
  set(OUT "${out}" PARENT_SCOPE)
  set(ERR "${err}" PARENT_SCOPE)
  set(LAST_COMMAND "dsm-lookup ${ARGN} --input ${file}" PARENT_SCOPE)
endfunction()

# reference(map space filter width level bias text): lookup_reference's answers to the points in text.
function(reference map space filter width level bias text)
  set(file "${WORK_DIR}/reference_points.txt")
  file(WRITE "${file}" "${text}")
  execute_process(COMMAND "${LOOKUP_REFERENCE}" "${map}" ${space} ${filter} ${width} ${level} ${bias}
    INPUT_FILE "${file}" RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "lookup_reference failed (${rc}): ${err}")
  endif()
  set(REFERENCE "${out}" PARENT_SCOPE)
endfunction()

function(expect_not_contains var text)
  string(FIND "${${var}}" "${text}" at)
  if(NOT at EQUAL -1)
    fail("expected ${var} not to contain '${text}'")
  endif()
endfunction()

function(expect_equal var expected)
  if(NOT "${${var}}" STREQUAL "${expected}")
    fail("expected ${var} to be exactly:\n${expected}")
  endif()
endfunction()

# Number of lines (newline characters) in a variable's value.
function(line_count var result)
  string(REGEX MATCHALL "\n" newlines "${${var}}")
  list(LENGTH newlines n)
  set(${result} ${n} PARENT_SCOPE)
endfunction()

function(expect_lines var expected)
  line_count(${var} n)
  if(NOT n EQUAL expected)
    fail("expected ${expected} lines in ${var}, found ${n}")
  endif()
endfunction()

# expect_same_lines(var expected): the variable's value is exactly expected;
# on a difference names the first line that differs instead of printing all.
function(expect_same_lines var expected)
  if("${${var}}" STREQUAL "${expected}")
    return()
  endif()
  string(REGEX MATCHALL "[^\n]*\n" got_lines "${${var}}")
  string(REGEX MATCHALL "[^\n]*\n" expected_lines "${expected}")
  list(LENGTH got_lines got_count)
  list(LENGTH expected_lines expected_count)
  set(first 0)
  foreach(a b IN ZIP_LISTS got_lines expected_lines)
    if(NOT "${a}" STREQUAL "${b}")
      break()
    endif()
    math(EXPR first "${first} + 1")
  endforeach()
  math(EXPR number "${first} + 1")
  set(OUT "(${got_count} lines, ${expected_count} expected)")
  fail("${var} differs from the expected ${expected_count} lines first at line ${number}")
endfunction()

# One error line on stderr in the tools' format: "dsm-lookup: ERROR '<file>': ...".
function(expect_one_error_line file)
  expect_error_line("dsm-lookup: ERROR '${file}': ")
endfunction()

# soft_reference(map space shape w h method samples layers z bias seed text):
# lookup_reference --soft's answers, in REFERENCE (all columns) and
# REFERENCE_VALUES (the visibility columns only, as the tool's CSV prints them).
function(soft_reference map space shape w h method samples layers z bias seed text)
  set(file "${WORK_DIR}/soft_reference_points.txt")
  file(WRITE "${file}" "${text}")
  execute_process(COMMAND "${LOOKUP_REFERENCE}" --soft "${map}" ${space} ${shape} ${w} ${h} ${method} ${samples}
                          ${layers} ${z} ${bias} ${seed}
    INPUT_FILE "${file}" RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "lookup_reference --soft failed (${rc}): ${err}")
  endif()
  set(REFERENCE "${out}" PARENT_SCOPE)
  string(REGEX REPLACE ",[^,
]*,[^,
]*
" "
" values "${out}")
  set(REFERENCE_VALUES "${values}" PARENT_SCOPE)
endfunction()

# build_soft_map(out radius): the soft-shadow scene of the file's head as a
# map; radius 0 leaves out area_radius.
function(build_soft_map out radius)
  if(NOT DSM_BUILD)
    message(FATAL_ERROR "check_dsm_lookup.cmake: -DDSM_BUILD=... is required for the soft_* checks")
  endif()
  set(area "")
  if(NOT radius EQUAL 0)
    set(area ", \"area_radius\": ${radius}")
  endif()
  set(scene "${WORK_DIR}/soft_scene_${radius}.json")
  file(WRITE "${scene}" "{\"light\": {\"type\": \"spot\", \"position\": [0, 10, 0], \"direction\": [0, -1, 0],
  \"up\": [0, 0, 1], \"fov\": 60, \"resolution\": 64${area}},
 \"objects\": [{\"type\": \"plane\", \"center\": [0, 0, 0], \"normal\": [0, 1, 0], \"size\": 40},
             {\"type\": \"quad\", \"center\": [0, 5, 0], \"u\": [1, 0, 0], \"v\": [0, 0, 1]}]}
")
  execute_process(COMMAND "${DSM_BUILD}" "${scene}" -o "${out}" --spp 16 --mtsm-layers 2 --threads 2 --quiet
    RESULT_VARIABLE rc ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "dsm-build failed (${rc}): ${err}")
  endif()
endfunction()

# Receivers on the soft map's plane: under the square, in the penumbra and
# beyond it.
set(SOFT_UMBRA "0 0 0\n0.3 0 -0.2\n-0.6 0 0.5\n")
set(SOFT_PENUMBRA "1.5 0 0\n2 0 0\n2.5 0 0\n-2 0 0.3\n0.2 0 1.8\n1.6 0 1.6\n")
set(SOFT_LIT "5 0 0\n-4.5 0 1\n0 0 -5\n3.6 0 3.6\n")

# Every line of a variable's value as a list.
function(split_lines var result)
  string(REGEX MATCHALL "[^\n]+" lines "${${var}}")
  set(${result} "${lines}" PARENT_SCOPE)
endfunction()

# ---------------------------------------------------------------------------
# The mono map's values, from its formula

# k(i, j) of the mono map.
function(mono_k i j out)
  math(EXPR k "(5 * ${i} + 3 * ${j} + ${i} * ${j}) % 16")
  set(${out} ${k} PARENT_SCOPE)
endfunction()

# numerator / denominator (a power of two up to 256) as %.9g prints it.
function(fraction_text numerator denominator out)
  math(EXPR scaled "${numerator} * (100000000 / ${denominator})")
  math(EXPR whole "${scaled} / 100000000")
  math(EXPR part "${scaled} % 100000000")
  if(part EQUAL 0)
    set(${out} "${whole}" PARENT_SCOPE)
    return()
  endif()
  string(LENGTH "${part}" digits)
  math(EXPR pad "8 - ${digits}")
  string(REPEAT "0" ${pad} zeros)
  string(REGEX REPLACE "0+$" "" part "${zeros}${part}")
  set(${out} "${whole}.${part}" PARENT_SCOPE)
endfunction()

# The centre of pixel (i, j) at light depth z ("3", "1.5") in a space, as "x y z".
function(mono_point space i j z out)
  if(space STREQUAL "raster")
    set(p "${i}.5 ${j}.5 ${z}")
  elseif(space STREQUAL "light")
    math(EXPR ly "7 - ${j}")
    set(p "${i}.5 ${ly}.5 ${z}")
  else()  # world = light - (1, -2, 0.5)
    if(i EQUAL 0)
      set(wx "-0.5")
    else()
      math(EXPR wx "${i} - 1")
      set(wx "${wx}.5")
    endif()
    math(EXPR wy "9 - ${j}")
    # z - 0.5 for the depths used here (3 -> 2.5, 1.5 -> 1, 0.5 -> 0, 2 -> 1.5)
    set(wz_3 "2.5")
    set(wz_1.5 "1")
    set(wz_0.5 "0")
    set(wz_2 "1.5")
    set(p "${wx} ${wy}.5 ${wz_${z}}")
  endif()
  set(${out} "${p}" PARENT_SCOPE)
endfunction()

# Box filter of width 2 (or triangle of width 4) at the centre of interior
# pixel (i, j), z past the vertices: weights 1 2 1 on each axis, / 16 / 16.
function(mono_smoothed i j out)
  set(sum 0)
  foreach(dj -1 0 1)
    foreach(di -1 0 1)
      math(EXPR x "${i} + ${di}")
      math(EXPR y "${j} + ${dj}")
      mono_k(${x} ${y} k)
      math(EXPR w "(2 - ${di} * ${di}) * (2 - ${dj} * ${dj})")
      math(EXPR sum "${sum} + ${w} * ${k}")
    endforeach()
  endforeach()
  fraction_text(${sum} 256 text)
  set(${out} "${text}" PARENT_SCOPE)
endfunction()

# Level-1 pixel (I, J): the mean of its four level-0 pixels.
function(mono_level1 I J out)
  set(sum 0)
  foreach(dj 0 1)
    foreach(di 0 1)
      math(EXPR x "2 * ${I} + ${di}")
      math(EXPR y "2 * ${J} + ${dj}")
      mono_k(${x} ${y} k)
      math(EXPR sum "${sum} + ${k}")
    endforeach()
  endforeach()
  fraction_text(${sum} 64 text)
  set(${out} "${text}" PARENT_SCOPE)
endfunction()

# Every pixel centre of the mono map at depth z in a space: POINTS (one per
# line) and VALUES (k/16 past the vertices, (16 + k)/32 halfway, 1 before).
function(mono_all_pixels space z)
  set(points "")
  set(values "")
  foreach(j RANGE 7)
    foreach(i RANGE 7)
      mono_point(${space} ${i} ${j} ${z} p)
      mono_k(${i} ${j} k)
      if(z STREQUAL "3")
        fraction_text(${k} 16 v)
      elseif(z STREQUAL "1.5")
        math(EXPR n "16 + ${k}")
        fraction_text(${n} 32 v)
      else()
        set(v 1)
      endif()
      string(APPEND points "${p}\n")
      string(APPEND values "${v}\n")
    endforeach()
  endforeach()
  set(POINTS "${points}" PARENT_SCOPE)
  set(VALUES "${values}" PARENT_SCOPE)
endfunction()

# ---------------------------------------------------------------------------
# Fresh maps

file(REMOVE_RECURSE "${WORK_DIR}")
file(MAKE_DIRECTORY "${WORK_DIR}")
set(MONO "${WORK_DIR}/mono.dsm")
set(RGB "${WORK_DIR}/rgb.dsm")
execute_process(COMMAND "${LOOKUP_REFERENCE}" --write-mono "${MONO}" RESULT_VARIABLE rc ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "lookup_reference --write-mono failed (${rc}): ${err}")
endif()
execute_process(COMMAND "${MAKE_SAMPLE_MAP}" "${RGB}" RESULT_VARIABLE rc ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "make_sample_map failed (${rc}): ${err}")
endif()
set(SOFT "${WORK_DIR}/soft.dsm")
if(CHECK MATCHES "^soft_" OR CHECK STREQUAL "auto_bias")
  build_soft_map("${SOFT}" 1)
endif()

# ---------------------------------------------------------------------------
# Checks

if(CHECK STREQUAL "known_values")
  # Level 0, a box of one pixel at pixel centres: each pixel's own function,
  # before, on and after its ramp.
  foreach(z 3 1.5 0.5)
    mono_all_pixels(raster ${z})
    query("${POINTS}" "${MONO}" --space raster --level 0)
    expect_rc(0)
    expect_empty(ERR)
    expect_equal(OUT "${VALUES}")
  endforeach()

elseif(CHECK STREQUAL "spaces")
  # The same pixel centres named in world, light and raster space (world is the default).
  foreach(space world light raster)
    mono_all_pixels(${space} 3)
    if(space STREQUAL "world")
      query("${POINTS}" "${MONO}" --level 0)
    else()
      query("${POINTS}" "${MONO}" --space ${space} --level 0)
    endif()
    expect_rc(0)
    expect_empty(ERR)
    expect_equal(OUT "${VALUES}")
  endforeach()
  # The world point of pixel (2, 5) read as light or raster coordinates is elsewhere.
  mono_point(world 2 5 3 p)
  mono_k(2 5 k)
  fraction_text(${k} 16 expected)
  query("${p}\n" "${MONO}" --level 0 --space world)
  expect_equal(OUT "${expected}\n")
  query("${p}\n" "${MONO}" --level 0 --space light)
  if("${OUT}" STREQUAL "${expected}\n")
    fail("light space gave the world-space answer")
  endif()
  # Outside the raster (and, for a perspective map, behind the light) is lit.
  query("-0.5 4 3\n8.5 4 3\n4 9 3\n" "${MONO}" --space raster)
  expect_equal(OUT "1\n1\n1\n")
  query("0 0 -1\n" "${RGB}" --space light)
  expect_equal(OUT "1,1,1\n")

elseif(CHECK STREQUAL "filters")
  set(points "")
  set(smoothed "")
  set(own "")
  foreach(j 1 3 6)
    foreach(i 1 2 5 6)
      mono_point(raster ${i} ${j} 3 p)
      string(APPEND points "${p}\n")
      mono_smoothed(${i} ${j} v)
      string(APPEND smoothed "${v}\n")
      mono_k(${i} ${j} k)
      fraction_text(${k} 16 v)
      string(APPEND own "${v}\n")
    endforeach()
  endforeach()
  # Default filter: box; width 1 is bilinear, exact at pixel centres.
  query("${points}" "${MONO}" -s raster -l 0)
  expect_equal(OUT "${own}")
  query("${points}" "${MONO}" -s raster -l 0 --filter box --filter-width 2)
  expect_equal(OUT "${smoothed}")
  # A triangle of width 2 reaches no neighbour centre; of width 4, weights 1 2 1 like the box of 2.
  query("${points}" "${MONO}" -s raster -l 0 --filter triangle --filter-width 2)
  expect_equal(OUT "${own}")
  query("${points}" "${MONO}" -s raster -l 0 --filter triangle -w 4)
  expect_equal(OUT "${smoothed}")
  # A narrower width is raised to the filter's smallest (lookup.h).
  query("${points}" "${MONO}" -s raster -l 0 --filter triangle -w 0.5)
  expect_equal(OUT "${own}")
  # The gaussian: the library's answer, different from both.
  query("${points}" "${MONO}" -s raster -l 0 --filter gaussian -w 4)
  set(gaussian "${OUT}")
  reference("${MONO}" raster gaussian 4 0 0 "${points}")
  string(REGEX REPLACE ",[^,\n]*\n" "\n" expected "${REFERENCE}")  # drop the error bound column
  expect_equal(OUT "${expected}")
  if(gaussian STREQUAL smoothed OR gaussian STREQUAL own)
    fail("the gaussian filter gave the same answers as the box")
  endif()

elseif(CHECK STREQUAL "levels")
  set(points "")
  set(level1 "")
  foreach(J 0 1 3)
    foreach(I 0 1 2 3)
      math(EXPR x "2 * ${I} + 1")
      math(EXPR y "2 * ${J} + 1")
      string(APPEND points "${x} ${y} 3\n")
      mono_level1(${I} ${J} v)
      string(APPEND level1 "${v}\n")
    endforeach()
  endforeach()
  # Level 1 alone: a one-pixel box there covers one level-1 pixel.
  query("${points}" "${MONO}" -s raster --level 1)
  expect_equal(OUT "${level1}")
  # Beyond the coarsest level: clamped to it.
  query("${points}" "${MONO}" -s raster --level 7)
  expect_equal(OUT "${level1}")
  # auto with a 2-pixel box picks level 1 (footprint 1 pixel there) ...
  query("${points}" "${MONO}" -s raster --level auto -w 2)
  expect_equal(OUT "${level1}")
  # Level 0 with a 2-pixel box at the same points covers the same four
  # level-0 pixels: the pyramid holds their exact mean.
  query("${points}" "${MONO}" -s raster --level 0 -w 2)
  expect_equal(OUT "${level1}")
  # At level-0 pixel centres, level 0 gives each pixel's own value and level 1
  # a mix of level-1 pixels (the library's answer), not the same.
  mono_all_pixels(raster 3)
  query("${POINTS}" "${MONO}" -s raster --level 0)
  expect_equal(OUT "${VALUES}")
  query("${POINTS}" "${MONO}" -s raster --level 1)
  reference("${MONO}" raster box 1 1 0 "${POINTS}")
  string(REGEX REPLACE ",[^,\n]*\n" "\n" expected "${REFERENCE}")
  expect_equal(OUT "${expected}")
  if(OUT STREQUAL VALUES)
    fail("--level 1 gave the level-0 answers")
  endif()
  # auto between levels blends them: the library's answer.
  query("${points}" "${MONO}" -s raster -w 1.5)
  reference("${MONO}" raster box 1.5 -1 0 "${points}")
  string(REGEX REPLACE ",[^,\n]*\n" "\n" expected "${REFERENCE}")
  expect_equal(OUT "${expected}")

elseif(CHECK STREQUAL "bias")
  # Depth 2 minus a bias of 0.5 is halfway down the ramp; a negative bias moves past it.
  set(points "")
  set(halfway "")
  set(after "")
  foreach(p "0 0" "3 4" "7 7" "5 2")
    string(REPLACE " " ";" ij "${p}")
    list(GET ij 0 i)
    list(GET ij 1 j)
    string(APPEND points "${i}.5 ${j}.5 2\n")
    mono_k(${i} ${j} k)
    math(EXPR n "16 + ${k}")
    fraction_text(${n} 32 v)
    string(APPEND halfway "${v}\n")
    fraction_text(${k} 16 v)
    string(APPEND after "${v}\n")
  endforeach()
  query("${points}" "${MONO}" -s raster -l 0 --bias 0.5)
  expect_equal(OUT "${halfway}")
  query("${points}" "${MONO}" -s raster -l 0 --bias=-0.5)
  expect_equal(OUT "${after}")
  query("${points}" "${MONO}" -s raster -l 0 -b 0)
  expect_equal(OUT "${after}")

elseif(CHECK STREQUAL "auto_bias")
  # The default bias is automatic: lit ground reads 1, the umbra stays dark,
  # and the answers are the library's with the bias unset; for point lookups
  # and soft shadows alike.
  execute_process(COMMAND "${DSM_LOOKUP}" "${SOFT}" --point 5,0,0 --point=-4.5,0,1 --point 0,0,-5 --point 3.6,0,3.6
    RESULT_VARIABLE RC OUTPUT_VARIABLE OUT ERROR_VARIABLE ERR)
  set(LAST_COMMAND "dsm-lookup ${SOFT} --point ... (no --bias)")
  expect_rc(0)
  expect_equal(OUT "1\n1\n1\n1\n")
  query("${SOFT_LIT}" "${SOFT}" --bias auto)
  expect_equal(OUT "1\n1\n1\n1\n")
  query("${SOFT_UMBRA}" "${SOFT}" --bias auto)
  expect_equal(OUT "0\n0\n0\n")
  # A number overrides it: a bias beyond the square (5 in front of the ground) lights the umbra.
  query("${SOFT_UMBRA}" "${SOFT}" --bias 6)
  expect_equal(OUT "1\n1\n1\n")
  query("${SOFT_UMBRA}${SOFT_PENUMBRA}${SOFT_LIT}" "${SOFT}" --area-light disk:1)
  expect_rc(0)
  soft_reference("${SOFT}" world disk 1 1 mtsm 64 0 0 auto 1 "${SOFT_UMBRA}${SOFT_PENUMBRA}${SOFT_LIT}")
  expect_equal(OUT "${REFERENCE_VALUES}")
  string(REGEX MATCH "1\n1\n1\n1\n$" lit "${OUT}")
  if(NOT lit)
    message(FATAL_ERROR "lit ground is not lit with the automatic bias:\n${OUT}")
  endif()
  run("${SOFT}" --bias frob --point 1,2,3)
  expect_rc(2)
  expect_contains(ERR "--bias: expected auto or a finite number, got 'frob'")

elseif(CHECK STREQUAL "error_bound")
  # rgb.dsm records error bounds 0.01 (level 0) and 0.015 (level 1); a blend
  # reports the larger; a lit point outside the map, 0.
  set(p "10.5 3.5 5\n")
  query("${p}" "${RGB}" -s raster -l 0 --error-bound)
  expect_matches(OUT "^[^,]+,[^,]+,[^,]+,0\\.01\n$")
  query("${p}" "${RGB}" -s raster -l 1 -e)
  expect_matches(OUT "^[^,]+,[^,]+,[^,]+,0\\.015\n$")
  query("${p}" "${RGB}" -s raster -w 1.5 -e)
  expect_matches(OUT "^[^,]+,[^,]+,[^,]+,0\\.015\n$")
  query("-5 3.5 5\n" "${RGB}" -s raster -e)
  expect_equal(OUT "1,1,1,0\n")
  query("${p}" "${RGB}" -s raster -l 0)
  expect_matches(OUT "^[^,]+,[^,]+,[^,]+\n$")
  query("${p}" "${RGB}" -s raster -l 1 -e --format json)
  expect_contains(OUT "\"error_bound\":0.015}")

elseif(CHECK STREQUAL "rgb")
  # make_sample_map's pixel (10, 3): one vertex (0.75, 0.5, 0.25) at z = 1.03;
  # (10, 5): three, ending at (0.75^3, 0.5^3, 0.25^3); (10, 4): empty.
  query("10.5 3.5 5\n10.5 3.5 0.5\n10.5 5.5 5\n10.5 4.5 5\n" "${RGB}" -s raster -l 0)
  expect_rc(0)
  expect_empty(ERR)
  expect_equal(OUT "0.75,0.5,0.25\n1,1,1\n0.421875,0.125,0.015625\n1,1,1\n")
  query("10.5 5.5 5\n" "${RGB}" -s raster -l 0 --header)
  expect_equal(OUT "r,g,b\n0.421875,0.125,0.015625\n")

elseif(CHECK STREQUAL "library")
  # Every combination below against dsm::LookupContext on the same points.
  set(world_points "")
  foreach(z -1.5 -0.97 -0.5 0.3 1.5)
    foreach(x -1.2 -0.7 -0.5 -0.31 0.1)
      foreach(y -0.2 0.1 0.3 0.6)
        string(APPEND world_points "${x} ${y} ${z}\n")
      endforeach()
    endforeach()
  endforeach()
  set(raster_points "")
  foreach(z 0.5 1.02 1.2 2 3.3)
    foreach(x 0 3.3 10.5 25.01 47.9 48.5)
      foreach(y 0.2 5.5 16 31.9)
        string(APPEND raster_points "${x} ${y} ${z}\n")
      endforeach()
    endforeach()
  endforeach()
  foreach(setup
      "world;box;1;-1;0" "world;gaussian;3;-1;0" "world;triangle;2.5;0;0.05"
      "light;triangle;2.5;0;0" "light;box;5;-1;0"
      "raster;box;1.5;-1;0" "raster;gaussian;6;1;0.1" "raster;triangle;3;-1;-0.2")
    list(GET setup 0 space)
    list(GET setup 1 filter)
    list(GET setup 2 width)
    list(GET setup 3 level)
    list(GET setup 4 bias)
    if(space STREQUAL "raster")
      set(points "${raster_points}")
    else()
      set(points "${world_points}")
    endif()
    if(level EQUAL -1)
      set(level_text auto)
    else()
      set(level_text ${level})
    endif()
    query("${points}" "${RGB}" --space ${space} --filter ${filter} --filter-width ${width} --level ${level_text}
          --bias=${bias} --error-bound)
    expect_rc(0)
    expect_empty(ERR)
    reference("${RGB}" ${space} ${filter} ${width} ${level} ${bias} "${points}")
    expect_equal(OUT "${REFERENCE}")
    # Not all lit: the points do reach into the shadows.
    string(REGEX MATCHALL "\n1,1,1," lit "\n${OUT}")
    list(LENGTH lit n)
    line_count(OUT total)
    if(n EQUAL total)
      fail("every answer is 1: the points miss the map")
    endif()
  endforeach()

elseif(CHECK STREQUAL "batches")
  # 10,000 queries (more than two batches of 4096), with comments, blank and
  # bad lines among them, answered as the library's single lookups
  # (lookup_reference) in input order; bad lines reported at their numbers.
  set(options -s raster -f gaussian -w 3 -e)
  set(reference_options raster gaussian 3 -1 0)
  # Bad lines at these line numbers (around the batch size), and what the
  # tool says of each.
  set(bad_4095 "1 2")
  set(problem_4095 "expected 3 numbers (x y z), found 2 fields")
  set(bad_4096 "x 1 2")
  set(problem_4096 "x 'x' is not a finite number")
  set(bad_4097 "1 2 3 4")
  set(problem_4097 "expected 3 numbers (x y z), found 4 fields")
  set(bad_6000 "1 nan 2")
  set(problem_6000 "y 'nan' is not a finite number")
  set(bad_8191 "3 4 1e999")
  set(problem_8191 "z '1e999' is not a finite number")
  set(bad_10003 ",1,2")
  set(problem_10003 "x '' is not a finite number")
  set(input_text "")
  set(good_points "")      # for lookup_reference, in order
  set(point_lines "")      # line number of each good point
  set(query_lines "")      # line number of each query, good or bad
  set(bad_queries "")      # index (from 0) of each bad query among the queries
  set(expected_err "")
  # Points for the corrupt map below: none in its damaged tile (raster x, y
  # < 16 at level 0) ...
  set(safe_points "")
  set(state 14)            # a linear congruential generator
  set(queries 0)
  set(line 0)
  while(queries LESS 10000)
    math(EXPR line "${line} + 1")
    math(EXPR mod1000 "${line} % 1000")
    if(mod1000 EQUAL 500)
      string(APPEND input_text "# comment at line ${line}\n")
      continue()
    elseif(mod1000 EQUAL 501)
      string(APPEND input_text "\n")
      continue()
    endif()
    list(APPEND query_lines ${line})
    if(DEFINED bad_${line})
      string(APPEND input_text "${bad_${line}}\n")
      list(APPEND bad_queries ${queries})
      string(APPEND expected_err "dsm-lookup: ERROR '${WORK_DIR}/batch.txt' line ${line}: ${problem_${line}}\n")
      math(EXPR queries "${queries} + 1")
      continue()
    endif()
    # Raster x in [0, 52), y in [0, 36), z in [0, 8) in hundredths: some
    # points lie outside the 48 x 32 map.
    set(hundredths "")
    foreach(range 5200 3600 800)
      math(EXPR state "(${state} * 1103515245 + 12345) % 2147483648")
      math(EXPR v "(${state} / 65536) % ${range}")
      math(EXPR whole "${v} / 100")
      math(EXPR part "${v} % 100")
      if(part LESS 10)
        set(part "0${part}")
      endif()
      list(APPEND hundredths "${whole}.${part}")
    endforeach()
    string(REPLACE ";" " " point "${hundredths}")
    string(APPEND input_text "${point}\n")
    string(APPEND good_points "${point}\n")
    list(APPEND point_lines ${line})
    list(GET hundredths 0 x)
    if(x GREATER_EQUAL 18)
      string(APPEND safe_points "${point}\n")
    endif()
    math(EXPR queries "${queries} + 1")
  endwhile()
  set(input "${WORK_DIR}/batch.txt")
  file(WRITE "${input}" "${input_text}")

  # Every answer, in order: the library's, with nan rows for the bad lines.
  reference("${RGB}" ${reference_options} "${good_points}")
  string(REGEX MATCHALL "[^\n]+" expected_rows "${REFERENCE}")
  foreach(at IN LISTS bad_queries)
    list(INSERT expected_rows ${at} "nan,nan,nan,nan")
  endforeach()
  list(JOIN expected_rows "\n" expected_out)
  string(APPEND expected_out "\n")
  run("${RGB}" ${options} --input "${input}")
  expect_rc(1)
  expect_same_lines(OUT "${expected_out}")
  expect_equal(ERR "${expected_err}")
  # Not all lit, not all in shadow: the points reach into the map's shadows.
  expect_matches(OUT "\n1,1,1,")
  expect_matches(OUT "\n0[.][0-9]+,")
  # The same from standard input.
  run_with_input("${input}" "${RGB}" ${options})
  expect_rc(1)
  expect_same_lines(OUT "${expected_out}")
  string(REPLACE "'${input}'" "'<stdin>'" expected_stdin_err "${expected_err}")
  expect_equal(ERR "${expected_stdin_err}")

  # JSON answers name their lines, in order; bad ones carry the problem.
  run("${RGB}" ${options} --format json --input "${input}")
  expect_rc(1)
  string(REGEX MATCHALL "\"line\":[0-9]+" numbered "${OUT}")
  string(REPLACE "\"line\":" "" numbered "${numbered}")
  if(NOT "${numbered}" STREQUAL "${query_lines}")
    fail("JSON answers do not name the query lines 1..${line} in order")
  endif()
  foreach(bad 4095 4096 4097 6000 8191 10003)
    expect_contains(OUT "\n{\"line\":${bad},\"error\":\"${problem_${bad}}\"}\n")
  endforeach()
  # Inline errors: in the answer stream, nothing on standard error.
  run("${RGB}" ${options} --errors inline --input "${input}")
  expect_rc(1)
  expect_empty(ERR)
  expect_contains(OUT "\nnan,nan,nan,nan,\"line 4096: x 'x' is not a finite number\"\n")

  # A sample answered one query per invocation (--point): the same answers.
  list(LENGTH point_lines point_count)
  string(REGEX MATCHALL "[^\n]+" reference_rows "${REFERENCE}")
  string(REGEX MATCHALL "[^\n]+" sample_points "${good_points}")
  foreach(k RANGE 0 9990 555)
    list(GET sample_points ${k} p)
    list(GET reference_rows ${k} expected)
    string(REPLACE " " "," p "${p}")
    run("${RGB}" ${options} --point "${p}")
    expect_rc(0)
    expect_equal(OUT "${expected}\n")
  endforeach()

  # --strict: the answers up to the first bad line (in the second batch), its
  # placeholder, one complaint.
  list(FIND expected_rows "nan,nan,nan,nan" first_bad)
  list(SUBLIST expected_rows 0 ${first_bad} strict_rows)
  list(JOIN strict_rows "\n" strict_out)
  run("${RGB}" ${options} --strict --input "${input}")
  expect_rc(1)
  expect_same_lines(OUT "${strict_out}\nnan,nan,nan,nan\n")
  expect_equal(ERR "dsm-lookup: ERROR '${input}' line 4095: ${problem_4095}\n")

  # A map error in the second batch: the answers before it, then the error.
  set(corrupt "${WORK_DIR}/corrupt.dsm")
  execute_process(COMMAND "${MAKE_SAMPLE_MAP}" --corrupt "${RGB}" "${corrupt}" RESULT_VARIABLE rc)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "make_sample_map --corrupt failed")
  endif()
  string(REGEX MATCHALL "[^\n]+" safe_list "${safe_points}")
  list(LENGTH safe_list safe_count)
  if(safe_count LESS 5000)
    message(FATAL_ERROR "expected at least 5000 points clear of the damaged tile, found ${safe_count}")
  endif()
  list(SUBLIST safe_list 0 4500 before)
  list(SUBLIST safe_list 4500 -1 after)
  list(JOIN before "\n" before_text)
  list(JOIN after "\n" after_text)
  file(WRITE "${WORK_DIR}/corrupt_queries.txt" "${before_text}\n1.5 1.5 5\n${after_text}\n")
  run("${corrupt}" ${options} --input "${WORK_DIR}/corrupt_queries.txt")
  expect_rc(1)
  reference("${RGB}" ${reference_options} "${before_text}\n")
  expect_same_lines(OUT "${REFERENCE}")
  expect_one_error_line("${corrupt}")
  expect_contains(ERR "CRC")

elseif(CHECK STREQUAL "json")
  query("# a comment\n\n1.5 2.5 3\n" "${MONO}" -s raster -l 0 --format json)
  expect_rc(0)
  mono_k(1 2 k)
  fraction_text(${k} 16 v)
  expect_equal(OUT "{\"line\":3,\"v\":${v}}\n")
  query("10.5 3.5 5\n  # indented comment\n10.5 5.5 5 # trailing comment\n" "${RGB}" -s raster -l 0
        --format json -e)
  expect_rc(0)
  expect_lines(OUT 2)
  string(REGEX MATCHALL "[^\n]+" objects "${OUT}")
  list(GET objects 0 first)
  list(GET objects 1 second)
  json_expect("${first}" 1 line)
  json_expect("${first}" 0.75 r)
  json_expect("${first}" 0.5 g)
  json_expect("${first}" 0.25 b)
  json_expect("${first}" 0.01 error_bound)
  json_expect("${second}" 3 line)
  json_expect("${second}" 0.125 g)
  run("${MONO}" --format json -s raster -l 0 --point 1.5,2.5,3 --point 0.5,0.5,0)
  expect_rc(0)
  expect_equal(OUT "{\"point\":1,\"v\":${v}}\n{\"point\":2,\"v\":1}\n")

elseif(CHECK STREQUAL "header")
  query("1.5 2.5 3\n" "${MONO}" -s raster --header)
  expect_rc(0)
  expect_matches(OUT "^v\n[0-9.]+\n$")
  query("1.5 2.5 3\n" "${MONO}" -s raster --header --error-bound)
  expect_matches(OUT "^v,error_bound\n[0-9.]+,[0-9.e-]+\n$")
  query("10.5 3.5 5\n" "${RGB}" -s raster --header -e)
  expect_matches(OUT "^r,g,b,error_bound\n")
  query("1.5 2.5 3\n" "${MONO}" --header --format json)
  expect_rc(2)
  expect_empty(OUT)

elseif(CHECK STREQUAL "bad_line" OR CHECK STREQUAL "strict")
  string(REPEAT "1" 5000 long)
  set(text "1.5 2.5 3\n1 2\nx 2 3\n0.5 0.5 0\n1 2 3 4\nnan 1 2\n${long} 1 1\n2.5,1.5,3\r\n1 1e999 1\n")
  mono_k(1 2 a)
  mono_k(2 1 b)
  fraction_text(${a} 16 va)
  fraction_text(${b} 16 vb)
  set(input "${WORK_DIR}/bad.txt")
  file(WRITE "${input}" "${text}")
  if(CHECK STREQUAL "bad_line")
    # Every query gets an answer line; the bad ones nan, and a complaint naming the line.
    run("${MONO}" -s raster -l 0 --input "${input}")
    expect_rc(1)
    expect_equal(OUT "${va}\nnan\nnan\n1\nnan\nnan\nnan\n${vb}\nnan\n")
    expect_lines(ERR 6)
    foreach(n 2 3 5 6 7 9)
      expect_contains(ERR "dsm-lookup: ERROR '${input}' line ${n}: ")
    endforeach()
    expect_contains(ERR "line 2: expected 3 numbers (x y z), found 2 fields\n")
    expect_contains(ERR "line 3: x 'x' is not a finite number\n")
    expect_contains(ERR "line 5: expected 3 numbers (x y z), found 4 fields\n")
    expect_contains(ERR "line 6: x 'nan' is not a finite number\n")
    expect_contains(ERR "line 7: longer than 4096 bytes\n")
    expect_contains(ERR "line 9: y '1e999' is not a finite number\n")
    # RGB: nan in every column; JSON: the line and the problem.
    run("${RGB}" -e --input "${input}")
    expect_rc(1)
    expect_matches(OUT "^[^\n]+\nnan,nan,nan,nan\nnan,nan,nan,nan\n")
    run("${MONO}" -s raster -l 0 --format json --input "${input}")
    expect_rc(1)
    string(REGEX MATCHALL "[^\n]+" objects "${OUT}")
    list(LENGTH objects n)
    if(NOT n EQUAL 9)
      fail("expected 9 JSON lines")
    endif()
    list(GET objects 1 second)
    json_expect("${second}" 2 line)
    json_expect("${second}" "expected 3 numbers (x y z), found 2 fields" error)
    list(GET objects 7 eighth)
    json_expect("${eighth}" 8 line)
    json_expect("${eighth}" ${vb} v)
  else()
    # --strict: stop at the first bad line, after its answer line.
    run("${MONO}" -s raster -l 0 --strict --input "${input}")
    expect_rc(1)
    expect_equal(OUT "${va}\nnan\n")
    expect_lines(ERR 1)
    expect_contains(ERR "dsm-lookup: ERROR '${input}' line 2: ")
    # A clean input passes under --strict.
    query("1.5 2.5 3\n" "${MONO}" -s raster -l 0 --strict)
    expect_rc(0)
    expect_equal(OUT "${va}\n")
  endif()

elseif(CHECK STREQUAL "stdin")
  mono_all_pixels(world 3)
  set(input "${WORK_DIR}/queries.txt")
  file(WRITE "${input}" "${POINTS}")
  run_with_input("${input}" "${MONO}" -l 0)
  expect_rc(0)
  expect_empty(ERR)
  expect_equal(OUT "${VALUES}")
  run_with_input("${input}" "${MONO}" -l 0 --input -)
  expect_rc(0)
  expect_equal(OUT "${VALUES}")
  # Bad lines on standard input are named '<stdin>'.
  file(WRITE "${input}" "1 2\n")
  run_with_input("${input}" "${MONO}")
  expect_rc(1)
  expect_equal(OUT "nan\n")
  expect_equal(ERR "dsm-lookup: ERROR '<stdin>' line 1: expected 3 numbers (x y z), found 2 fields\n")
  # The map itself from standard input, queries from a file.
  file(WRITE "${input}" "${POINTS}")
  run_with_input("${MONO}" - -l 0 --input "${input}")
  expect_rc(0)
  expect_equal(OUT "${VALUES}")
  # ... but not both from standard input.
  run_with_input("${MONO}" - -l 0)
  expect_rc(2)
  expect_contains(ERR "cannot both come from standard input")
  # A broken map on standard input is named '<stdin>'.
  run_with_input("${input}" - --input "${input}")
  expect_rc(1)
  expect_one_error_line("<stdin>")
  expect_contains(ERR "not a deep shadow map")
  # No queries at all: no output, success.
  file(WRITE "${input}" "")
  run_with_input("${input}" "${MONO}")
  expect_rc(0)
  expect_empty(OUT)

elseif(CHECK STREQUAL "points")
  mono_k(1 2 a)
  fraction_text(${a} 16 va)
  run("${MONO}" -s raster -l 0 --point 1.5,2.5,3)
  expect_rc(0)
  expect_equal(OUT "${va}\n")
  run("${MONO}" -s raster -l 0 -p 1.5,2.5,3 --point=-1,2,3 -p "0.5 0.5 0")
  expect_rc(0)
  expect_equal(OUT "${va}\n1\n1\n")
  # With --input as well, the points come first.
  query("0.5 0.5 0\n" "${MONO}" -s raster -l 0 --point 1.5,2.5,3)
  expect_rc(0)
  expect_equal(OUT "${va}\n1\n")
  foreach(bad "1,2" "a,b,c" "1,2,inf" "1,2,3,4")
    run("${MONO}" --point "${bad}")
    expect_rc(2)
    expect_empty(OUT)
    expect_contains(ERR "dsm-lookup: --point '${bad}': expected three finite numbers X,Y,Z")
  endforeach()

elseif(CHECK STREQUAL "input_file")
  mono_all_pixels(light 1.5)
  query("${POINTS}" "${MONO}" -s light -l 0)
  expect_rc(0)
  expect_equal(OUT "${VALUES}")
  run("${MONO}" -i "${WORK_DIR}/no-such-queries.txt")
  expect_rc(1)
  expect_one_error_line("${WORK_DIR}/no-such-queries.txt")
  expect_contains(ERR "cannot open")
  run("${MONO}" -i "${WORK_DIR}")
  expect_rc(1)
  expect_one_error_line("${WORK_DIR}")

elseif(CHECK STREQUAL "stats")
  mono_all_pixels(raster 3)
  query("${POINTS}" "${MONO}" -s raster -l 0 --stats)
  expect_rc(0)
  expect_equal(OUT "${VALUES}")
  expect_lines(ERR 2)
  expect_matches(ERR "^dsm-lookup: stats: 64 queries \\(0 bad\\) in [0-9.e+-]+ s, [0-9.e+]+ queries/s\n")
  # The four level-0 tiles, each read once into a 256 MiB cache.
  string(CONCAT pattern "\ndsm-lookup: stats: cache [0-9]+ hits, 4 misses \\([0-9.]+% hits\\), 4 tiles read "
                        "\\([0-9]+ bytes\\), 0 read twice, 0 waits, 0 evictions, peak [1-9][0-9]* of 268435456 bytes in use\n$")
  expect_matches(ERR "${pattern}")
  # A budget of 0 keeps one tile: every new tile evicts the last.
  query("${POINTS}" "${MONO}" -s raster -l 0 --stats --cache-mb 0)
  expect_rc(0)
  expect_equal(OUT "${VALUES}")
  expect_matches(ERR "4 tiles read \\([0-9]+ bytes\\), 0 read twice, 0 waits, 3 evictions, peak [0-9]+ of 0 bytes")
  # Bad lines are counted.
  query("1 2\n1 2 3\n" "${MONO}" --stats)
  expect_rc(1)
  expect_contains(ERR "dsm-lookup: stats: 2 queries (1 bad)")

elseif(CHECK STREQUAL "streaming")
  if(NOT PYTHON)
    message(FATAL_ERROR "check_dsm_lookup.cmake: -DPYTHON=... is required for the streaming check")
  endif()
  # A renderer's coprocess: write one line, wait for its answer (with a
  # timeout) before writing the next, keeping standard input open throughout.
  mono_k(1 2 a)
  mono_k(6 7 b)
  fraction_text(${a} 16 va)
  fraction_text(${b} 16 vb)
  set(script "${WORK_DIR}/stream.py")
  file(WRITE "${script}" [=[
import os, select, subprocess, sys, time

tool, mono, expected_a, expected_b = sys.argv[1:5]
process = subprocess.Popen([tool, mono, "--space", "raster", "--level", "0", "--bias", "0"],
                           stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
pending = b""

def read_line(stream, timeout=10.0):
    """One line from a pipe, or a failure after timeout seconds."""
    global pending
    deadline = time.monotonic() + timeout
    while b"\n" not in pending:
        left = deadline - time.monotonic()
        if left <= 0 or not select.select([stream], [], [], left)[0]:
            sys.exit("no answer within %g s (got %r so far)" % (timeout, pending))
        chunk = os.read(stream.fileno(), 4096)
        if not chunk:
            sys.exit("the tool closed its output early (got %r)" % pending)
        pending += chunk
    line, pending = pending.split(b"\n", 1)
    return line.decode()

def ask(query, expected):
    process.stdin.write(query.encode() + b"\n")
    process.stdin.flush()
    answer = read_line(process.stdout)
    if answer != expected:
        sys.exit("query %r: expected %r, got %r" % (query, expected, answer))

ask("1.5 2.5 3", expected_a)
ask("6.5 7.5 1.5", "%.9g" % ((1 + float(expected_b)) / 2))
process.stdin.write(b"# a comment, then a blank line: no answers\n\n")
ask("0.5 0.5 0", "1")
ask("1 2", "nan")  # a bad line still gets its answer at once ...
error = read_line(process.stderr)  # ... and its complaint
if error != "dsm-lookup: ERROR '<stdin>' line 6: expected 3 numbers (x y z), found 2 fields":
    sys.exit("unexpected error line %r" % error)
ask("6.5 7.5 3", expected_b)
process.stdin.close()
try:
    status = process.wait(timeout=10)
except subprocess.TimeoutExpired:
    process.kill()
    sys.exit("the tool did not exit after its input closed")
if pending or process.stdout.read():
    sys.exit("unexpected output after the last answer")
if status != 1:
    sys.exit("expected exit status 1 after a bad line, got %d" % status)
print("streaming ok")
]=])
  execute_process(COMMAND "${PYTHON}" "${script}" "${DSM_LOOKUP}" "${MONO}" "${va}" "${vb}"
    RESULT_VARIABLE RC OUTPUT_VARIABLE OUT ERROR_VARIABLE ERR TIMEOUT 50)
  set(LAST_COMMAND "${PYTHON} ${script}")
  expect_rc(0)
  expect_contains(OUT "streaming ok")

elseif(CHECK STREQUAL "help")
  run(--help)
  expect_rc(0)
  expect_empty(ERR)
  foreach(option --input --point --space --filter-width --filter --level --bias --format --header --error-bound
                 --strict --stats --cache-mb --area-light --light-samples --layers --z-threshold --seed --soft
                 --version docs/dsm-lookup.md)
    expect_contains(OUT "${option}")
  endforeach()

elseif(CHECK STREQUAL "version")
  run(--version)
  expect_rc(0)
  expect_equal(OUT "dsm-lookup ${VERSION}\n")

elseif(CHECK STREQUAL "usage")
  foreach(args
      "" "--space;galaxy;${MONO}" "--filter;lanczos;${MONO}" "--filter-width;-1;${MONO}"
      "--filter-width;wide;${MONO}" "--filter-width;1e9;${MONO}" "--level;-1;${MONO}" "--level;coarse;${MONO}"
      "--format;xml;${MONO}"
      "--cache-mb;-5;${MONO}" "--bias;inf;${MONO}" "--frobnicate;${MONO}" "${MONO};${RGB}")
    run(${args})
    expect_rc(2)
    expect_empty(OUT)
    expect_contains(ERR "dsm-lookup: ")
  endforeach()

elseif(CHECK STREQUAL "missing")
  set(missing "${WORK_DIR}/no-such-map.dsm")
  run("${missing}" --point 1,2,3)
  expect_rc(1)
  expect_empty(OUT)
  expect_one_error_line("${missing}")
  expect_contains(ERR "cannot open")

elseif(CHECK STREQUAL "corrupt")
  # Opens, but the first non-empty level-0 tile fails its CRC when a lookup reads it.
  set(corrupt "${WORK_DIR}/corrupt.dsm")
  execute_process(COMMAND "${MAKE_SAMPLE_MAP}" --corrupt "${RGB}" "${corrupt}" RESULT_VARIABLE rc)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "make_sample_map --corrupt failed")
  endif()
  query("1.5 1.5 5\n2.5 2.5 5\n" "${corrupt}" -s raster -l 0)
  expect_rc(1)
  expect_empty(OUT)
  expect_one_error_line("${corrupt}")
  expect_contains(ERR "CRC")
  # Truncated: open() already fails.
  set(truncated "${WORK_DIR}/truncated.dsm")
  execute_process(COMMAND "${MAKE_SAMPLE_MAP}" --truncate "${RGB}" "${truncated}" 3000 RESULT_VARIABLE rc)
  query("1.5 1.5 5\n" "${truncated}")
  expect_rc(1)
  expect_empty(OUT)
  expect_one_error_line("${truncated}")

elseif(CHECK STREQUAL "not_a_map")
  set(text "${WORK_DIR}/notes.txt")
  file(WRITE "${text}" "not a map at all\n")
  query("1 2 3\n" "${text}")
  expect_rc(1)
  expect_empty(OUT)
  expect_one_error_line("${text}")
  expect_contains(ERR "not a deep shadow map")

elseif(CHECK STREQUAL "soft_values")
  # Umbra near 0, lit exactly 1, penumbra strictly between: all the library's answers.
  query("${SOFT_UMBRA}${SOFT_PENUMBRA}${SOFT_LIT}" "${SOFT}" --area-light disk:1 --bias 0.05)
  expect_rc(0)
  expect_empty(ERR)
  soft_reference("${SOFT}" world disk 1 1 mtsm 64 0 0 0.05 1 "${SOFT_UMBRA}${SOFT_PENUMBRA}${SOFT_LIT}")
  expect_equal(OUT "${REFERENCE_VALUES}")
  split_lines(OUT values)
  list(SUBLIST values 0 3 umbra)
  list(SUBLIST values 3 6 penumbra)
  list(SUBLIST values 9 4 lit)
  foreach(v IN LISTS umbra)
    if(v GREATER 0.05)
      fail("umbra value ${v} is not near 0")
    endif()
  endforeach()
  foreach(v IN LISTS penumbra)
    if(NOT (v GREATER 0.05 AND v LESS 0.95))
      fail("penumbra value ${v} is not strictly between 0 and 1")
    endif()
  endforeach()
  foreach(v IN LISTS lit)
    if(NOT v STREQUAL "1")
      fail("lit value ${v} is not exactly 1")
    endif()
  endforeach()
  # Visibility grows from the umbra's edge outwards (x = 1.5, 2, 2.5).
  list(GET penumbra 0 a)
  list(GET penumbra 1 b)
  list(GET penumbra 2 c)
  if(NOT (a LESS b AND b LESS c))
    fail("penumbra values ${a}, ${b}, ${c} do not grow away from the square")
  endif()
  # Every soft option reaches the library: samples, layers, z threshold, seed; and light-space points.
  query("${SOFT_PENUMBRA}" "${SOFT}" --area-light disk:0.8 --light-samples 100 --layers 1 --z-threshold 0.01
        --bias 0.1 --seed 5)
  expect_rc(0)
  soft_reference("${SOFT}" world disk 0.8 0.8 mtsm 100 1 0.01 0.1 5 "${SOFT_PENUMBRA}")
  expect_equal(OUT "${REFERENCE_VALUES}")
  set(light_points "0.5 0.3 11.73\n2 0 11.73\n-1.7 1.1 11.73\n")
  query("${light_points}" "${SOFT}" --area-light disk:1 --space light --bias 0.05)
  expect_rc(0)
  soft_reference("${SOFT}" light disk 1 1 mtsm 64 0 0 0.05 1 "${light_points}")
  expect_equal(OUT "${REFERENCE_VALUES}")

elseif(CHECK STREQUAL "soft_pcf")
  # The PCF baseline: the library's pcfVisibility, not the traced answer in the penumbra.
  query("${SOFT_PENUMBRA}" "${SOFT}" --area-light disk:1 --bias 0.05 --soft pcf)
  expect_rc(0)
  expect_empty(ERR)
  set(pcf "${OUT}")
  soft_reference("${SOFT}" world disk 1 1 pcf 64 0 0 0.05 1 "${SOFT_PENUMBRA}")
  expect_equal(pcf "${REFERENCE_VALUES}")
  query("${SOFT_PENUMBRA}" "${SOFT}" --area-light disk:1 --bias 0.05 --soft mtsm)
  split_lines(pcf pcf_values)
  split_lines(OUT mtsm_values)
  foreach(k RANGE 5)
    list(GET pcf_values ${k} p)
    list(GET mtsm_values ${k} m)
    if(p STREQUAL m)
      fail("pcf and mtsm agree (${p}) at penumbra point ${k}")
    endif()
  endforeach()
  # JSON shows the blocker depth and filter width it used.
  query("2 0 0\n" "${SOFT}" --area-light disk:1 --bias 0.05 --soft pcf --format json)
  expect_rc(0)
  soft_reference("${SOFT}" world disk 1 1 pcf 64 0 0 0.05 1 "2 0 0\n")
  string(REPLACE "," ";" fields "${REFERENCE}")
  string(STRIP "${fields}" fields)
  list(GET fields 0 v)
  list(GET fields 1 depth)
  list(GET fields 2 width)
  expect_equal(OUT "{\"line\":1,\"v\":${v},\"blocker_depth\":${depth},\"filter_width\":${width}}\n")

elseif(CHECK STREQUAL "soft_determinism")
  # The same answers on every run, from --point and from a file alike.
  set(points "${SOFT_UMBRA}${SOFT_PENUMBRA}${SOFT_LIT}")
  query("${points}" "${SOFT}" --area-light disk:1 --bias 0.05 --light-samples 16)
  expect_rc(0)
  set(first "${OUT}")
  query("${points}" "${SOFT}" --area-light disk:1 --bias 0.05 --light-samples 16)
  expect_equal(OUT "${first}")
  split_lines(first values)
  list(GET values 4 at_2)
  run("${SOFT}" --area-light disk:1 --bias 0.05 --light-samples 16 --point 2,0,0)
  expect_equal(OUT "${at_2}\n")
  # Another seed draws other light samples: another penumbra estimate.
  query("${points}" "${SOFT}" --area-light disk:1 --bias 0.05 --light-samples 16 --seed 2)
  expect_rc(0)
  if(OUT STREQUAL first)
    fail("--seed 2 gave the answers of seed 1")
  endif()

elseif(CHECK STREQUAL "soft_rect")
  # A rectangle 2 wide and 1 high (half-sizes 1 and 0.5): the library's answers, not the disk's.
  query("${SOFT_PENUMBRA}" "${SOFT}" --area-light rect:2,1 --bias 0.05)
  expect_rc(0)
  expect_empty(ERR)
  soft_reference("${SOFT}" world rect 2 1 mtsm 64 0 0 0.05 1 "${SOFT_PENUMBRA}")
  expect_equal(OUT "${REFERENCE_VALUES}")
  set(rect "${OUT}")
  query("${SOFT_PENUMBRA}" "${SOFT}" --area-light disk:1 --bias 0.05)
  if(OUT STREQUAL rect)
    fail("rect:2,1 gave the disk's answers")
  endif()
  # Full sizes, not half-sizes: rect:0.5,2 is half 0.25 x 1 (light x is world x here).
  query("2.5 0 0\n" "${SOFT}" --area-light rect:0.5,2 --bias 0.05)
  expect_rc(0)
  soft_reference("${SOFT}" world rect 0.5 2 mtsm 64 0 0 0.05 1 "2.5 0 0\n")
  expect_equal(OUT "${REFERENCE_VALUES}")

elseif(CHECK STREQUAL "soft_output")
  # CSV header, JSON details, bad lines, --strict and --stats as for point lookups.
  query("2 0 0\n" "${SOFT}" --area-light disk:1 --bias 0.05 --header)
  expect_rc(0)
  expect_matches(OUT "^v\n0\\.[0-9]+\n$")
  query("# comment\n2 0 0\n5 0 0\n" "${SOFT}" --area-light disk:1 --bias 0.05 --format json)
  expect_rc(0)
  soft_reference("${SOFT}" world disk 1 1 mtsm 64 0 0 0.05 1 "2 0 0\n5 0 0\n")
  split_lines(REFERENCE_VALUES values)
  list(GET values 0 v)
  expect_equal(OUT "{\"line\":2,\"v\":${v},\"rays\":64,\"classified_lit\":false}\n{\"line\":3,\"v\":1,\"rays\":0,\"classified_lit\":true}\n")
  set(text "2 0 0\n1 2\n5 0 0\n")
  query("${text}" "${SOFT}" --area-light disk:1 --bias 0.05)
  expect_rc(1)
  expect_equal(OUT "${v}\nnan\n1\n")
  expect_lines(ERR 1)
  expect_contains(ERR "line 2: expected 3 numbers (x y z), found 2 fields\n")
  query("${text}" "${SOFT}" --area-light disk:1 --bias 0.05 --strict)
  expect_rc(1)
  expect_equal(OUT "${v}\nnan\n")
  query("${SOFT_UMBRA}${SOFT_LIT}" "${SOFT}" --area-light disk:1 --bias 0.05 --stats)
  expect_rc(0)
  expect_lines(ERR 3)
  expect_contains(ERR "dsm-lookup: stats: 7 queries (0 bad)")
  # The lit points are classified lit; the umbra's are traced, 64 rays each,
  # and under the opaque square most of them end by the umbra early-out.
  expect_matches(ERR "\ndsm-lookup: stats: soft 7 queries \\(4 classified lit\\), 192 rays \\([1-9][0-9]* ended by the umbra early-out\\), [0-9]+ nodes, [1-9][0-9]* pixels, [1-9][0-9]* samples hit, [1-9][0-9]* tiles in the hierarchy\n$")
  # The same counters as one JSON object with --format json.
  query("${SOFT_UMBRA}${SOFT_LIT}" "${SOFT}" --area-light disk:1 --bias 0.05 --stats --format json)
  expect_rc(0)
  expect_lines(ERR 1)
  json_expect("${ERR}" 7 stats queries)
  json_expect("${ERR}" 0 stats bad)
  json_expect("${ERR}" 7 stats soft queries)
  json_expect("${ERR}" 4 stats soft classified_lit)
  json_expect("${ERR}" 192 stats soft rays)
  foreach(key seconds queries_per_second)
    json_expect_type("${ERR}" NUMBER stats ${key})
  endforeach()
  foreach(key hits misses tiles_read bytes_read read_twice waits evictions peak_bytes budget_bytes)
    json_expect_type("${ERR}" NUMBER stats cache ${key})
  endforeach()
  foreach(key rays_proven_opaque nodes pixels samples_hit hierarchy_tiles)
    string(JSON n GET "${ERR}" stats soft ${key})
    if(n LESS 1)
      fail("stats soft ${key}: expected > 0, got ${n}")
    endif()
  endforeach()
  string(JSON opaque GET "${ERR}" stats soft rays_proven_opaque)
  if(NOT ERR MATCHES "^{\"stats\":" OR opaque GREATER 192)
    fail("expected one JSON object of statistics, at most 192 rays proven opaque: ${ERR}")
  endif()
  # Point lookups: no soft counters.
  query("${SOFT_LIT}" "${SOFT}" --stats --format json)
  expect_rc(0)
  json_expect("${ERR}" 4 stats queries)
  string(JSON soft ERROR_VARIABLE missing GET "${ERR}" stats soft)
  if(NOT missing)
    fail("point lookups' statistics carry soft counters: ${ERR}")
  endif()

elseif(CHECK STREQUAL "soft_usage")
  foreach(args
      "--area-light;disk;${SOFT}" "--area-light;disk:0;${SOFT}" "--area-light;disk:-1;${SOFT}"
      "--area-light;disk:1,2;${SOFT}" "--area-light;rect:2;${SOFT}" "--area-light;rect:2,x;${SOFT}"
      "--area-light;rect:2,0;${SOFT}" "--area-light;sphere:1;${SOFT}" "--area-light;disk:inf;${SOFT}"
      "--area-light;disk:1;--error-bound;${SOFT}" "--area-light;disk:1;-e;${SOFT}"
      "--area-light;disk:1;--space;raster;${SOFT}" "--area-light;disk:1;--filter;box;${SOFT}"
      "--area-light;disk:1;--filter-width;2;${SOFT}" "--area-light;disk:1;--level;0;${SOFT}"
      "--area-light;disk:1;--bias=-0.1;${SOFT}" "--area-light;disk:1;--light-samples;0;${SOFT}"
      "--area-light;disk:1;--layers;-1;${SOFT}" "--area-light;disk:1;--z-threshold;-1;${SOFT}"
      "--area-light;disk:1;--seed=-1;${SOFT}" "--area-light;disk:1;--soft;vsm;${SOFT}"
      "--area-light;disk:1;--soft;pcf;--light-samples;8;${SOFT}"
      "--light-samples;8;${SOFT}" "--soft;pcf;${SOFT}" "--seed;3;${SOFT}" "--layers;1;${SOFT}"
      "--z-threshold;0.1;${SOFT}")
    run(${args} --point 2,0,0)
    expect_rc(2)
    expect_empty(OUT)
    expect_contains(ERR "dsm-lookup: ")
  endforeach()
  run(--area-light rect:2,1 --error-bound "${SOFT}" --point 2,0,0)
  expect_contains(ERR "dsm-lookup: --error-bound does not apply to --area-light")
  run(--area-light disk:1 --space raster "${SOFT}" --point 2,0,0)
  expect_contains(ERR "dsm-lookup: --area-light takes world or light points, not --space raster")
  run(--area-light disk:1:2 "${SOFT}" --point 2,0,0)
  expect_contains(ERR "dsm-lookup: --area-light 'disk:1:2': expected disk:R or rect:W,H")
  # The defaults, named explicitly, are fine.
  run(--area-light disk:1 --space world --soft mtsm --light-samples 64 --layers 0 --seed 1 "${SOFT}" -p 2,0,0)
  expect_rc(0)

elseif(CHECK STREQUAL "soft_map_errors")
  # A light larger than the one the map was built for does not fit its frustum.
  run("${SOFT}" --area-light disk:1.5 --point 2,0,0)
  expect_rc(1)
  expect_empty(OUT)
  expect_one_error_line("${SOFT}")
  expect_contains(ERR "does not fit the map's frustum")
  run("${SOFT}" --area-light rect:2.5,1 --point 2,0,0)
  expect_rc(1)
  expect_one_error_line("${SOFT}")
  # A smaller light fits.
  run("${SOFT}" --area-light disk:0.5 --point 2,0,0)
  expect_rc(0)
  # An orthographic map has no light position to put an area light at.
  run("${MONO}" --area-light disk:1 --point 2,0,0)
  expect_rc(1)
  expect_empty(OUT)
  expect_one_error_line("${MONO}")
  expect_contains(ERR "perspective")
  # A map built without area_radius has no light plane to put an area light
  # on (its projection centre is the point light): refused, naming the file.
  set(plain "${WORK_DIR}/plain.dsm")
  build_soft_map("${plain}" 0)
  run("${plain}" --area-light disk:0.5 --point 2,0,0)
  expect_rc(1)
  expect_empty(OUT)
  expect_one_error_line("${plain}")
  expect_contains(ERR "area_radius")
  # The map read from standard input is named '<stdin>' in the error.
  run_with_input("${SOFT}" - --area-light disk:2 --point 2,0,0)
  expect_rc(1)
  expect_one_error_line("<stdin>")

else()
  message(FATAL_ERROR "check_dsm_lookup.cmake: unknown check '${CHECK}'")
endif()

# Every public header of the renderer-facing read side compiles alone as C++17
# with -Wall -Wextra -Werror -pedantic, as a renderer that still builds as
# C++17 includes it. The list is every header in INCLUDE_DIR/dsm except the
# heavy side (scene building, sampling, OpenEXR, the reference tracer,
# pictures, the depth-map baseline, the dsm-info JSON) and the umbrella dsm.h,
# which includes them.
#
# cmake -DCXX=... -DINCLUDE_DIR=... -DGENERATED_INCLUDE_DIR=... -DWORK_DIR=... -P check_public_headers.cmake

set(heavy_side_headers
  dsm.h
  depth_shadow_map.h
  exr_deep.h
  image_io.h
  map_json.h
  reference_tracer.h
  sampler.h
  scene.h)

file(GLOB headers RELATIVE "${INCLUDE_DIR}/dsm" "${INCLUDE_DIR}/dsm/*.h")
list(REMOVE_ITEM headers ${heavy_side_headers})
list(LENGTH headers count)
if(count LESS 10)
  message(FATAL_ERROR "only ${count} public headers found in ${INCLUDE_DIR}/dsm")
endif()

file(REMOVE_RECURSE "${WORK_DIR}")
file(MAKE_DIRECTORY "${WORK_DIR}")
set(failed "")
foreach(header IN LISTS headers)
  string(REPLACE "." "_" stem "${header}")
  set(unit "${WORK_DIR}/${stem}.cpp")
  file(WRITE "${unit}" "#include \"dsm/${header}\"\n")
  execute_process(
    COMMAND "${CXX}" -std=c++17 -Wall -Wextra -Werror -pedantic -fsyntax-only
            -I "${INCLUDE_DIR}" -I "${GENERATED_INCLUDE_DIR}" "${unit}"
    RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    list(APPEND failed "${header}")
    message("dsm/${header} does not compile alone as C++17:\n${out}${err}")
  else()
    message("dsm/${header}: ok")
  endif()
endforeach()
if(failed)
  message(FATAL_ERROR "public headers that do not compile alone as C++17: ${failed}")
endif()

# Every public header of the renderer-facing read side (the components of
# dsm::core: core, format, lookup, soft, ops) and the C API's dsm/dsm_c.h
# compiles alone as C++17 with -Wall -Wextra -Werror -pedantic, as a renderer
# that still builds as C++17 includes it. The heavy components (build, exr,
# reference) keep their headers in folders of their own and are not checked.
#
# cmake -DCXX=... -DLIBRARY_DIR=... -DWORK_DIR=... -P check_public_headers.cmake

set(read_side_components core format lookup soft ops)

set(include_flags "")
set(headers "")
foreach(component IN LISTS read_side_components)
  set(dir "${LIBRARY_DIR}/${component}/include")
  list(APPEND include_flags -I "${dir}")
  file(GLOB component_headers RELATIVE "${dir}/dsm" "${dir}/dsm/*.h")
  list(APPEND headers ${component_headers})
endforeach()
# The core umbrella header too, from the source tree alone (nothing generated).
list(APPEND include_flags -I "${LIBRARY_DIR}/c/include" -I "${LIBRARY_DIR}/include")
list(APPEND headers dsm_c.h dsm.h)
list(LENGTH headers count)
if(count LESS 20)
  message(FATAL_ERROR "only ${count} public headers found in ${LIBRARY_DIR}/{core,format,lookup,soft,ops}/include/dsm")
endif()

file(REMOVE_RECURSE "${WORK_DIR}")
file(MAKE_DIRECTORY "${WORK_DIR}")
set(failed "")
foreach(header IN LISTS headers)
  string(REPLACE "." "_" stem "${header}")
  set(unit "${WORK_DIR}/${stem}.cpp")
  file(WRITE "${unit}" "#include \"dsm/${header}\"\n")
  execute_process(
    COMMAND "${CXX}" -std=c++17 -Wall -Wextra -Werror -pedantic -fsyntax-only ${include_flags} "${unit}"
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

cmake_minimum_required(VERSION 3.25)
# Installs libdsm into a fresh prefix and builds consumers against it.
#   MODE=static  install BUILD_DIR; a consumer of every component (consumer/,
#                find_package(dsm)) and a C++17 consumer of dsm::core alone
#                (consumer_core/, find_package(dsm COMPONENTS core)).
#   MODE=shared  configure SOURCE_DIR as a shared, core-only build
#                (BUILD_SHARED_LIBS=ON, DSM_CORE_ONLY=ON), install it; its
#                library may need zlib, zstd and the C/C++ runtime only (readelf -d);
#                then the same core consumer.
# In both modes no installed text file names a path of the build machine, and
# the core consumer's 1,000 lookups on a map DSM_BUILD makes of SCENE print
# exactly what DSM_LOOKUP prints for the same points.
file(REMOVE_RECURSE "${WORK_DIR}")
set(prefix "${WORK_DIR}/prefix")
function(run)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "command failed (${rc}): ${ARGN}\n${out}\n${err}")
  endif()
endfunction()

if(MODE STREQUAL "static")
  run(${CMAKE_COMMAND} --install "${BUILD_DIR}" --prefix "${prefix}")
elseif(MODE STREQUAL "shared")
  set(launcher "")
  if(COMPILER_LAUNCHER)
    set(launcher "-DCMAKE_CXX_COMPILER_LAUNCHER=${COMPILER_LAUNCHER}")
  endif()
  run(${CMAKE_COMMAND} -S "${SOURCE_DIR}" -B "${WORK_DIR}/shared" -DCMAKE_BUILD_TYPE=Release
      -DBUILD_SHARED_LIBS=ON -DDSM_CORE_ONLY=ON ${launcher})
  run(${CMAKE_COMMAND} --build "${WORK_DIR}/shared" --parallel 2)
  run(${CMAKE_COMMAND} --install "${WORK_DIR}/shared" --prefix "${prefix}")
  file(GLOB_RECURSE libraries "${prefix}/*.so")
  if(NOT libraries)
    message(FATAL_ERROR "the shared build installed no library under ${prefix}")
  endif()
  # zlib, zstd and the C/C++ runtime, nothing else.
  set(allowed libz.so.1 libzstd.so.1 libstdc++.so.6 libm.so.6 libgcc_s.so.1 libc.so.6)
  foreach(library IN LISTS libraries)
    execute_process(COMMAND readelf -d "${library}" OUTPUT_VARIABLE dynamic RESULT_VARIABLE rc)
    if(NOT rc EQUAL 0)
      message(FATAL_ERROR "readelf -d ${library} failed")
    endif()
    string(REGEX MATCHALL "\\(NEEDED\\)[^\n]*\\[([^]]+)\\]" entries "${dynamic}")
    set(needed "")
    foreach(entry IN LISTS entries)
      string(REGEX REPLACE ".*\\[([^]]+)\\]" "\\1" name "${entry}")
      list(APPEND needed "${name}")
      # The C API (libdsm_c) is a layer over dsm::core and needs it as well
      # (and the dynamic loader, for its per-thread last error).
      if(library MATCHES "/libdsm_c\\.so$" AND name MATCHES "^(libdsm_core\\.so\\.[0-9]+|ld-linux[-a-z0-9_.]*\\.so\\.[0-9]+)$")
        continue()
      endif()
      if(NOT name IN_LIST allowed)
        message(FATAL_ERROR "${library} needs ${name}; dsm::core may need only: ${allowed}")
      endif()
    endforeach()
    if(library MATCHES "/libdsm_c\\.so$")
      if(NOT needed MATCHES "libdsm_core\\.so")
        message(FATAL_ERROR "${library} does not need libdsm_core (NEEDED: ${needed})")
      endif()
    elseif(NOT "libz.so.1" IN_LIST needed)
      message(FATAL_ERROR "${library} does not need zlib (NEEDED: ${needed}): is it the core library?")
    endif()
    message(STATUS "${library}: NEEDED ${needed}")
  endforeach()
else()
  message(FATAL_ERROR "MODE must be static or shared, not '${MODE}'")
endif()

# No installed text file names the source tree, the build tree, the prefix or
# a system library directory (binaries keep their debug information).
file(GLOB_RECURSE installed LIST_DIRECTORIES false "${prefix}/*")
set(machine_paths "${SOURCE_DIR}" "${BUILD_DIR}" "${WORK_DIR}" "/usr/lib" "/usr/include" "/usr/local" "/usr/share")
foreach(file IN LISTS installed)
  if(file MATCHES "\\.(a|so)(\\.[0-9]+)*$" OR file MATCHES "/bin/[^/]*$" OR file MATCHES "\\.(pyc|png)$")
    continue()
  endif()
  file(READ "${file}" text)
  foreach(path IN LISTS machine_paths)
    string(FIND "${text}" "${path}" at)
    if(NOT at EQUAL -1)
      message(FATAL_ERROR "${file} names a path of the build machine: ${path}")
    endif()
  endforeach()
endforeach()

# The core consumer answers as dsm-lookup does on a map dsm-build made.
run(${DSM_BUILD} "${SCENE}" -o "${WORK_DIR}/map.dsm" -r 64 -s 2)
run(${CMAKE_COMMAND} -S "${SOURCE_DIR}/tests/install/consumer_core" -B "${WORK_DIR}/consumer_core"
    "-DCMAKE_PREFIX_PATH=${prefix}")
run(${CMAKE_COMMAND} --build "${WORK_DIR}/consumer_core")
execute_process(COMMAND "${WORK_DIR}/consumer_core/dsm_consumer_core" "${WORK_DIR}/map.dsm" "${WORK_DIR}/points.txt"
  RESULT_VARIABLE rc OUTPUT_VARIABLE consumer ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "dsm_consumer_core failed (${rc}): ${err}")
endif()
execute_process(COMMAND ${DSM_LOOKUP} "${WORK_DIR}/map.dsm" --input "${WORK_DIR}/points.txt"
  RESULT_VARIABLE rc OUTPUT_VARIABLE tool ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "dsm-lookup failed (${rc}): ${err}")
endif()
string(REGEX MATCHALL "\n" lines "${consumer}")
list(LENGTH lines count)
if(NOT count EQUAL 1000)
  message(FATAL_ERROR "dsm_consumer_core printed ${count} answers, expected 1000")
endif()
if(NOT consumer STREQUAL tool)
  message(FATAL_ERROR "dsm_consumer_core and dsm-lookup differ on the same points")
endif()
string(REGEX MATCHALL "(^|\n)0\\.[0-9]" shadowed "${consumer}")
if(NOT shadowed)
  message(FATAL_ERROR "no point of the 1000 is in shadow: the check would prove nothing")
endif()
message(STATUS "dsm::core consumer (${MODE}): 1000 lookups match dsm-lookup")

# (b) A C99 consumer of the C API belongs here, beside the C++ one.

if(MODE STREQUAL "static")
  run(${CMAKE_COMMAND} -S "${CONSUMER_DIR}" -B "${WORK_DIR}/consumer" "-DCMAKE_PREFIX_PATH=${prefix}")
  run(${CMAKE_COMMAND} --build "${WORK_DIR}/consumer")
  run("${WORK_DIR}/consumer/dsm_consumer")
  message(STATUS "find_package(dsm CONFIG) from ${prefix}: ok")
endif()

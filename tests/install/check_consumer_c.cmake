# The C99 consumer (consumer_c/main.c) against dsm-lookup: a map made by
# dsm-build, 1,000 points looked up through the C API must print exactly as
# dsm-lookup prints them for the same points.
# -DDSM_BUILD, -DDSM_LOOKUP, -DCONSUMER (the built consumer), -DEXAMPLES_DIR, -DWORK_DIR.
file(REMOVE_RECURSE "${WORK_DIR}")
file(MAKE_DIRECTORY "${WORK_DIR}")
function(run)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "command failed (${rc}): ${ARGN}\n${out}\n${err}")
  endif()
  set(OUT "${out}" PARENT_SCOPE)
endfunction()
set(map "${WORK_DIR}/area-light.dsm")
set(points "${WORK_DIR}/points.txt")
run("${DSM_BUILD}" "${EXAMPLES_DIR}/area-light.json" -o "${map}" --resolution 64 --spp 4 --threads 2 --quiet)
run("${CONSUMER}" "${map}" "${points}")
run("${DSM_LOOKUP}" "${map}" --space light --error-bound --input "${points}")
file(WRITE "${WORK_DIR}/expected.csv" "${OUT}")
run("${CONSUMER}" "${map}" "${points}" "${WORK_DIR}/expected.csv")
message(STATUS "${OUT}")

# The independent reader spec/dsm_reader.py (written from spec/dsm-format.md,
# standard library and NumPy) against libdsm's reader: every pixel of every
# level, bit for bit, of maps covering both format versions, both tile
# layouts, value steps, RGB, counts, layers, mip levels, empty and stored
# tiles, plus the committed samples (one of the first 1.1 depth coding) and
# the dsm-info sample map.
#
# cmake -DPYTHON=... -DREADER=... -DFORMAT_MAPS=... -DMAKE_SAMPLE_MAP=...
#       -DSAMPLES_DIR=... -DWORK_DIR=... -P check_python_reader.cmake

file(REMOVE_RECURSE "${WORK_DIR}")
file(MAKE_DIRECTORY "${WORK_DIR}")
execute_process(COMMAND ${FORMAT_MAPS} write "${WORK_DIR}" RESULT_VARIABLE rc ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "format_maps write failed (${rc}): ${err}")
endif()
execute_process(COMMAND ${MAKE_SAMPLE_MAP} "${WORK_DIR}/tool-sample.dsm" RESULT_VARIABLE rc ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "make_sample_map failed (${rc}): ${err}")
endif()
file(GLOB samples "${SAMPLES_DIR}/*.dsm")
# rich-first-coding.dsm is the only map of the first 1.1 depth coding (no
# PREDICTED_DEPTHS): today's writer makes none, so both readers' decoding of
# it is checked through the committed sample alone.
list(FIND samples "${SAMPLES_DIR}/rich-first-coding.dsm" first_coding)
if(first_coding EQUAL -1)
  message(FATAL_ERROR "spec/samples/rich-first-coding.dsm is missing")
endif()
file(GLOB generated "${WORK_DIR}/*.dsm")
set(maps ${samples} ${generated})
list(LENGTH maps count)
if(count LESS 10)
  message(FATAL_ERROR "only ${count} maps to compare")
endif()
foreach(map IN LISTS maps)
  execute_process(COMMAND ${FORMAT_MAPS} dump "${map}" RESULT_VARIABLE rc OUTPUT_VARIABLE expected ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "libdsm cannot read '${map}' (${rc}): ${err}")
  endif()
  execute_process(COMMAND ${PYTHON} "${READER}" "${map}" RESULT_VARIABLE rc OUTPUT_VARIABLE actual ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "spec/dsm_reader.py cannot read '${map}' (${rc}): ${err}")
  endif()
  if(expected STREQUAL "")
    message(FATAL_ERROR "'${map}': libdsm's dump is empty")
  endif()
  if(NOT actual STREQUAL expected)
    file(WRITE "${WORK_DIR}/expected.txt" "${expected}")
    file(WRITE "${WORK_DIR}/actual.txt" "${actual}")
    message(FATAL_ERROR "'${map}': the readers disagree (see ${WORK_DIR}/expected.txt and actual.txt)")
  endif()
endforeach()
message(STATUS "${count} maps read identically by both readers")

# What every dsm-* tool refuses and how it bounds its work (docs/robustness.md):
# thread counts, inputs that are not regular files, option values, standard
# input, hostile EXR headers, memory, and where dsm-lookup reports bad queries.
#
#   cmake -DCHECK=<check> -DDSM_BUILD=... -DDSM_INFO=... -DDSM_MERGE=... -DDSM_LOOKUP=...
#         -DDSM_CONVERT=... -DMAKE_SAMPLE_MAP=... -DEXAMPLES_DIR=<examples/> -DPYTHON=<python3>
#         -DWORK_DIR=<fresh dir> -P check_tool_limits.cmake
#
# Checks: threads fifo options exr_bounds stdin_limit stdin_empty exr_header out_of_memory
#         build_estimate lookup_errors_inline lookup_errors_quiet.
# Every command runs under a timeout: a hang fails the check instead of the suite.
cmake_minimum_required(VERSION 3.25)

foreach(var CHECK DSM_BUILD DSM_INFO DSM_MERGE DSM_LOOKUP DSM_CONVERT MAKE_SAMPLE_MAP EXAMPLES_DIR PYTHON WORK_DIR)
  if(NOT DEFINED ${var})
    message(FATAL_ERROR "check_tool_limits.cmake: -D${var}=... is required")
  endif()
endforeach()

include("${CMAKE_CURRENT_LIST_DIR}/check_common.cmake")

# run_limited(label [INPUT file] [ENV var=value...] COMMAND program args...):
# runs it for at most 20 seconds; sets RC, OUT, ERR and LAST_COMMAND.
function(run_limited label)
  cmake_parse_arguments(PARSE_ARGV 1 arg "" "INPUT" "ENV;COMMAND")
  set(input_args)
  if(arg_INPUT)
    set(input_args INPUT_FILE "${arg_INPUT}")
  endif()
  execute_process(COMMAND ${CMAKE_COMMAND} -E env ${arg_ENV} ${arg_COMMAND}
    ${input_args} TIMEOUT 20 RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  set(RC "${rc}" PARENT_SCOPE)
  set(OUT "${out}" PARENT_SCOPE)
  set(ERR "${err}" PARENT_SCOPE)
  set(LAST_COMMAND "${label}: ${arg_COMMAND}" PARENT_SCOPE)
endfunction()

function(expect_not_contains var text)
  string(FIND "${${var}}" "${text}" at)
  if(NOT at EQUAL -1)
    fail("expected ${var} not to contain '${text}'")
  endif()
endfunction()

# The directory holds no file at all.
function(expect_empty_dir dir)
  file(GLOB left "${dir}/*" "${dir}/.*")
  if(left)
    fail("expected ${dir} to be empty, found: ${left}")
  endif()
endfunction()

file(REMOVE_RECURSE "${WORK_DIR}")
file(MAKE_DIRECTORY "${WORK_DIR}")
set(SCENE "${EXAMPLES_DIR}/leaves.json")
set(MAP "${WORK_DIR}/sample.dsm")
execute_process(COMMAND "${MAKE_SAMPLE_MAP}" "${MAP}" RESULT_VARIABLE rc ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "make_sample_map failed: ${err}")
endif()

if(CHECK STREQUAL "threads")
  # More threads than cores: clamped, said in one line, no TBB warning; a count
  # near INT_MAX used to crash before writing (leaving a temporary file) and
  # 70000 in TBB's arena destructor.
  foreach(threads 70000 2147483647 4294967295)
    set(out "${WORK_DIR}/threads-${threads}.dsm")
    run_limited(dsm-build COMMAND "${DSM_BUILD}" "${SCENE}" -o "${out}" -r 16 --spp 1 --threads ${threads})
    expect_rc(0)
    # The note comes first, once, in one line; the rest is the progress.
    expect_matches(ERR "^dsm-build: --threads ${threads} is more than the [0-9]+ cores? this process may use; using [0-9]+\n")
    string(REGEX MATCHALL "--threads" notes "${ERR}")
    list(LENGTH notes count)
    if(NOT count EQUAL 1)
      fail("expected one note about --threads")
    endif()
    expect_not_contains(ERR "TBB")
    run_limited(dsm-info COMMAND "${DSM_INFO}" --verify "${out}")
    expect_rc(0)
  endforeach()
  # Quiet: clamped without a word.
  run_limited(dsm-build COMMAND "${DSM_BUILD}" "${SCENE}" -o "${WORK_DIR}/quiet.dsm" -r 16 --spp 1 --threads 70000 -q)
  expect_rc(0)
  expect_empty(ERR)
  file(GLOB temporaries "${WORK_DIR}/.*tmp*")
  if(temporaries)
    fail("temporary files left: ${temporaries}")
  endif()

elseif(CHECK STREQUAL "fifo")
  # A FIFO as any input is refused at once ("not a regular file"), never
  # opened blocking; nobody ever writes to it.
  foreach(name fifo.dsm fifo.exr fifo.json queries.fifo)
    execute_process(COMMAND mkfifo "${WORK_DIR}/${name}" RESULT_VARIABLE rc)
    if(NOT rc EQUAL 0)
      message(FATAL_ERROR "mkfifo failed")
    endif()
  endforeach()
  set(fifo "${WORK_DIR}/fifo.dsm")
  foreach(command
      "dsm-info|${DSM_INFO}|${fifo}"
      "dsm-info|${DSM_INFO}|--verify|${fifo}"
      "dsm-lookup|${DSM_LOOKUP}|${fifo}|--point|0,0,1"
      "dsm-merge|${DSM_MERGE}|${fifo}|${MAP}|-o|${WORK_DIR}/merged.dsm"
      "dsm-convert|${DSM_CONVERT}|${fifo}|${WORK_DIR}/out.exr"
      "dsm-convert|${DSM_CONVERT}|${WORK_DIR}/fifo.exr|${WORK_DIR}/out.dsm"
      "dsm-build|${DSM_BUILD}|${WORK_DIR}/fifo.json|-o|${WORK_DIR}/built.dsm")
    string(REPLACE "|" ";" command "${command}")
    list(POP_FRONT command tool)
    run_limited(${tool} COMMAND ${command})
    expect_rc(1)
    expect_error_line("${tool}: ERROR ")
    expect_contains(ERR "not a regular file")
  endforeach()
  run_limited(dsm-lookup COMMAND "${DSM_LOOKUP}" "${MAP}" --input "${WORK_DIR}/queries.fifo")
  expect_rc(1)
  expect_error_line("dsm-lookup: ERROR '${WORK_DIR}/queries.fifo': ")
  expect_contains(ERR "not a regular file")
  # Standard input through "-" still works, for the map and for the queries.
  run_limited(dsm-info INPUT "${MAP}" COMMAND "${DSM_INFO}" --verify -)
  expect_rc(0)
  file(WRITE "${WORK_DIR}/queries.txt" "0 0 1\n")
  run_limited(dsm-lookup INPUT "${WORK_DIR}/queries.txt" COMMAND "${DSM_LOOKUP}" "${MAP}" --space raster --input -)
  expect_rc(0)

elseif(CHECK STREQUAL "options")
  # Every value below used to be accepted: NaN silently became the default,
  # a seed above 2^64 was clamped, an empty region meant the whole map, -1
  # wrapped around to 4294967295. Each is a usage error now (status 2), and
  # nothing is written.
  execute_process(COMMAND "${DSM_CONVERT}" -q "${MAP}" "${WORK_DIR}/sample.exr" RESULT_VARIABLE rc)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "dsm-convert could not make the sample EXR")
  endif()
  set(EXR "${WORK_DIR}/sample.exr")
  set(out "${WORK_DIR}/out")
  foreach(command
      "dsm-merge|${DSM_MERGE}|${MAP}|-o|${out}.dsm|--tolerance|nan"
      "dsm-merge|${DSM_MERGE}|${MAP}|-o|${out}.dsm|--tolerance|inf"
      "dsm-merge|${DSM_MERGE}|${MAP}|-o|${out}.dsm|--zlib-level|-1"
      "dsm-convert|${DSM_CONVERT}|${EXR}|${out}.dsm|-e|nan"
      "dsm-convert|${DSM_CONVERT}|${EXR}|${out}.dsm|--max-linear-error|nan"
      "dsm-convert|${DSM_CONVERT}|${EXR}|${out}.dsm|--ortho-width|nan"
      "dsm-convert|${DSM_CONVERT}|${EXR}|${out}.dsm|--tile-size|-1"
      "dsm-convert|${DSM_CONVERT}|${MAP}|${out}.exr|--max-deviation|nan"
      "dsm-convert|${DSM_CONVERT}|${MAP}|${out}.exr|--level|-1"
      "dsm-lookup|${DSM_LOOKUP}|${MAP}|--point|0,0,1|--cache-mb|nan"
      "dsm-lookup|${DSM_LOOKUP}|${MAP}|--point|0,0,1|--filter-width|nan"
      "dsm-lookup|${DSM_LOOKUP}|${MAP}|--point|0,0,1|--area-light|disk:1|--seed|18446744073709551616"
      "dsm-lookup|${DSM_LOOKUP}|${MAP}|--point|0,0,1|--area-light|disk:1|--z-threshold|inf"
      "dsm-info|${DSM_INFO}|${MAP}|--pixel|0,0|--level|-1"
      "dsm-build|${DSM_BUILD}|${SCENE}|-o|${out}.dsm|-r|16|--seed|18446744073709551616"
      "dsm-build|${DSM_BUILD}|${SCENE}|-o|${out}.dsm|-r|16|--region|0,0,0,0"
      "dsm-build|${DSM_BUILD}|${SCENE}|-o|${out}.dsm|-r|16|--region|-1,0,8,8"
      "dsm-build|${DSM_BUILD}|${SCENE}|-o|${out}.dsm|-r|16|--region|0,0,4294967296,8"
      "dsm-build|${DSM_BUILD}|${SCENE}|-o|${out}.dsm|-r|16|--filter-width|nan"
      "dsm-build|${DSM_BUILD}|${SCENE}|-o|${out}.dsm|-r|16|--tolerance|nan"
      "dsm-build|${DSM_BUILD}|${SCENE}|-o|${out}.dsm|-r|16|--tolerance|inf"
      "dsm-build|${DSM_BUILD}|${SCENE}|-o|${out}.dsm|-r|16|--mip-levels|1e30"
      "dsm-build|${DSM_BUILD}|${SCENE}|-o|${out}.dsm|-r|16|--spp|-1"
      "dsm-build|${DSM_BUILD}|${SCENE}|-o|${out}.dsm|-r|16|--threads|-1")
    string(REPLACE "|" ";" command "${command}")
    list(POP_FRONT command tool)
    run_limited(${tool} COMMAND ${command})
    expect_rc(2)
    expect_empty(OUT)
    expect_matches(ERR "^${tool}: ")
    expect_no_file("${out}.dsm")
    expect_no_file("${out}.exr")
  endforeach()
  # The same values in range are accepted.
  run_limited(dsm-build COMMAND "${DSM_BUILD}" "${SCENE}" -o "${out}.dsm" -r 16 --spp 1 -q
              --seed 18446744073709551615 --region 0,0,8,8)
  expect_rc(0)

elseif(CHECK STREQUAL "exr_bounds")
  # float32 cannot resolve error bounds below 1e-6: --max-deviation 1e-12 grew
  # to gigabytes, --max-linear-error 1e-300 never ended. Refused at once.
  execute_process(COMMAND "${DSM_CONVERT}" -q "${MAP}" "${WORK_DIR}/sample.exr" RESULT_VARIABLE rc)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "dsm-convert could not make the sample EXR")
  endif()
  foreach(args "${MAP};${WORK_DIR}/out.exr;--max-deviation;1e-12"
               "${MAP};${WORK_DIR}/out.exr;--max-deviation;9e-7"
               "${MAP};${WORK_DIR}/out.exr;--max-deviation;2"
               "${WORK_DIR}/sample.exr;${WORK_DIR}/out.dsm;--max-linear-error;1e-9"
               "${WORK_DIR}/sample.exr;${WORK_DIR}/out.dsm;--max-linear-error;1e-300")
    run_limited(dsm-convert COMMAND "${DSM_CONVERT}" ${args})
    expect_rc(2)
    expect_contains(ERR "[1e-06, 1]")
    expect_no_file("${WORK_DIR}/out.exr")
    expect_no_file("${WORK_DIR}/out.dsm")
  endforeach()
  # The floor itself is accepted and finishes.
  run_limited(dsm-convert COMMAND "${DSM_CONVERT}" -q "${MAP}" "${WORK_DIR}/floor.exr" --max-deviation 1e-6)
  expect_rc(0)
  run_limited(dsm-convert COMMAND "${DSM_CONVERT}" -q "${WORK_DIR}/sample.exr" "${WORK_DIR}/floor.dsm"
              --max-linear-error 1e-6)
  expect_rc(0)

elseif(CHECK STREQUAL "stdin_limit")
  # An endless standard input is copied up to the limit (DSM_STDIN_LIMIT,
  # 64 KiB here), then refused; the copy never outlives the tool.
  set(tmp "${WORK_DIR}/tmp")
  file(MAKE_DIRECTORY "${tmp}")
  foreach(command "dsm-info|${DSM_INFO}|-"
                  "dsm-convert|${DSM_CONVERT}|-|${WORK_DIR}/out.exr"
                  "dsm-lookup|${DSM_LOOKUP}|-|--point|0,0,1")
    string(REPLACE "|" ";" command "${command}")
    list(POP_FRONT command tool)
    run_limited(${tool} INPUT /dev/zero ENV TMPDIR=${tmp} DSM_STDIN_LIMIT=64K COMMAND ${command})
    expect_rc(1)
    expect_error_line("${tool}: ERROR '<stdin>': longer than the limit of 64 KiB")
    expect_contains(ERR "DSM_STDIN_LIMIT")
    expect_empty_dir("${tmp}")
  endforeach()
  # Within the limit it reads.
  run_limited(dsm-info INPUT "${MAP}" ENV TMPDIR=${tmp} DSM_STDIN_LIMIT=1M COMMAND "${DSM_INFO}" --verify -)
  expect_rc(0)
  expect_empty_dir("${tmp}")
  # A malformed limit is an error, not a silent default.
  run_limited(dsm-info INPUT "${MAP}" ENV TMPDIR=${tmp} DSM_STDIN_LIMIT=lots COMMAND "${DSM_INFO}" -)
  expect_rc(1)
  expect_contains(ERR "DSM_STDIN_LIMIT")

elseif(CHECK STREQUAL "stdin_empty")
  # Empty standard input used to leave $TMPDIR/dsm-stdin-* behind on every call.
  set(tmp "${WORK_DIR}/tmp")
  file(MAKE_DIRECTORY "${tmp}")
  file(WRITE "${WORK_DIR}/empty" "")
  foreach(command "dsm-info|${DSM_INFO}|-"
                  "dsm-info|${DSM_INFO}|--verify|-"
                  "dsm-convert|${DSM_CONVERT}|-|${WORK_DIR}/out.exr"
                  "dsm-lookup|${DSM_LOOKUP}|-|--point|0,0,1")
    string(REPLACE "|" ";" command "${command}")
    list(POP_FRONT command tool)
    run_limited(${tool} INPUT "${WORK_DIR}/empty" ENV TMPDIR=${tmp} COMMAND ${command})
    expect_rc(1)
    expect_error_line("${tool}: ERROR '<stdin>': empty")
    expect_empty_dir("${tmp}")
  endforeach()
  # Nor does a successful read leave anything.
  run_limited(dsm-info INPUT "${MAP}" ENV TMPDIR=${tmp} COMMAND "${DSM_INFO}" -)
  expect_rc(0)
  expect_empty_dir("${tmp}")

elseif(CHECK STREQUAL "exr_header")
  # A 4 KiB EXR whose header has a string attribute claiming 1.8 GB: OpenEXR
  # would allocate (and fill) it before failing. Refused as corrupt from the
  # file's size, with a small peak memory.
  set(exr "${WORK_DIR}/huge-attribute.exr")
  execute_process(COMMAND "${PYTHON}" -c [=[
import struct, sys
def attribute(name, kind, value, size=None):
    return name + b"\0" + kind + b"\0" + struct.pack("<i", len(value) if size is None else size) + value
header = b"\x76\x2f\x31\x01" + struct.pack("<I", 2 | 0x800)
header += attribute(b"type", b"string", b"deepscanline")
header += attribute(b"comments", b"string", b"x" * 16, size=0x6c000000)
with open(sys.argv[1], "wb") as f:
    f.write(header + bytes(4096 - len(header)))
]=] "${exr}" RESULT_VARIABLE rc)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "could not write ${exr}")
  endif()
  set(rss "${WORK_DIR}/max-rss-kib")
  run_limited(dsm-convert COMMAND /usr/bin/time -f %M -o "${rss}" "${DSM_CONVERT}" "${exr}" "${WORK_DIR}/out.dsm")
  expect_rc(1)
  expect_error_line("dsm-convert: ERROR '${exr}': header attribute 'comments' (string) claims 1811939328 bytes")
  expect_no_file("${WORK_DIR}/out.dsm")
  file(READ "${rss}" kib)
  string(STRIP "${kib}" kib)
  if(kib GREATER 262144)
    fail("peak memory ${kib} KiB: more than 256 MiB for a 4 KiB file")
  endif()

elseif(CHECK STREQUAL "out_of_memory")
  # An allocation failure is one error line, not a bare std::bad_alloc. A
  # 131072^2 build under a 512 MiB address-space cap runs out at once.
  run_limited(dsm-build COMMAND prlimit --as=536870912 "${DSM_BUILD}" "${SCENE}" -o "${WORK_DIR}/big.dsm"
              -r 131072 --spp 1 -q)
  expect_rc(1)
  expect_error_line("dsm-build: ERROR ")
  expect_contains(ERR "out of memory")
  expect_not_contains(ERR "bad_alloc")
  expect_no_file("${WORK_DIR}/big.dsm")

elseif(CHECK STREQUAL "build_estimate")
  # Above 16384^2 pixels dsm-build says what it is about to do, in one line,
  # before starting (here it is then stopped after 3 s of CPU time).
  run_limited(dsm-build COMMAND prlimit --cpu=3 "${DSM_BUILD}" "${SCENE}" -o "${WORK_DIR}/big.dsm"
              -r 20000 --spp 4)
  expect_matches(ERR "^dsm-build: 20000 x 20000 pixels x 4 samples = 1600000000 sample rays, about [0-9.]+ (MiB|GiB) of memory")
  # A small build says nothing of the kind.
  run_limited(dsm-build COMMAND "${DSM_BUILD}" "${SCENE}" -o "${WORK_DIR}/small.dsm" -r 16 --spp 1)
  expect_rc(0)
  expect_not_contains(ERR "sample rays")

elseif(CHECK STREQUAL "lookup_errors_inline")
  # A client that reads only standard output and never drains standard error:
  # with --errors inline it gets an answer for each of 10,000 bad lines (with
  # --errors stderr it stalled once the unread error pipe filled).
  execute_process(COMMAND "${PYTHON}" -c [=[
import subprocess, sys, threading
lookup, map_path = sys.argv[1], sys.argv[2]
process = subprocess.Popen([lookup, map_path, "--errors", "inline"], stdin=subprocess.PIPE,
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE)
watchdog = threading.Timer(30, process.kill)
watchdog.start()
def feed():
    try:
        for i in range(10000):
            process.stdin.write(b"1 2\n")
        process.stdin.close()
    except BrokenPipeError:
        pass
threading.Thread(target=feed, daemon=True).start()
answers = process.stdout.read().decode().splitlines()
status = process.wait()
watchdog.cancel()
if len(answers) != 10000:
    sys.exit(f"expected 10000 answers, got {len(answers)} (status {status})")
expected = 'nan,nan,nan,"line 1: expected 3 numbers (x y z), found 2 fields"'
if answers[0] != expected:
    sys.exit(f"first answer {answers[0]!r}, expected {expected!r}")
if not all(a.startswith("nan,nan,nan,\"line ") for a in answers):
    sys.exit("an answer is not an inline error")
if status != 1:
    sys.exit(f"exit status {status}, expected 1")
]=] "${DSM_LOOKUP}" "${MAP}" RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err TIMEOUT 60)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "inline errors: ${rc}\n${out}\n${err}")
  endif()
  # Good answers get an empty error column, so every row has the same columns;
  # JSON answers carry the error in the answer object.
  file(WRITE "${WORK_DIR}/queries.txt" "0 0 1\n1 2\n")
  run_limited(dsm-lookup INPUT "${WORK_DIR}/queries.txt"
              COMMAND "${DSM_LOOKUP}" "${MAP}" --space raster --errors inline --header)
  expect_rc(1)
  expect_empty(ERR)
  expect_matches(OUT "^r,g,b,error\n[0-9.e+-]+,[0-9.e+-]+,[0-9.e+-]+,\nnan,nan,nan,\"line 2: expected 3 numbers")
  run_limited(dsm-lookup INPUT "${WORK_DIR}/queries.txt"
              COMMAND "${DSM_LOOKUP}" "${MAP}" --space raster --errors inline --format json)
  expect_rc(1)
  expect_empty(ERR)
  expect_contains(OUT "{\"line\":2,\"error\":\"expected 3 numbers (x y z), found 2 fields\"}")

elseif(CHECK STREQUAL "lookup_errors_quiet")
  # --errors quiet: the placeholder answers only, nothing on standard error.
  set(lines "")
  foreach(i RANGE 1 10000)
    string(APPEND lines "1 2\n")
  endforeach()
  file(WRITE "${WORK_DIR}/bad.txt" "${lines}")
  run_limited(dsm-lookup INPUT "${WORK_DIR}/bad.txt" COMMAND "${DSM_LOOKUP}" "${MAP}" --errors quiet)
  expect_rc(1)
  expect_empty(ERR)
  string(REGEX MATCHALL "nan,nan,nan\n" answers "${OUT}")
  list(LENGTH answers count)
  if(NOT count EQUAL 10000)
    fail("expected 10000 placeholder answers, got ${count}")
  endif()
  run_limited(dsm-lookup INPUT "${WORK_DIR}/bad.txt" COMMAND "${DSM_LOOKUP}" "${MAP}" --errors loud)
  expect_rc(2)

else()
  message(FATAL_ERROR "check_tool_limits.cmake: unknown CHECK '${CHECK}'")
endif()

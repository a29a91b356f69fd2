# Helpers shared by the tool checks (check_dsm_*.cmake): run a tool and check
# its exit status, output and JSON. A check script includes this file and
# defines run(args...) as run_tool() of its own program.

# run_tool(program label args...): runs it; sets RC, OUT, ERR and LAST_COMMAND
# in the caller of run().
macro(run_tool program label)
  execute_process(COMMAND ${program} ${ARGN}
    RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  set(RC "${rc}" PARENT_SCOPE)
  set(OUT "${out}" PARENT_SCOPE)
  set(ERR "${err}" PARENT_SCOPE)
  set(LAST_COMMAND "${label} ${ARGN}" PARENT_SCOPE)
endmacro()

function(fail what)
  message(FATAL_ERROR "${what}\n  command: ${LAST_COMMAND}\n  exit: ${RC}\n"
                      "  stdout:\n${OUT}\n  stderr:\n${ERR}")
endfunction()

function(expect_rc expected)
  if(NOT "${RC}" STREQUAL "${expected}")
    fail("expected exit status ${expected}")
  endif()
endfunction()

# expect_contains(VAR text): the variable's value contains text (literally).
function(expect_contains var text)
  string(FIND "${${var}}" "${text}" at)
  if(at EQUAL -1)
    fail("expected ${var} to contain '${text}'")
  endif()
endfunction()

function(expect_matches var regex)
  if(NOT "${${var}}" MATCHES "${regex}")
    fail("expected ${var} to match '${regex}'")
  endif()
endfunction()

function(expect_empty var)
  if(NOT "${${var}}" STREQUAL "")
    fail("expected ${var} to be empty")
  endif()
endfunction()

function(json_expect json expected)
  string(JSON value ERROR_VARIABLE error GET "${json}" ${ARGN})
  if(error)
    fail("JSON: ${error}")
  endif()
  if(NOT "${value}" STREQUAL "${expected}")
    fail("JSON ${ARGN}: expected '${expected}', got '${value}'")
  endif()
endfunction()

function(json_expect_type json expected)
  string(JSON value ERROR_VARIABLE error TYPE "${json}" ${ARGN})
  if(error)
    fail("JSON: ${error}")
  endif()
  if(NOT "${value}" STREQUAL "${expected}")
    fail("JSON ${ARGN}: expected type ${expected}, got ${value}")
  endif()
endfunction()

# expect_error_line(prefix): exactly one line on stderr, starting with prefix
# (the tools' convention: "<tool>: ERROR '<file>': <message>").
function(expect_error_line prefix)
  string(REGEX MATCHALL "\n" newlines "${ERR}")
  list(LENGTH newlines lines)
  if(NOT lines EQUAL 1)
    fail("expected exactly one line on stderr")
  endif()
  string(FIND "${ERR}" "${prefix}" at)
  if(NOT at EQUAL 0)
    fail("expected stderr to start with \"${prefix}\"")
  endif()
endfunction()

# expect_no_file(path): a failed run left no file behind.
function(expect_no_file path)
  if(EXISTS "${path}")
    fail("expected no file '${path}' after a failed run")
  endif()
endfunction()

# Runs a test program and passes only when it exits with 0 AND its output matches a pattern.
# (CTest's PASS_REGULAR_EXPRESSION alone would ignore the exit code.)
#   cmake -DCOMMAND=<program;args...> -DEXPECT=<regex> -P run_and_match.cmake
if(NOT DEFINED COMMAND OR NOT DEFINED EXPECT)
  message(FATAL_ERROR "run_and_match.cmake: pass -DCOMMAND=<program;args> and -DEXPECT=<regex>")
endif()
execute_process(COMMAND ${COMMAND} RESULT_VARIABLE status OUTPUT_VARIABLE out ERROR_VARIABLE err)
message("${out}${err}")
if(NOT status STREQUAL "0")
  message(FATAL_ERROR "'${COMMAND}' exited with ${status}")
endif()
if(NOT out MATCHES "${EXPECT}")
  message(FATAL_ERROR "'${COMMAND}' exited with 0 but its output does not match '${EXPECT}'")
endif()

# Writes OUT (a C header) with NH_GIT_REVISION = `git describe --always
# --dirty --abbrev=12` of SRC, or "unknown" outside a git checkout. Run at
# every build (target nh_git_revision); the file is rewritten only when the
# revision changed, so main.c is recompiled only then.
execute_process(COMMAND git -C "${SRC}" describe --always --dirty --abbrev=12
  OUTPUT_VARIABLE rev OUTPUT_STRIP_TRAILING_WHITESPACE ERROR_QUIET RESULT_VARIABLE rc)
if(NOT rc EQUAL 0 OR rev STREQUAL "")
  set(rev "unknown")
endif()
set(text "#define NH_GIT_REVISION \"${rev}\"\n")
if(EXISTS "${OUT}")
  file(READ "${OUT}" old)
endif()
if(NOT "${old}" STREQUAL "${text}")
  file(WRITE "${OUT}" "${text}")
endif()

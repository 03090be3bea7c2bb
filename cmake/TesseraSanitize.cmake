# Sanitizer builds (docs/testing.md). TESSERA_SANITIZE adds the flags to every target:
#   -DTESSERA_SANITIZE=address,undefined   ASan + UBSan (build-asan/ of scripts/test.sh)
#   -DTESSERA_SANITIZE=thread              TSan (build-tsan/)
# UBSan's checks stay recoverable so that tests/sanitizers/ubsan.supp can name third-party
# code; the tests run with UBSAN_OPTIONS=halt_on_error=1 (tests/CMakeLists.txt), so every
# other report ends the process and fails its test. The dependencies
# (CAF, Embree, TBB, websocketpp's asio) come from Debian and are not instrumented: see
# tests/sanitizers/ for the runtime options and suppressions the tests run with.
#
# TESSERA_FUZZ (clang only) builds the libFuzzer targets of tests/fuzz and adds libFuzzer's
# coverage instrumentation (-fsanitize=fuzzer-no-link) to every target, so one ASan build
# serves both the suite and the fuzzers. Without it the fuzz targets are built as plain
# executables that replay their checked-in corpus once (any compiler).
set(TESSERA_SANITIZE "" CACHE STRING "Sanitizers for every target: address,undefined | thread | empty")
option(TESSERA_FUZZ "Build the libFuzzer targets (clang; adds coverage instrumentation everywhere)" OFF)

if(TESSERA_SANITIZE)
  if(TESSERA_SANITIZE MATCHES "thread" AND TESSERA_SANITIZE MATCHES "address")
    message(FATAL_ERROR "TESSERA_SANITIZE: thread and address cannot be combined")
  endif()
  add_compile_options(-fsanitize=${TESSERA_SANITIZE} -fno-omit-frame-pointer)
  add_link_options(-fsanitize=${TESSERA_SANITIZE})
  message(STATUS "Tessera: sanitizers ${TESSERA_SANITIZE} on every target")
endif()

if(TESSERA_FUZZ)
  if(NOT CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
    message(FATAL_ERROR "TESSERA_FUZZ needs clang (libFuzzer): -DCMAKE_CXX_COMPILER=clang++")
  endif()
  add_compile_options(-fsanitize=fuzzer-no-link)
  message(STATUS "Tessera: libFuzzer targets and coverage instrumentation on every target")
endif()

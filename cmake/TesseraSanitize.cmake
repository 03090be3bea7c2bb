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

# Under TSan, the pure compute libraries are compiled without instrumentation (they still link
# into executables that carry the TSan runtime; mixing is supported). They hold no threads, locks
# or shared state of their own: the ray tracer, rasterizer, codecs and load balancer run on TBB
# (not instrumented either) or on the calling thread, and instrumented they made rendering 5-15x
# slower, so the e2e tests missed their frame deadlines. TSan's target is the actor, session,
# server and network layers, which stay instrumented (docs/testing.md, "What TSan can and cannot
# see here"). Their calls into these libraries are still checked at the call site; accesses made
# inside them are not (nor inline/template code the linker happens to take from their objects).
# tessera_scene is in the list for its loops over scene data (e.g. Texture::has_alpha over every
# texel, called by the rasterizer's sync): that data reaches the renderer by CAF message, so
# instrumented, each texel was a (suppressed, but still stack-restored) report and the renderer
# actor stalled for minutes. A plain variable, not a cache entry, so that a change here reaches
# existing build directories.
set(TESSERA_TSAN_UNINSTRUMENTED tessera_raytracer tessera_rasterizer tessera_codecs tessera_lb tessera_scene)
function(tessera_tsan_apply_uninstrumented)
  foreach(target ${TESSERA_TSAN_UNINSTRUMENTED})
    if(NOT TARGET ${target})
      message(FATAL_ERROR "TESSERA_TSAN_UNINSTRUMENTED: no target ${target}")
    endif()
    # Comes after the directory's -fsanitize=thread on the command line, so it wins.
    target_compile_options(${target} PRIVATE -fno-sanitize=thread)
  endforeach()
  if(TESSERA_TSAN_UNINSTRUMENTED)
    message(STATUS "Tessera: TSan leaves out ${TESSERA_TSAN_UNINSTRUMENTED}")
  endif()
endfunction()
if(TESSERA_SANITIZE MATCHES "thread")
  # Runs once every directory has defined its targets (end of the top-level CMakeLists.txt).
  cmake_language(DEFER DIRECTORY ${CMAKE_SOURCE_DIR} CALL tessera_tsan_apply_uninstrumented)
endif()

if(TESSERA_FUZZ)
  if(NOT CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
    message(FATAL_ERROR "TESSERA_FUZZ needs clang (libFuzzer): -DCMAKE_CXX_COMPILER=clang++")
  endif()
  add_compile_options(-fsanitize=fuzzer-no-link)
  message(STATUS "Tessera: libFuzzer targets and coverage instrumentation on every target")
endif()

// Catch2's implementation (test registry, reporters, Session) and a main() that asks the test's
// test_prelude() first (tests/catch_runner.h). The tests that must be able to skip link this
// library instead of Catch2::Catch2WithMain, so that Catch's implementation is compiled once
// rather than in each of them (33 s a file at -O3).
#define CATCH_CONFIG_RUNNER
#include <catch2/catch.hpp>

#include "tests/catch_runner.h"

int main(int argc, char** argv) {
  if (int rc = test_prelude()) return rc;
  return Catch::Session().run(argc, argv);
}

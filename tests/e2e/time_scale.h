#pragma once
// How much slower than the Release build a test process runs: TESSERA_TEST_TIME_SCALE, which
// the sanitizer builds set for every test (tests/CMakeLists.txt: 3 under ASan, 5 under TSan),
// 1 when unset. In-test wall-clock deadlines multiply by it; checks that compare timings
// loosen or stand down where it is above 1 (docs/testing.md).
#include <cstdlib>

namespace tessera::test {

inline int time_scale() {
  const char* s = std::getenv("TESSERA_TEST_TIME_SCALE");
  int v = s ? std::atoi(s) : 1;
  return v >= 1 ? v : 1;
}

}  // namespace tessera::test

#pragma once
// For the tests that link tessera_catch_runner (tests/CMakeLists.txt, RUNNER): the library's
// main() calls the test's test_prelude() before Catch starts. A prelude returns 0 to run the
// test cases, or an exit status to end there: 77 when the test cannot run on this machine
// (CTest's SKIP_RETURN_CODE), after printing why.
int test_prelude();

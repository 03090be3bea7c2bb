// Static file resolution, MIME types and session tokens of the node's HTTP endpoint.
#include <catch2/catch.hpp>

#include "net/http.h"

using namespace tessera::http;

TEST_CASE("Static targets resolve inside the web root and nowhere else", "[unit]") {
  // Run from the repository root (CTest's working directory).
  auto demo = resolve_static("web", "/demo/index.html?x=1");
  REQUIRE(demo);
  CHECK(demo->find("/web/demo/index.html") != std::string::npos);
  CHECK(resolve_static("web", "/demo/"));
  CHECK(resolve_static("web", "/demo"));  // a directory means its index.html
  for (const char* bad : {"", "demo/index.html", "/../CMakeLists.txt", "/demo/../../CMakeLists.txt",
                          "/%2e%2e/CMakeLists.txt", "/%2E%2E%2FCMakeLists.txt", "/.hidden", "/demo/%00",
                          "/demo/index.html%00.png", "/%zz", "/demo\\..\\..\\CMakeLists.txt", "/nonexistent.html"})
    CHECK_FALSE(resolve_static("web", bad));
}

TEST_CASE("MIME types follow the file extension", "[unit]") {
  CHECK(std::string(mime_type("a/b.html")) == "text/html; charset=utf-8");
  CHECK(std::string(mime_type("x.JS")) == "text/javascript; charset=utf-8");
  CHECK(std::string(mime_type("x.png")) == "image/png");
  CHECK(std::string(mime_type("x.wasm")) == "application/wasm");
  CHECK(std::string(mime_type("dir.d/noext")) == "application/octet-stream");
}

TEST_CASE("Session tokens and query parameters", "[unit]") {
  CHECK(valid_token("abcdEFGH_-09"));
  CHECK_FALSE(valid_token("short"));
  CHECK_FALSE(valid_token("has space in it"));
  CHECK_FALSE(valid_token(std::string(65, 'a')));
  CHECK(query_param("/ws?session=abc&x=1", "session") == "abc");
  CHECK(query_param("/ws?x=1&session=abc#f", "session") == "abc");
  CHECK(query_param("/ws", "session").empty());
  CHECK(target_path("/a/b?c#d") == "/a/b");
}

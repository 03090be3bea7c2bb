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

TEST_CASE("Only the client, the demo pages, the index page and the three.js build are public", "[unit]") {
  for (const char* ok : {"index.html", "src/xml3d.js", "src/net/Protocol.js", "demo/index.html", "demo/demo.css",
                         "node_modules/three/build/three.module.js", "node_modules/three/build/three.core.js"})
    CHECK(public_path(ok));
  for (const char* no : {"package.json", "package-lock.json", "tools/static-server.js", "test/run-unit.js",
                         "node_modules/ws/index.js", "node_modules/three/package.json", "node_modules/three/src/Three.js",
                         "src", "demo/", "srcx/a.js", "index.htm"})
    CHECK_FALSE(public_path(no));
  // Run from the repository root (CTest's working directory).
  CHECK(resolve_public("web", "/demo/index.html"));
  CHECK(resolve_public("web", "/src/xml3d.js"));
  CHECK(resolve_public("web", "/demo/"));
  for (const char* no : {"/package.json", "/package-lock.json", "/tools/static-server.js", "/test/run-unit.js",
                         "/%70ackage.json", "/demo/../package.json", "/src/../tools/static-server.js"})
    CHECK_FALSE(resolve_public("web", no));
  // An operator's further public folders (tessera.web-public) add exactly those folders.
  const std::vector<std::string> extra{"test/browser/pages/"};
  CHECK(public_path("test/browser/pages/node.html", extra));
  CHECK_FALSE(public_path("test/browser/pages/node.html"));
  CHECK_FALSE(public_path("test/browser/node-e2e.test.js", extra));
  CHECK_FALSE(public_path("test/browser/pages", extra));
  CHECK(resolve_public("web", "/test/browser/pages/node.html", extra));
  CHECK_FALSE(resolve_public("web", "/test/browser/pages/../node-e2e.test.js", extra));
}

TEST_CASE("Range headers: one byte range is served, several or malformed ones mean the whole file", "[unit]") {
  ByteRange r;
  CHECK(parse_range("", 100, r) == RangeKind::full);
  CHECK(parse_range("bytes=0-9", 100, r) == RangeKind::partial);
  CHECK((r.first == 0 && r.last == 9));
  CHECK(parse_range("bytes=90-", 100, r) == RangeKind::partial);
  CHECK((r.first == 90 && r.last == 99));
  CHECK(parse_range("bytes=50-1000", 100, r) == RangeKind::partial);  // clamped to the end
  CHECK((r.first == 50 && r.last == 99));
  CHECK(parse_range("bytes=-10", 100, r) == RangeKind::partial);  // the last 10 bytes
  CHECK((r.first == 90 && r.last == 99));
  CHECK(parse_range("bytes=-1000", 100, r) == RangeKind::partial);
  CHECK((r.first == 0 && r.last == 99));
  CHECK(parse_range(" Bytes = 5 - 5 ", 100, r) == RangeKind::partial);
  CHECK((r.first == 5 && r.last == 5));
  CHECK(parse_range("bytes=99999999999999999999999-", 100, r) == RangeKind::unsatisfiable);
  CHECK(parse_range("bytes=100-", 100, r) == RangeKind::unsatisfiable);
  CHECK(parse_range("bytes=-0", 100, r) == RangeKind::unsatisfiable);
  CHECK(parse_range("bytes=0-", 0, r) == RangeKind::unsatisfiable);
  for (const char* full : {"bytes=0-1,5-6", "items=0-5", "bytes=5-1", "bytes=a-b", "bytes=", "bytes=-", "bytes 0-5",
                           "bytes=1-2-3"})
    CHECK(parse_range(full, 100, r) == RangeKind::full);
}

// A node without a usable EGL: the rasterizer's context cannot be created. A client that
// asks for the rasterizer gets a clear error, and a ray-traced client on the same node keeps
// getting frames.
//
// The missing EGL is simulated through libglvnd (Debian's libEGL): before the first EGL call,
// __EGL_VENDOR_LIBRARY_FILENAMES names a vendor file that does not exist, so no EGL vendor
// library (Mesa's libegl-mesa0) is loaded, exactly as on a machine without it. On a machine
// where that does not take away EGL (a libEGL without glvnd) the test exits 77.
#include <catch2/catch.hpp>

#include "tests/catch_runner.h"

#include <cstdio>
#include <cstdlib>

#include "renderer/rasterizer.h"
#include "tests/e2e/node_fixture.h"

using namespace tessera;
using namespace tessera::test;
using protocol::DisplayKind;

TEST_CASE("Without EGL the rasterizer throws a clear error on every call", "[fault]") {
  Rasterizer r;
  std::vector<std::string> warnings;
  Scene scene;
  for (int i = 0; i < 2; ++i) {  // the failure is remembered, not retried into something else
    try {
      r.sync(scene, warnings);
      FAIL("sync did not throw");
    } catch (const std::runtime_error& e) {
      std::string m = e.what();
      INFO(m);
      CHECK(m.find("cannot create an OpenGL ES 3 context") != std::string::npos);
      CHECK(m.find("EGL") != std::string::npos);
    }
  }
  TaskResult out;
  CHECK_THROWS_WITH(r.render({0, 0, 4, 4}, RenderSettings{}, out), Catch::Contains("OpenGL ES 3 context"));
}

TEST_CASE("Without EGL a rasterizer session gets an error and a ray tracer session keeps its frames", "[e2e][fault]") {
  TestNode node;
  const int W = 160, H = 90;
  ProtoClient gl, rt;
  REQUIRE(gl.connect(node.port()));
  REQUIRE(rt.connect(node.port()));
  REQUIRE(gl.handshake(DisplayKind::jpeg, W, H, 90, protocol::RendererKind::rasterizer));
  REQUIRE(rt.handshake(DisplayKind::jpeg, W, H, 90, protocol::RendererKind::raytracer));
  REQUIRE(gl.upload(pavilion().scene));
  REQUIRE(rt.upload(pavilion().scene));
  REQUIRE(rt.send({protocol::Settings{0, 2}}));
  REQUIRE(gl.send({protocol::SetCamera{pavilion_loop().camera(0)}, protocol::RenderRequest{1}}));
  auto e = gl.next<protocol::ErrorReply>();
  REQUIRE(e);
  INFO(e->message);
  CHECK(e->message.find("rasterizer: cannot create an OpenGL ES 3 context") != std::string::npos);
  for (uint32_t i = 0; i < 2; ++i) {
    auto f = rt.render(pavilion_loop().camera(i * 30), 5 + i);
    REQUIRE(f);
    CHECK(f->frame == 5 + i);
    CHECK(f->timings.kernel_ms > 0);
  }
  CHECK(node.count(Ev::error, [](const Event& e) { return has(e, "message", "OpenGL ES 3 context"); }) >= 1);
}

int test_prelude() {
  setenv("__EGL_VENDOR_LIBRARY_FILENAMES", "/nonexistent/tessera-test-no-egl-vendor.json", 1);
  std::string why;
  if (rasterizer_available(&why)) {
    std::printf("SKIP: this libEGL still creates a context without vendor files (not libglvnd); cannot simulate a "
                "machine without EGL\n");
    return 77;
  }
  std::printf("simulated missing EGL: %s\n", why.c_str());
  return 0;
}

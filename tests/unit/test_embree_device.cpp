// One Embree device per process (renderer/embree_device.h): ray tracers share it, it ends with
// the last of them, and it records the errors Embree reports.
#include <catch2/catch.hpp>

#include <memory>

#include "renderer/embree_device.h"
#include "renderer/raytracer.h"

using namespace tessera;

TEST_CASE("ray tracers share one Embree device that ends with the last of them", "[raytracer]") {
  REQUIRE(EmbreeDevice::live() == 0);
  {
    auto a = std::make_unique<RayTracer>();
    auto b = std::make_unique<RayTracer>();
    CHECK(EmbreeDevice::live() == 1);
    auto held = EmbreeDevice::acquire();
    a.reset();
    b.reset();
    CHECK(EmbreeDevice::live() == 1);  // still held here
  }
  CHECK(EmbreeDevice::live() == 0);
  RayTracer again;  // a new one is made after the last went
  CHECK(EmbreeDevice::live() == 1);
}

TEST_CASE("the shared device records what Embree reports", "[raytracer]") {
  auto d = EmbreeDevice::acquire();
  const uint64_t before = d->errors();
  CHECK(d->last_error().empty());
  RTCGeometry g = rtcNewGeometry(d->get(), RTCGeometryType(9999));  // no such geometry type
  CHECK(g == nullptr);
  CHECK(d->errors() == before + 1);
  CHECK(d->last_error().find("embree: ") == 0);
  CHECK(d->last_error().find("invalid geometry type") != std::string::npos);  // Embree's own words
}

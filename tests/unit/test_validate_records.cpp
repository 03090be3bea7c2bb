// Cluster workers apply forwarded client records through apply_records (actors/checks.h):
// the same validation as a client's decode (core/validate.h), so a singular, nearly
// singular or huge transform forwarded by a master (or sent straight to a worker's cluster
// port) is refused with a message and never reaches the worker's renderer.
#include <catch2/catch.hpp>

#include <caf/binary_deserializer.hpp>
#include <caf/binary_serializer.hpp>

#include "actors/checks.h"
#include "actors/node.h"
#include "protocol/protocol.h"
#include "renderer/raytracer.h"

using namespace tessera;

namespace {

Mat4 zero_matrix() {
  Mat4 z;
  z.m.fill(0);
  return z;
}

}  // namespace

TEST_CASE("apply_records refuses singular, nearly singular and huge transforms and cameras; the scene stays unchanged",
          "[stability][validate][cluster]") {
  protocol::Limits lim;
  Scene scene;
  // A triangle mesh that is fine.
  protocol::SetBuffer b;
  b.id = 1;
  b.buffer.components = 3;
  b.buffer.f = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  protocol::SetMesh good;
  good.id = 2;
  good.mesh.positions = 1;
  protocol::SetCamera cam;
  cam.camera.to_world = Mat4::look_at({0, 0, 3}, {0, 0, 0}, {0, 1, 0});
  REQUIRE(apply_records(scene, protocol::encode({b, good, cam}), lim).empty());
  const uint64_t version = scene.version();

  Mat4 one_huge;
  one_huge.m[5] = 3e38f;
  const struct {
    const char* name;
    Mat4 xf;
  } bad[] = {{"all zero", zero_matrix()},
             {"zero z-scale", Mat4::scale({1, 1, 0})},
             {"uniform scale 1e-30", Mat4::scale(Vec3{1e-30f})},
             {"scale 1e19", Mat4::scale(Vec3{1e19f})},
             {"3e38 in one element", one_huge}};
  for (const auto& c : bad) {
    INFO(c.name);
    protocol::SetMesh m;
    m.id = 3;
    m.mesh.positions = 1;
    m.mesh.transform = c.xf;
    std::string err = apply_records(scene, protocol::encode(protocol::ClientRecord{m}), lim);
    INFO(err);
    CHECK(err.find("(mesh): transform") != std::string::npos);
    protocol::SetCamera bc;
    bc.camera.to_world = c.xf;
    err = apply_records(scene, protocol::encode(protocol::ClientRecord{bc}), lim);
    INFO(err);
    CHECK(err.find("(camera): to_world") != std::string::npos);
    CHECK(scene.version() == version);
    CHECK(scene.meshes().size() == 1);
  }
  // The worker's scene still renders.
  scene.set_resolution(8, 8);
  RayTracer rt;
  std::vector<std::string> warnings;
  rt.sync(scene, warnings);
  CHECK(warnings.empty());
  TaskResult res;
  rt.render({0, 0, 8, 8}, RenderSettings{}, res);
  CHECK(res.image.width == 8);
}

// What a hostile peer's message costs before it is refused: CAF 0.17 sizes a byte vector by
// the length its stream claims, so a 40-byte message claiming 1 TiB of tile pixels threw
// std::bad_alloc (and 2^32-1 bytes made the node allocate and zero 4 GiB). BytesField
// (actors/messages.h) refuses the claim before anything is allocated.
TEST_CASE("A byte-vector field claiming more bytes than its message holds is refused before any allocation",
          "[cluster][peer]") {
  auto claim = [](uint64_t n, size_t skip_fields) {
    // skip_fields uint32/int32 fields (frame, rect), then the claimed length as CAF writes it (varbyte).
    std::vector<char> buf(skip_fields * 4, 0);
    for (uint64_t x = n;;) {
      uint8_t b = uint8_t(x & 0x7f);
      x >>= 7;
      buf.push_back(char(x ? (b | 0x80) : b));
      if (!x) break;
    }
    buf.resize(buf.size() + 16, 1);  // a few bytes of "pixels"
    return buf;
  };
  for (uint64_t n : {uint64_t(1) << 40, uint64_t(0xffffffffu), uint64_t(17)}) {
    INFO("claimed " << n << " bytes");
    auto buf = claim(n, 5);  // TileResult: frame, then the pixel rectangle (x0, y0, x1, y1)
    TileResult t;
    caf::binary_deserializer src{nullptr, buf.data(), buf.size()};
    caf::error err;
    REQUIRE_NOTHROW(err = src(t));
    CHECK(err);
    CHECK(t.rgba.capacity() <= buf.size());
    Payload p;
    auto pbuf = claim(n, 0);
    caf::binary_deserializer psrc{nullptr, pbuf.data(), pbuf.size()};
    REQUIRE_NOTHROW(err = psrc(p));
    CHECK(err);
    CHECK(p.bytes.capacity() <= pbuf.size());
  }
  // A claim the message does hold loads as before.
  TileResult ok;
  ok.frame = 3;
  ok.pixels = {0, 0, 2, 1};
  ok.rgba = {1, 2, 3, 4, 5, 6, 7, 8};
  std::vector<char> buf;
  caf::binary_serializer sink{nullptr, buf};
  REQUIRE(!sink(ok));
  TileResult back;
  caf::binary_deserializer src{nullptr, buf.data(), buf.size()};
  REQUIRE(!src(back));
  CHECK(back.rgba == ok.rgba);
  CHECK(back.frame == 3);
}

// Cluster workers apply forwarded client records through apply_records (actors/cluster.cpp):
// the same validation as a client's decode (renderer/validate.h), so a singular, nearly
// singular or huge transform forwarded by a master (or sent straight to a worker's cluster
// port) is refused with a message and never reaches the worker's renderer.
#include <catch2/catch.hpp>

#include "actors/node.h"
#include "net/protocol.h"
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

// The synthetic scene of `tessera make-scene` (app/synthetic_scene.h): it loads without a
// warning, with the triangles, textures, materials and instances it says it wrote, the same
// seed gives the same files, and a spec out of range is refused.
#include <catch2/catch.hpp>

#include <fstream>
#include <iterator>
#include <stdexcept>
#include <string>

#include "app/synthetic_scene.h"
#include "core/gltf_loader.h"
#include "tests/unit/temp_files.h"

using namespace tessera;

namespace {

std::string slurp(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
}

app::SyntheticSceneSpec small() {
  app::SyntheticSceneSpec s;
  s.unique_triangles = 20000;
  s.instanced_triangles = 65000;
  s.textures = 5;
  s.texture_size = 64;
  return s;
}

}  // namespace

TEST_CASE("a synthetic scene loads with what it says it holds") {
  test::TempDir dir("synthetic");
  const app::SyntheticSceneFigures f = app::write_synthetic_scene(dir.path, small());
  CHECK(f.unique_triangles >= 20000);
  CHECK(f.unique_triangles < 20000 + 2 * 48 * 48);  // stops at the first mesh past the count
  CHECK(f.instanced_triangles >= 65000);
  CHECK(f.textures == 5);
  CHECK(f.materials == 5);
  CHECK(f.nodes > f.meshes);  // instances beyond one node per mesh

  LoadedScene ls = load_gltf(dir.path + "/scene.gltf");
  std::string warnings;
  for (auto& w : ls.warnings) warnings += w + "\n";
  INFO("loader warnings:\n" << warnings);
  CHECK(ls.warnings.empty());
  const Scene& s = ls.scene;
  CHECK(s.triangle_count() == f.instanced_triangles);
  CHECK(s.meshes().size() == size_t(f.nodes));
  CHECK(s.textures().size() == 5);
  CHECK(s.materials().size() == 5);
  CHECK(s.lights().size() == 1);
  CHECK(ls.has_camera);
  for (auto& [id, e] : s.textures()) {
    CHECK(e.value.width == 64);
    CHECK(e.value.height == 64);
  }
  for (auto& [id, e] : s.meshes()) {
    std::string err = s.validate_mesh(e.value);
    INFO("mesh " << id << ": " << err);
    CHECK(err.empty());
  }
  // The camera looks at the scene: its centre is in front of it (glTF cameras look down -Z).
  const Vec3 centre = (ls.bounds.lo + ls.bounds.hi) * 0.5f;
  const Mat4& w = s.camera().to_world;
  const Vec3 eye{w.m[12], w.m[13], w.m[14]}, forward{-w.m[8], -w.m[9], -w.m[10]};
  CHECK(dot(centre - eye, forward) > 0);
  // The camera loop loads and looks at the courtyard too.
  CameraLoop loop = load_camera_loop(dir.path + "/camera-loop.json");
  CHECK(loop.frames.size() == 120);
  for (size_t f : {size_t(0), size_t(60)}) {
    const Mat4 m = loop.camera(f).to_world;
    CHECK(dot(centre - Vec3{m.m[12], m.m[13], m.m[14]}, Vec3{-m.m[8], -m.m[9], -m.m[10]}) > 0);
  }
}

TEST_CASE("a synthetic scene is the same for the same seed, and another for another") {
  test::TempDir a("synthetic"), b("synthetic"), c("synthetic");
  app::write_synthetic_scene(a.path, small());
  app::write_synthetic_scene(b.path, small());
  app::SyntheticSceneSpec other = small();
  other.seed = 2;
  app::write_synthetic_scene(c.path, other);
  for (const char* f : {"/scene.gltf", "/scene.bin", "/textures/t000.jpg", "/textures/t004.jpg"}) {
    INFO(f);
    CHECK(slurp(a.path + f) == slurp(b.path + f));
    CHECK(slurp(a.path + f) != slurp(c.path + f));
  }
}

TEST_CASE("a synthetic scene spec out of range is refused") {
  test::TempDir dir("synthetic");
  app::SyntheticSceneSpec s = small();
  s.instanced_triangles = s.unique_triangles - 1;
  CHECK_THROWS_AS(app::write_synthetic_scene(dir.path, s), std::invalid_argument);
  s = small();
  s.texture_size = 4;
  CHECK_THROWS_AS(app::write_synthetic_scene(dir.path, s), std::invalid_argument);
  s = small();
  s.unique_triangles = 0;
  CHECK_THROWS_AS(app::write_synthetic_scene(dir.path, s), std::invalid_argument);
}

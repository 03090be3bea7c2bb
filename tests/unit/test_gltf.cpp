// glTF loading: the three shared scenes load with the counts their READMEs state, and
// broken files throw std::runtime_error naming the file, never crash.
#include <catch2/catch.hpp>

#include "tests/unit/temp_files.h"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <unistd.h>

#include <nlohmann/json.hpp>

#include "core/gltf_loader.h"
#include "core/image.h"
#include "renderer/raytracer.h"

using namespace tessera;

namespace {

std::string scene_path(const std::string& name, const std::string& file) {
  return std::string(TESSERA_SCENES_DIR) + "/" + name + "/" + file;
}

struct Expect {
  const char* name;
  size_t triangles, textures, materials, meshes, lights;
  float extent;  // metres, from the README's "% of the ... m scene extent"
  bool sky;
};

void check_scene(const Expect& x) {
  const std::string path = scene_path(x.name, "scene.gltf");
  LoadedScene ls = load_gltf(path);
  const Scene& s = ls.scene;
  INFO(x.name);
  std::string warnings;
  for (auto& w : ls.warnings) warnings += w + "\n";
  INFO("loader warnings:\n" << warnings);
  CHECK(ls.warnings.empty());
  CHECK(s.triangle_count() == x.triangles);
  CHECK(s.textures().size() == x.textures);
  CHECK(s.materials().size() == x.materials);
  CHECK(s.meshes().size() == x.meshes);
  CHECK(s.lights().size() == x.lights);
  // Every texture was decoded into consistent RGBA8, and is referenced by a material.
  for (auto& [id, e] : s.textures()) {
    const Texture& t = e.value;
    CHECK(t.width > 0);
    CHECK(t.height > 0);
    CHECK(t.rgba.size() == size_t(t.width) * t.height * 4);
    bool used = false;
    for (auto& [mid, m] : s.materials())
      used = used || m.value.diffuse_texture == id || m.value.specular_texture == id || m.value.emissive_texture == id;
    CHECK(used);
  }
  // Every mesh passes validation.
  for (auto& [id, e] : s.meshes()) {
    std::string err = s.validate_mesh(e.value);
    INFO("mesh " << id << ": " << err);
    CHECK(err.empty());
  }
  // The camera: found in the file, not mirrored, and the camera loop starts there.
  CHECK(ls.has_camera);
  CHECK(s.camera().to_world.det3() == Approx(1.0f).margin(1e-3f));
  CameraLoop loop = load_camera_loop(scene_path(x.name, "camera-loop.json"));
  CHECK(loop.frames.size() == 240);
  Camera c0 = loop.camera(0);
  CHECK(c0.fov_y == Approx(s.camera().fov_y).margin(1e-3f));
  for (int i = 0; i < 16; ++i) CHECK(c0.to_world.m[size_t(i)] == Approx(s.camera().to_world.m[size_t(i)]).margin(2e-3f));
  // The loop is closed: frame 240 is frame 0.
  CHECK(loop.camera(240).to_world == c0.to_world);
  CHECK(ls.bounds.extent() == Approx(x.extent).epsilon(0.05));
  // Sky: an ambient term where the scene has an environment, none where it has not.
  const Environment& env = s.environment();
  CHECK(env.linear);
  if (x.sky) {
    CHECK(env.ambient.x > 0);
    CHECK(env.exposure > 0);
  } else {
    CHECK(env.ambient == Vec3{0, 0, 0});
  }
}

}  // namespace

TEST_CASE("pavilion loads: 130,503 triangles, 6 textures, the sun, water with IOR 1.33", "[gltf][scenes]") {
  check_scene({"pavilion", 130503, 6, 17, 106, 1, 168.9f, true});
  LoadedScene ls = load_gltf(scene_path("pavilion", "scene.gltf"));
  REQUIRE(ls.scene.lights().size() == 1);
  const Light& sun = ls.scene.lights().begin()->second.value;
  CHECK(sun.type == Light::Type::directional);
  // README: direction to the sun [0.3697, 0.5874, 0.72]; light travels the other way.
  Vec3 to_sun = normalize(Vec3{0.3697f, 0.5874f, 0.72f});
  CHECK(dot(normalize(sun.direction), -to_sun) == Approx(1.0f).margin(1e-3f));
  CHECK(sun.intensity == Approx(1.013f).margin(1e-3f));
  bool water = false, glass = false;
  for (auto& [id, e] : ls.scene.materials()) {
    if (e.value.refraction > 0 && std::fabs(e.value.ior - 1.33f) < 1e-3f) water = true;
    if (e.value.refraction > 0 && std::fabs(e.value.ior - 1.5f) < 1e-3f) glass = true;
  }
  CHECK(water);
  CHECK(glass);
}

TEST_CASE("living-room loads: 143,035 triangles, 4 textures, no lights, alpha-masked leaves, a mirror", "[gltf][scenes]") {
  check_scene({"living-room", 143035, 4, 19, 65, 0, 7.6f, true});
  LoadedScene ls = load_gltf(scene_path("living-room", "scene.gltf"));
  bool masked = false, mirror = false, glass = false;
  for (auto& [id, e] : ls.scene.materials()) {
    const Material& m = e.value;
    if (m.alpha_mask) {
      masked = true;
      CHECK(m.alpha_cutoff == Approx(0.5f));
      const Texture* t = ls.scene.texture(m.diffuse_texture);
      REQUIRE(t);
      CHECK(t->has_alpha());  // leaf.png's alpha channel is the mask
    }
    if (m.reflection > 0.9f) mirror = true;
    if (m.refraction > 0 && std::fabs(m.ior - 1.5f) < 1e-3f) glass = true;
  }
  CHECK(masked);
  CHECK(mirror);
  CHECK(glass);
}

TEST_CASE("kitchen loads: 1,050,727 triangles, 11 textures, 4 point lights, blended blinds", "[gltf][scenes]") {
  // Loaded once: it is the big one.
  check_scene({"kitchen", 1050727, 11, 88, 293, 4, 11.6f, false});
}

TEST_CASE("kitchen lights and materials match its README", "[gltf][scenes]") {
  LoadedScene ls = load_gltf(scene_path("kitchen", "scene.gltf"));
  int points = 0;
  bool window_light = false;
  for (auto& [id, e] : ls.scene.lights()) {
    const Light& l = e.value;
    points += l.type == Light::Type::point;
    if (length(l.position - Vec3{0.06031f, 1.974f, -3.067f}) < 1e-3f) {
      window_light = true;
      CHECK(l.intensity == Approx(14.32f).margin(0.01f));
    }
  }
  CHECK(points == 4);
  CHECK(window_light);
  bool blinds = false, emissive = false;
  for (auto& [id, e] : ls.scene.materials()) {
    if (!e.value.alpha_mask && std::fabs(e.value.opacity - 0.612f) < 1e-3f) blinds = true;
    if (max_component(e.value.emissive_color) > 1) emissive = true;
  }
  CHECK(blinds);
  CHECK(emissive);
}

// ---------------------------------------------------------------------------------------
// Broken files
// ---------------------------------------------------------------------------------------
namespace {

using test::TempDir;
using test::tri_bin;

// A valid glTF instancing the triangle twice (once mirrored); fields can be overridden.
std::string tri_gltf(const std::string& buffer_uri = "tri.bin", int pos_count = 3, int pos_accessor = 0,
                     const std::string& index_max = "2") {
  std::ostringstream j;
  j << R"({"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0,1]}],)"
    << R"("nodes":[{"mesh":0},{"mesh":0,"scale":[-1,1,1],"translation":[3,0,0]}],)"
    << R"("meshes":[{"primitives":[{"attributes":{"POSITION":)" << pos_accessor << R"(},"indices":1}]}],)"
    << R"("buffers":[{"uri":")" << buffer_uri << R"(","byteLength":44}],)"
    << R"("bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":36},{"buffer":0,"byteOffset":36,"byteLength":6}],)"
    << R"("accessors":[{"bufferView":0,"componentType":5126,"count":)" << pos_count
    << R"(,"type":"VEC3","min":[0,0,0],"max":[1,1,0]},)"
    << R"({"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR","min":[0],"max":[)" << index_max << R"(]}]})";
  return j.str();
}

// Loads and expects a std::runtime_error whose message names the file.
// `says`: a part the message must hold besides the path (none: the path alone).
void expect_error(const std::string& path, const char* what, const std::string& says = "") {
  INFO(what << " (" << path << ")");
  try {
    load_gltf(path);
    FAIL("loaded without an error");
  } catch (const std::runtime_error& e) {
    std::string msg = e.what();
    INFO("message: " << msg);
    CHECK(msg.find(path) != std::string::npos);
    if (!says.empty()) CHECK(msg.find(says) != std::string::npos);
  }
}

}  // namespace

TEST_CASE("a minimal glTF loads, instancing one mesh through two nodes (one mirrored)", "[gltf][broken]") {
  TempDir dir;
  dir.write("tri.bin", tri_bin());
  LoadedScene ls = load_gltf(dir.write("tri.gltf", tri_gltf()));
  REQUIRE(ls.scene.meshes().size() == 2);
  const Mesh& a = ls.scene.meshes().begin()->second.value;
  const Mesh& b = std::next(ls.scene.meshes().begin())->second.value;
  CHECK(a.positions == b.positions);  // instances share the buffers
  CHECK(a.indices == b.indices);
  CHECK(a.transform.det3() > 0);
  CHECK(b.transform.det3() < 0);
  CHECK(ls.scene.triangle_count() == 2);
  CHECK(ls.bounds.lo.x == Approx(0));
  CHECK(ls.bounds.hi.x == Approx(3));
  CHECK_FALSE(ls.has_camera);
}

// tri_gltf()'s buffer, and a 2x1 PNG of the given RGBA texels beside it.
static void write_triangle_and_image(TempDir& dir, const std::string& png, const uint8_t (&texels)[8]) {
  dir.write("tri.bin", tri_bin());
  Image img(2, 1);
  std::copy(texels, texels + 8, img.rgba.begin());
  write_png(dir.path + "/" + png, img);
}

TEST_CASE("glTF emissiveTexture becomes the material's emissive texture, times emissiveFactor", "[gltf]") {
  TempDir dir;
  const uint8_t texels[8] = {200, 30, 40, 255, 10, 220, 90, 255};
  write_triangle_and_image(dir, "glow.png", texels);
  std::string j = tri_gltf();
  j.pop_back();  // reopen the top-level object
  j += R"(,"images":[{"uri":"glow.png"}],"textures":[{"source":0}],)"
       R"("materials":[{"name":"lamp","emissiveFactor":[1,0.5,0.25],"emissiveTexture":{"index":0}},)"
       R"({"name":"broken","emissiveFactor":[1,1,1],"emissiveTexture":{"index":5}}]})";
  // The first mesh's primitive uses material 0.
  const std::string prim = R"("indices":1})";
  j.replace(j.find(prim), prim.size(), R"("indices":1,"material":0})");
  LoadedScene ls = load_gltf(dir.write("glow.gltf", j));
  REQUIRE(ls.scene.textures().size() == 1);
  const Texture& tex = ls.scene.textures().begin()->second.value;
  CHECK(tex.width == 2);
  CHECK(tex.srgb);
  CHECK(std::equal(texels, texels + 8, tex.rgba.begin()));
  const Id tex_id = ls.scene.textures().begin()->first;
  int lamps = 0, broken = 0;
  for (const auto& [id, e] : ls.scene.materials()) {
    const Material& m = e.value;
    if (m.emissive_texture == tex_id) {
      ++lamps;
      CHECK(m.emissive_color.x == Approx(1));
      CHECK(m.emissive_color.y == Approx(0.5));
      CHECK(m.emissive_color.z == Approx(0.25));
      CHECK(m.diffuse_texture == kNoId);
    } else if (m.emissive_color.x == Approx(1) && m.emissive_color.y == Approx(1)) {
      ++broken;
      CHECK(m.emissive_texture == kNoId);  // a missing texture is left out with a warning
    }
  }
  CHECK(lamps == 1);
  CHECK(broken == 1);
  bool warned = false;
  for (const std::string& w : ls.warnings) warned = warned || (w.find("broken") != std::string::npos && w.find("texture 5") != std::string::npos);
  CHECK(warned);
}

TEST_CASE("a glTF image that is not PNG or JPEG is left out with a warning, the rest loads", "[gltf][broken]") {
  // Fuzz finding gltf_psd_header_1GiB: a PSD header claiming 16384 x 16384 in a data: URI
  // (30 bytes, no pixels) made stb_image allocate and write 1 GiB.
  TempDir dir;
  dir.write("tri.bin", tri_bin());
  std::string j = tri_gltf();
  j.pop_back();
  j += R"(,"images":[{"uri":"data:image/png;base64,OEJQUwABAAAAAAAAAAMAAEAAAABAAAAIAAMAAAAAAAAAAAAAAAAAAA=="}],)"
       R"("textures":[{"source":0}],"materials":[{"pbrMetallicRoughness":{"baseColorTexture":{"index":0}}}]})";
  LoadedScene ls = load_gltf(dir.write("psd.gltf", j));
  CHECK(ls.scene.textures().empty());
  CHECK(ls.scene.meshes().size() == 2);
  bool warned = false;
  for (const std::string& w : ls.warnings)
    warned = warned || (w.find("could not be decoded (not a PNG or JPEG image)") != std::string::npos);
  CHECK(warned);
}

TEST_CASE("glTF textures of one image share its decoded bytes", "[gltf]") {
  TempDir dir;
  const uint8_t texels[8] = {200, 30, 40, 255, 10, 220, 90, 128};
  write_triangle_and_image(dir, "one.png", texels);
  std::string j = tri_gltf();
  j.pop_back();
  j += R"(,"images":[{"uri":"one.png"}],"samplers":[{"wrapS":33071},{"magFilter":9728}],)"
       R"("textures":[{"source":0,"sampler":0},{"source":0,"sampler":1},{"source":0}],)"
       R"("materials":[{"pbrMetallicRoughness":{"baseColorTexture":{"index":0}},"emissiveTexture":{"index":1}}]})";
  LoadedScene ls = load_gltf(dir.write("shared.gltf", j));
  REQUIRE(ls.scene.textures().size() == 3);
  for (const std::string& w : ls.warnings) CHECK(w.find("could not be decoded") == std::string::npos);
  const Texture& first = ls.scene.textures().begin()->second.value;
  CHECK(std::equal(texels, texels + 8, first.rgba.begin(), first.rgba.end()));
  for (const auto& [id, e] : ls.scene.textures()) {
    INFO("texture " << id);
    CHECK(e.value.rgba.same(first.rgba));
    CHECK(e.value.width == 2);
  }
  // Samplers stay per texture.
  auto it = ls.scene.textures().begin();
  CHECK(it->second.value.sampler.wrap_s == Sampler::Wrap::clamp);
  ++it;
  CHECK(it->second.value.sampler.filter == Sampler::Filter::nearest);
}

TEST_CASE("glTF COLOR_0 becomes the mesh's float3 colour buffer, used by its material", "[gltf]") {
  TempDir dir;
  dir.write("tri.bin", tri_bin());
  const uint8_t rgba[12] = {255, 0, 0, 255, 0, 255, 0, 128, 0, 0, 51, 0};
  dir.write("col.bin", std::string(reinterpret_cast<const char*>(rgba), sizeof rgba));
  // COLOR_0 as accessor 2: `count` normalised unsigned bytes of `type`.
  auto with_colors = [&](const std::string& type, int count) {
    std::string j = tri_gltf();
    auto swap = [&](const std::string& from, const std::string& to) {
      REQUIRE(j.find(from) != std::string::npos);
      j.replace(j.find(from), from.size(), to);
    };
    swap(R"({"POSITION":0})", R"({"POSITION":0,"COLOR_0":2})");
    swap(R"("byteLength":44}])", R"("byteLength":44},{"uri":"col.bin","byteLength":12}])");
    swap(R"("byteLength":6}])", R"("byteLength":6},{"buffer":1,"byteOffset":0,"byteLength":12}])");
    j.resize(j.size() - 2);  // before the accessors' "]}"
    j += R"(,{"bufferView":2,"componentType":5121,"normalized":true,"count":)" + std::to_string(count) +
         R"(,"type":")" + type + R"("}],"materials":[{}]})";
    swap(R"("indices":1})", R"("indices":1,"material":0})");
    return j;
  };
  {
    LoadedScene ls = load_gltf(dir.write("rgba.gltf", with_colors("VEC4", 3)));
    REQUIRE(ls.scene.meshes().size() == 2);
    const Mesh& m = ls.scene.meshes().begin()->second.value;
    REQUIRE(m.colors != kNoId);
    const Buffer* c = ls.scene.buffer(m.colors);
    REQUIRE(c);
    CHECK(c->components == 3);  // RGBA: alpha left out
    const std::vector<float> want = {1, 0, 0, 0, 1, 0, 0, 0, 0.2f};
    REQUIRE(c->f.size() == want.size());
    for (size_t i = 0; i < want.size(); ++i) CHECK(c->f[i] == Approx(want[i]));
    CHECK(ls.scene.validate_mesh(m).empty());
    REQUIRE(ls.scene.material(m.material));
    CHECK(ls.scene.material(m.material)->use_vertex_color);
    CHECK(ls.warnings.empty());
  }
  {  // RGB: three bytes an element, read tightly packed from the same 12 bytes
    LoadedScene ls = load_gltf(dir.write("rgb.gltf", with_colors("VEC3", 3)));
    const Mesh& m = ls.scene.meshes().begin()->second.value;
    REQUIRE(m.colors != kNoId);
    const std::vector<float> want = {1, 0, 0, 1, 0, 1, 0, 0.5019608f, 0};
    const Buffer* c = ls.scene.buffer(m.colors);
    REQUIRE(c->f.size() == want.size());
    for (size_t i = 0; i < want.size(); ++i) CHECK(c->f[i] == Approx(want[i]));
  }
  {  // Another element count than POSITION's: left out with a warning, the mesh still loads.
    LoadedScene ls = load_gltf(dir.write("short.gltf", with_colors("VEC4", 2)));
    REQUIRE(ls.scene.meshes().size() == 2);
    CHECK(ls.scene.meshes().begin()->second.value.colors == kNoId);
    bool warned = false;
    for (const std::string& w : ls.warnings) warned = warned || w.find("COLOR_0 has 2 elements") != std::string::npos;
    CHECK(warned);
  }
  expect_error(dir.write("vec2.gltf", with_colors("VEC2", 3)), "COLOR_0 of two components");
}

// ---------------------------------------------------------------------------------------
// Conformance: what real exporters write besides float triangles (gltfpack's quantized
// attributes, sparse accessors, strips and fans, texture coordinate sets and transforms,
// unlit materials, required extensions).
// ---------------------------------------------------------------------------------------
namespace {

// A binary buffer built view by view (each padded to 4 bytes), and the JSON of its views.
struct Bin {
  std::string bytes;
  std::vector<std::string> views;
  template <class T>
  int view(const std::vector<T>& values, int stride = 0) {
    const size_t at = bytes.size();
    bytes.append(reinterpret_cast<const char*>(values.data()), values.size() * sizeof(T));
    const size_t length = bytes.size() - at;
    while (bytes.size() % 4) bytes.push_back('\0');
    views.push_back(R"({"buffer":0,"byteOffset":)" + std::to_string(at) + R"(,"byteLength":)" + std::to_string(length) +
                    (stride ? R"(,"byteStride":)" + std::to_string(stride) : std::string()) + "}");
    return int(views.size()) - 1;
  }
};

// A glTF of one mesh (`primitives`), one node, `accessors` and `extra` top-level members, over `bin`.
std::string gltf_of(TempDir& dir, const Bin& bin, const std::string& primitives, const std::string& accessors,
                    const std::string& extra = "") {
  dir.write("q.bin", bin.bytes);
  std::string views;
  for (const auto& v : bin.views) views += (views.empty() ? "" : ",") + v;
  return R"({"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],)"
         R"("meshes":[{"primitives":[)" + primitives + R"(]}],"buffers":[{"uri":"q.bin","byteLength":)" +
         std::to_string(bin.bytes.size()) + R"(}],"bufferViews":[)" + views + R"(],"accessors":[)" + accessors + "]" +
         extra + "}";
}

std::string accessor(int view, int type, int count, const char* shape, bool normalized = false,
                     const std::string& more = "") {
  return R"({"bufferView":)" + std::to_string(view) + R"(,"componentType":)" + std::to_string(type) +
         R"(,"count":)" + std::to_string(count) + R"(,"type":")" + shape + R"(")" +
         (normalized ? R"(,"normalized":true)" : "") + more + "}";
}

const Mesh& only_mesh(const LoadedScene& ls) {
  REQUIRE(ls.scene.meshes().size() == 1);
  return ls.scene.meshes().begin()->second.value;
}

std::vector<float> floats_of(const LoadedScene& ls, Id id) {
  const Buffer* b = ls.scene.buffer(id);
  REQUIRE(b);
  return b->f;
}

bool warned(const LoadedScene& ls, const std::string& part) {
  for (const std::string& w : ls.warnings)
    if (w.find(part) != std::string::npos) return true;
  return false;
}

}  // namespace

TEST_CASE("quantized glTF attributes load as the floats they encode (KHR_mesh_quantization)", "[gltf]") {
  TempDir dir;
  Bin bin;
  // Positions: normalized shorts (-32768 clamps to -1), 8 bytes a vertex; the same triangle
  // as plain shorts, and as floats; normals: normalized bytes, 4 bytes a vertex; texture
  // coordinates: normalized unsigned shorts; indices: unsigned bytes.
  const int pn = bin.view(std::vector<int16_t>{0, 0, 0, 0, 32767, 0, 0, 0, 0, -32768, 0, 0}, 8);
  const int pi = bin.view(std::vector<int16_t>{0, 0, 0, 0, 2, 0, 0, 0, 0, -3, 0, 0}, 8);
  const int pf = bin.view(std::vector<float>{0, 0, 0, 2, 0, 0, 0, -3, 0});
  const int nb = bin.view(std::vector<int8_t>{0, 0, 127, 0, 0, 0, 127, 0, 0, 0, -128, 0}, 4);
  const int tu = bin.view(std::vector<uint16_t>{0, 0, 65535, 0, 0, 65535});
  const int tb = bin.view(std::vector<int8_t>{-127, 127, 0, 64, 127, -128});
  const int ix = bin.view(std::vector<uint8_t>{0, 1, 2});
  const std::string accessors =
      accessor(pn, 5122, 3, "VEC3", true) + "," + accessor(pi, 5122, 3, "VEC3") + "," + accessor(pf, 5126, 3, "VEC3") +
      "," + accessor(nb, 5120, 3, "VEC3", true) + "," + accessor(tu, 5123, 3, "VEC2", true) + "," +
      accessor(tb, 5120, 3, "VEC2", true) + "," + accessor(ix, 5121, 3, "SCALAR");
  auto prim = [](int pos, int uv) {
    return R"({"attributes":{"POSITION":)" + std::to_string(pos) + R"(,"NORMAL":3,"TEXCOORD_0":)" + std::to_string(uv) +
           R"(},"indices":6})";
  };
  const std::string required = R"(,"extensionsUsed":["KHR_mesh_quantization"],"extensionsRequired":["KHR_mesh_quantization"])";
  {
    LoadedScene ls = load_gltf(dir.write("n.gltf", gltf_of(dir, bin, prim(0, 4), accessors, required)));
    CHECK(ls.warnings.empty());
    const Mesh& m = only_mesh(ls);
    CHECK(floats_of(ls, m.positions) == std::vector<float>{0, 0, 0, 1, 0, 0, 0, -1, 0});
    CHECK(floats_of(ls, m.normals) == std::vector<float>{0, 0, 1, 0, 0, 1, 0, 0, -1});
    CHECK(floats_of(ls, m.texcoords) == std::vector<float>{0, 0, 1, 0, 0, 1});
    CHECK(ls.scene.validate_mesh(m).empty());
    CHECK(ls.scene.triangle_count() == 1);
  }
  {  // Signed normalized bytes: over 127, -128 clamped to -1.
    LoadedScene ls = load_gltf(dir.write("b.gltf", gltf_of(dir, bin, prim(0, 5), accessors, required)));
    const std::vector<float> t = floats_of(ls, only_mesh(ls).texcoords);
    const std::vector<float> want = {-1, 1, 0, 64 / 127.0f, 1, -1};
    REQUIRE(t.size() == want.size());
    for (size_t i = 0; i < want.size(); ++i) CHECK(t[i] == want[i]);
  }
  {  // Plain shorts are their values: the same buffers as the float twin.
    LoadedScene a = load_gltf(dir.write("i.gltf", gltf_of(dir, bin, prim(1, 4), accessors, required)));
    LoadedScene b = load_gltf(dir.write("f.gltf", gltf_of(dir, bin, prim(2, 4), accessors)));
    CHECK(floats_of(a, only_mesh(a).positions) == floats_of(b, only_mesh(b).positions));
    CHECK(a.bounds.lo.y == -3);
    CHECK(a.bounds.hi.x == 2);
  }
  // An unsigned int is no vertex attribute type.
  const std::string uint_pos = accessor(ix, 5125, 0, "VEC3");
  expect_error(dir.write("u.gltf", gltf_of(dir, bin, R"({"attributes":{"POSITION":0}})", uint_pos)),
               "unsigned int positions", "unsupported component type 5125");
}

TEST_CASE("glTF sparse accessors replace the elements they name, over a bufferView or zeros", "[gltf]") {
  TempDir dir;
  Bin bin;
  const int pos = bin.view(std::vector<float>{0, 0, 0, 1, 0, 0, 0, 1, 0});
  const int idx = bin.view(std::vector<uint8_t>{2});
  const int val = bin.view(std::vector<float>{5, 6, 7});
  const int idx2 = bin.view(std::vector<uint16_t>{0, 2});
  const int val2 = bin.view(std::vector<float>{1, 1, 1, 2, 2, 2});
  const int bad_order = bin.view(std::vector<uint16_t>{2, 0});
  const int bad_range = bin.view(std::vector<uint16_t>{0, 3});
  auto sparse = [](int count, int indices, int itype, int values) {
    return R"(,"sparse":{"count":)" + std::to_string(count) + R"(,"indices":{"bufferView":)" + std::to_string(indices) +
           R"(,"componentType":)" + std::to_string(itype) + R"(},"values":{"bufferView":)" + std::to_string(values) + "}}";
  };
  const std::string prim = R"({"attributes":{"POSITION":0}})";
  {
    LoadedScene ls = load_gltf(dir.write("s.gltf", gltf_of(dir, bin, prim, accessor(pos, 5126, 3, "VEC3", false, sparse(1, idx, 5121, val)))));
    CHECK(floats_of(ls, only_mesh(ls).positions) == std::vector<float>{0, 0, 0, 1, 0, 0, 5, 6, 7});
    CHECK(ls.warnings.empty());
  }
  {  // No bufferView: zeros, then the substitutions.
    const std::string a = R"({"componentType":5126,"count":3,"type":"VEC3")" + sparse(2, idx2, 5123, val2) + "}";
    LoadedScene ls = load_gltf(dir.write("z.gltf", gltf_of(dir, bin, prim, a)));
    CHECK(floats_of(ls, only_mesh(ls).positions) == std::vector<float>{1, 1, 1, 0, 0, 0, 2, 2, 2});
  }
  auto broken = [&](const char* name, const std::string& sp, const std::string& says) {
    expect_error(dir.write(name, gltf_of(dir, bin, prim, accessor(pos, 5126, 3, "VEC3", false, sp))), name, says);
  };
  broken("order.gltf", sparse(2, bad_order, 5123, val2), "not increasing");
  broken("range.gltf", sparse(2, bad_range, 5123, val2), "out of range");
  broken("values.gltf", sparse(2, idx2, 5123, val), "sparse values read past the end");
  broken("indices.gltf", sparse(2, idx, 5121, val2), "sparse indices read past the end");
  broken("itype.gltf", sparse(1, idx, 5126, val), "sparse indices must be unsigned");
  broken("count.gltf", sparse(4, idx2, 5123, val2), "substitutions for 3 elements");
}

TEST_CASE("glTF triangle strips and fans become triangle lists; points and lines are left out", "[gltf]") {
  TempDir dir;
  Bin bin;
  const int pos = bin.view(std::vector<float>{0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0});
  const int idx = bin.view(std::vector<uint16_t>{3, 2, 1, 0});
  const std::string accessors = accessor(pos, 5126, 4, "VEC3") + "," + accessor(idx, 5123, 4, "SCALAR");
  auto indices_of = [&](const std::string& name, const std::string& prim) {
    LoadedScene ls = load_gltf(dir.write(name, gltf_of(dir, bin, prim, accessors)));
    const Mesh& m = only_mesh(ls);
    const Buffer* b = ls.scene.buffer(m.indices);
    REQUIRE(b);
    CHECK(ls.scene.validate_mesh(m).empty());
    CHECK(ls.scene.triangle_count() == 2);
    return b->u;
  };
  // The specification's order: strip triangle i is (v_i, v_i+1+i%2, v_i+2-i%2), fan triangle i
  // (v_i+1, v_i+2, v_0): every triangle keeps the first one's winding.
  CHECK(indices_of("strip.gltf", R"({"attributes":{"POSITION":0},"mode":5})") == std::vector<uint32_t>{0, 1, 2, 1, 3, 2});
  CHECK(indices_of("fan.gltf", R"({"attributes":{"POSITION":0},"mode":6})") == std::vector<uint32_t>{1, 2, 0, 2, 3, 0});
  CHECK(indices_of("istrip.gltf", R"({"attributes":{"POSITION":0},"indices":1,"mode":5})") ==
        std::vector<uint32_t>{3, 2, 1, 2, 0, 1});
  CHECK(indices_of("ifan.gltf", R"({"attributes":{"POSITION":0},"indices":1,"mode":6})") ==
        std::vector<uint32_t>{2, 1, 3, 1, 0, 3});
  LoadedScene lines = load_gltf(dir.write("lines.gltf", gltf_of(dir, bin, R"({"attributes":{"POSITION":0},"mode":1})", accessors)));
  CHECK(lines.scene.meshes().empty());
  CHECK(warned(lines, "mode 1 (points or lines) is not triangles"));
}

TEST_CASE("a glTF material's texture coordinate set and KHR_texture_transform are baked into the mesh", "[gltf]") {
  TempDir dir;
  Bin bin;
  const int pos = bin.view(std::vector<float>{0, 0, 0, 1, 0, 0, 0, 1, 0});
  const int uv0 = bin.view(std::vector<float>{0, 0, 1, 0, 0, 1});
  const int uv1 = bin.view(std::vector<float>{0.5f, 0.5f, 1, 0.5f, 0.5f, 1});
  Image img(2, 1);
  write_png(dir.path + "/t.png", img);
  const std::string accessors = accessor(pos, 5126, 3, "VEC3") + "," + accessor(uv0, 5126, 3, "VEC2") + "," + accessor(uv1, 5126, 3, "VEC2");
  const std::string prim = R"({"attributes":{"POSITION":0,"TEXCOORD_0":1,"TEXCOORD_1":2},"material":0})";
  auto file = [&](const std::string& name, const std::string& base_info, const std::string& more_material = "") {
    const std::string extra = R"(,"images":[{"uri":"t.png"}],"textures":[{"source":0}],"materials":[{"pbrMetallicRoughness":{"baseColorTexture":)" +
                              base_info + "}" + more_material + R"(}],"extensionsUsed":["KHR_texture_transform"])";
    return load_gltf(dir.write(name, gltf_of(dir, bin, prim, accessors, extra)));
  };
  auto near = [](const std::vector<float>& got, const std::vector<float>& want) {
    REQUIRE(got.size() == want.size());
    for (size_t i = 0; i < want.size(); ++i) CHECK(got[i] == Approx(want[i]).margin(1e-6));
  };
  {
    LoadedScene ls = file("set0.gltf", R"({"index":0})");
    near(floats_of(ls, only_mesh(ls).texcoords), {0, 0, 1, 0, 0, 1});
    CHECK(ls.warnings.empty());
  }
  {
    LoadedScene ls = file("set1.gltf", R"({"index":0,"texCoord":1})");
    near(floats_of(ls, only_mesh(ls).texcoords), {0.5f, 0.5f, 1, 0.5f, 0.5f, 1});
  }
  {  // The extension's order: scale, then rotate (columns (cos, -sin), (sin, cos): counter-clockwise
    // with v down, as the TextureTransformTest sample model and three.js, not the transposed
    // matrix of the extension's GLSL listing), then offset. A quarter turn: u' = 3 v + 0.5,
    // v' = -2 u + 0.25.
    LoadedScene ls = file("xf.gltf", R"({"index":0,"extensions":{"KHR_texture_transform":{"offset":[0.5,0.25],"rotation":1.5707963267948966,"scale":[2,3]}}})");
    near(floats_of(ls, only_mesh(ls).texcoords), {0.5f, 0.25f, 0.5f, -1.75f, 3.5f, 0.25f});
    CHECK(ls.warnings.empty());
  }
  {  // Its texCoord overrides the textureInfo's.
    LoadedScene ls = file("xf1.gltf", R"({"index":0,"texCoord":0,"extensions":{"KHR_texture_transform":{"offset":[1,0],"texCoord":1}}})");
    near(floats_of(ls, only_mesh(ls).texcoords), {1.5f, 0.5f, 2, 0.5f, 1.5f, 1});
  }
  {  // An emissive texture that reads other coordinates is drawn with the base colour's, and said so.
    LoadedScene ls = file("em.gltf", R"({"index":0})", R"(,"emissiveTexture":{"index":0,"texCoord":1})");
    near(floats_of(ls, only_mesh(ls).texcoords), {0, 0, 1, 0, 0, 1});
    CHECK(warned(ls, "emissive texture reads other texture coordinates"));
  }
  {  // A mirrored sampler is drawn repeating, and said so once.
    const std::string extra =
        R"(,"images":[{"uri":"t.png"}],"samplers":[{"wrapS":33648,"wrapT":33648}],"textures":[{"source":0,"sampler":0},{"source":0,"sampler":0}],)"
        R"("materials":[{"pbrMetallicRoughness":{"baseColorTexture":{"index":0}},"emissiveTexture":{"index":1}}])";
    LoadedScene ls = load_gltf(dir.write("mirror.gltf", gltf_of(dir, bin, prim, accessors, extra)));
    CHECK(ls.warnings.size() == 1);
    CHECK(warned(ls, "MIRRORED_REPEAT, which is drawn as REPEAT"));
    for (const auto& [id, t] : ls.scene.textures()) CHECK(t.value.sampler.wrap_s == Sampler::Wrap::repeat);
  }
  {  // A set the primitive lacks: no texture coordinates (the texture shows its first texel).
    LoadedScene ls = file("set2.gltf", R"({"index":0,"texCoord":2})");
    CHECK(only_mesh(ls).texcoords == kNoId);
  }
  {  // KHR_materials_pbrSpecularGlossiness: the diffuse colour and texture (and its coordinates)
     // are the base colour's; a dielectric, whatever metallicFactor's default says.
    const std::string extra =
        R"(,"images":[{"uri":"t.png"}],"textures":[{"source":0}],"materials":[{"extensions":{"KHR_materials_pbrSpecularGlossiness":)"
        R"({"diffuseFactor":[0.5,0.25,1,0.5],"glossinessFactor":0.2,"diffuseTexture":{"index":0,"texCoord":1,)"
        R"("extensions":{"KHR_texture_transform":{"scale":[2,2]}}}}}}],"extensionsUsed":["KHR_materials_pbrSpecularGlossiness","KHR_texture_transform"])";
    LoadedScene ls = load_gltf(dir.write("sg.gltf", gltf_of(dir, bin, prim, accessors, extra)));
    CHECK(ls.warnings.empty());
    const Mesh& m = only_mesh(ls);
    near(floats_of(ls, m.texcoords), {1, 1, 2, 1, 1, 2});
    const Material* mat = ls.scene.material(m.material);
    REQUIRE(mat);
    CHECK(mat->diffuse_texture != kNoId);
    CHECK(mat->diffuse_color == Vec3{0.5f, 0.25f, 1});
    CHECK(mat->reflection == 0);
  }
}

TEST_CASE("glTF KHR_materials_unlit shows the base colour unlit; unknown required extensions are refused by name", "[gltf]") {
  TempDir dir;
  Bin bin;
  const int pos = bin.view(std::vector<float>{0, 0, 0, 1, 0, 0, 0, 1, 0});
  const std::string accessors = accessor(pos, 5126, 3, "VEC3");
  const std::string prim = R"({"attributes":{"POSITION":0},"material":0})";
  {
    const std::string extra =
        R"(,"materials":[{"pbrMetallicRoughness":{"baseColorFactor":[0.2,0.4,0.6,1],"metallicFactor":1},"extensions":{"KHR_materials_unlit":{}}}],"extensionsUsed":["KHR_materials_unlit"])";
    LoadedScene ls = load_gltf(dir.write("unlit.gltf", gltf_of(dir, bin, prim, accessors, extra)));
    const Material* m = ls.scene.material(only_mesh(ls).material);
    REQUIRE(m);
    CHECK(m->model == Material::Model::matte);
    CHECK(m->diffuse_color == Vec3{0.2f, 0.4f, 0.6f});
    CHECK(m->reflection == 0);
    CHECK(ls.warnings.empty());
  }
  const std::string draco = R"(,"materials":[{}],"extensionsUsed":["KHR_draco_mesh_compression","EXT_meshopt_compression"],"extensionsRequired":["KHR_draco_mesh_compression","EXT_meshopt_compression"])";
  expect_error(dir.write("draco.gltf", gltf_of(dir, bin, prim, accessors, draco)), "Draco",
               "requires glTF extensions this loader does not implement: KHR_draco_mesh_compression, EXT_meshopt_compression");
  // Used, not required: the file loads without it, and a warning names it.
  const std::string used = R"(,"materials":[{}],"extensionsUsed":["KHR_materials_clearcoat","KHR_materials_ior"])";
  LoadedScene ls = load_gltf(dir.write("used.gltf", gltf_of(dir, bin, prim, accessors, used)));
  CHECK(ls.warnings.size() == 1);
  CHECK(warned(ls, "glTF extensions ignored: KHR_materials_clearcoat"));
  CHECK_FALSE(warned(ls, "KHR_materials_ior"));
}

TEST_CASE("a Draco glTF whose accessors have no bufferView is refused by the extension name and not by tinygltf", "[gltf][broken]") {
  // As Draco exporters write it: the accessors give only counts and types, the geometry lies in
  // the compressed bufferView the primitive's extension names. tinygltf refuses such a file
  // itself ("accessor[0] invalid bufferView") before the loader sees extensionsRequired.
  TempDir dir;
  Bin bin;
  const int compressed = bin.view(std::vector<float>{1, 2, 3, 4});
  const std::string accessors = R"({"componentType":5123,"count":3,"type":"SCALAR"},{"componentType":5126,"count":3,"type":"VEC3"})";
  const std::string prim = R"({"attributes":{"POSITION":1},"indices":0,"extensions":{"KHR_draco_mesh_compression":{"bufferView":)" +
                           std::to_string(compressed) + R"(,"attributes":{"POSITION":0}}}})";
  const std::string extra = R"(,"extensionsUsed":["KHR_draco_mesh_compression"],"extensionsRequired":["KHR_draco_mesh_compression"])";
  const std::string file = gltf_of(dir, bin, prim, accessors, extra);
  expect_error(dir.write("draco.gltf", file), "Draco, .gltf",
               "requires glTF extensions this loader does not implement: KHR_draco_mesh_compression");
  // The same in a .glb: its JSON chunk is read for the names.
  std::string json = file;
  while (json.size() % 4) json += ' ';
  auto u32 = [](uint32_t v) { return std::string(reinterpret_cast<const char*>(&v), 4); };
  const std::string glb = "glTF" + u32(2) + u32(uint32_t(12 + 8 + json.size())) + u32(uint32_t(json.size())) + "JSON" + json;
  expect_error(dir.write("draco.glb", glb), "Draco, .glb", "requires glTF extensions this loader does not implement: KHR_draco_mesh_compression");
  // A file tinygltf refuses for another reason keeps tinygltf's message.
  const std::string plain = gltf_of(dir, bin, R"({"attributes":{"POSITION":1},"indices":0})", accessors);
  expect_error(dir.write("plain.gltf", plain), "no bufferView, no extension", "invalid bufferView");
}

TEST_CASE("a glTF without scenes draws every node tree from its roots (as the web reader)", "[gltf]") {
  TempDir dir;
  Bin bin;
  const int pos = bin.view(std::vector<float>{0, 0, 0, 1, 0, 0, 0, 1, 0});
  std::string file = gltf_of(dir, bin, R"({"attributes":{"POSITION":0}})", accessor(pos, 5126, 3, "VEC3"));
  // No scene, no scenes; two trees: node 0 (moved by 5 in x) with its child 1, and node 2 alone.
  const std::string head = R"("scene":0,"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],)";
  REQUIRE(file.find(head) != std::string::npos);
  file.replace(file.find(head), head.size(),
               R"("nodes":[{"children":[1],"translation":[5,0,0]},{"mesh":0},{"mesh":0,"translation":[0,7,0]}],)");
  LoadedScene ls = load_gltf(dir.write("noscenes.gltf", file));
  REQUIRE(ls.scene.meshes().size() == 2);
  std::vector<std::pair<float, float>> moved;
  for (const auto& [id, e] : ls.scene.meshes()) {
    const Vec3 p = e.value.transform.transform_point({0, 0, 0});
    moved.push_back({p.x, p.y});
  }
  std::sort(moved.begin(), moved.end());
  CHECK(moved == std::vector<std::pair<float, float>>{{0.0f, 7.0f}, {5.0f, 0.0f}});
}

TEST_CASE("glTF materials become the XML3D materials of tests/data/gltf-materials.json (the web reader's table too)", "[gltf]") {
  std::ifstream in(TESSERA_TEST_DATA_DIR "/gltf-materials.json");
  REQUIRE(in);
  const nlohmann::json table = nlohmann::json::parse(in);
  const auto& cases = table.at("cases");
  nlohmann::json materials = nlohmann::json::array();
  for (const auto& c : cases) materials.push_back(c.at("material"));
  TempDir dir;
  Bin bin;
  const int pos = bin.view(std::vector<float>{0, 0, 0, 1, 0, 0, 0, 1, 0});
  const std::string extra = R"(,"materials":)" + materials.dump() +
                            R"(,"extensionsUsed":["KHR_materials_transmission","KHR_materials_ior","KHR_materials_emissive_strength","KHR_materials_unlit","KHR_materials_pbrSpecularGlossiness"])";
  LoadedScene ls = load_gltf(dir.write("materials.gltf", gltf_of(dir, bin, R"({"attributes":{"POSITION":0},"material":0})",
                                                                accessor(pos, 5126, 3, "VEC3"), extra)));
  CHECK(ls.warnings.empty());
  REQUIRE(ls.scene.materials().size() == cases.size());
  size_t i = 0;
  for (const auto& [id, entry] : ls.scene.materials()) {  // ids in the file's order
    const Material& m = entry.value;
    const auto& c = cases.at(i++);
    const auto& x = c.at("expect");
    INFO(c.at("name").get<std::string>());
    auto vec = [](const nlohmann::json& v) { return Vec3{v.at(0).get<float>(), v.at(1).get<float>(), v.at(2).get<float>()}; };
    auto same = [](const Vec3& a, const Vec3& b) {
      return std::fabs(a.x - b.x) < 1e-5f && std::fabs(a.y - b.y) < 1e-5f && std::fabs(a.z - b.z) < 1e-5f;
    };
    const char* model = m.model == Material::Model::matte ? "matte" : m.model == Material::Model::diffuse ? "diffuse" : "phong";
    CHECK(model == x.at("model").get<std::string>());
    CHECK(same(m.diffuse_color, vec(x.at("diffuse"))));
    CHECK(same(m.specular_color, vec(x.at("specular"))));
    CHECK(same(m.emissive_color, vec(x.at("emissive"))));
    if (x.contains("shininess")) CHECK(m.shininess == Approx(x.at("shininess").get<float>()).margin(1e-5));
    CHECK(m.opacity == Approx(x.at("opacity").get<float>()).margin(1e-6));
    CHECK(m.reflection == Approx(x.at("reflection").get<float>()).margin(1e-5));
    CHECK(m.refraction == Approx(x.at("refraction").get<float>()).margin(1e-6));
    if (x.contains("ior")) CHECK(m.ior == Approx(x.at("ior").get<float>()).margin(1e-6));
    CHECK(m.alpha_mask == x.at("alphaMask").get<bool>());
    if (x.contains("alphaCutoff")) CHECK(m.alpha_cutoff == Approx(x.at("alphaCutoff").get<float>()).margin(1e-6));
    CHECK(m.double_sided == x.at("doubleSided").get<bool>());
  }
}

TEST_CASE("a glTF orthographic camera is drawn as a perspective one, and a warning says so", "[gltf]") {
  TempDir dir;
  const std::string j =
      R"({"asset":{"version":"2.0"},"cameras":[{"type":"orthographic","orthographic":{"xmag":2,"ymag":2,"znear":0.1,"zfar":100}}],)"
      R"("nodes":[{"camera":0,"translation":[0,0,5]}],"scenes":[{"nodes":[0]}],"scene":0})";
  LoadedScene ls = load_gltf(dir.write("ortho.gltf", j));
  CHECK(ls.has_camera);
  CHECK(ls.scene.camera().to_world.m[14] == 5);
  CHECK(ls.warnings.size() == 1);
  CHECK(warned(ls, "camera of type 'orthographic' drawn as a perspective one with a 45 degree field of view"));
}

TEST_CASE("glTF animations skins and morph targets are not played and one warning says so; the rest pose loads", "[gltf]") {
  TempDir dir;
  Bin bin;
  const int pos = bin.view(std::vector<float>{0, 0, 0, 1, 0, 0, 0, 1, 0});
  const int delta = bin.view(std::vector<float>{0, 0, 1, 0, 0, 1, 0, 0, 1});
  const int times = bin.view(std::vector<float>{0, 1});
  const int weights = bin.view(std::vector<float>{0, 1});
  const std::string accessors = accessor(pos, 5126, 3, "VEC3") + "," + accessor(delta, 5126, 3, "VEC3") + "," +
                                accessor(times, 5126, 2, "SCALAR", false, R"(,"min":[0],"max":[1])") + "," +
                                accessor(weights, 5126, 2, "SCALAR");
  {  // Nothing to play: no warning.
    LoadedScene ls = load_gltf(dir.write("still.gltf", gltf_of(dir, bin, R"({"attributes":{"POSITION":0}})", accessors)));
    CHECK(ls.warnings.empty());
  }
  // A morph target on the primitive, and an animation of its weight.
  const std::string anim =
      R"(,"animations":[{"samplers":[{"input":2,"output":3}],"channels":[{"sampler":0,"target":{"node":0,"path":"weights"}}]}])";
  LoadedScene ls = load_gltf(
      dir.write("morph.gltf", gltf_of(dir, bin, R"({"attributes":{"POSITION":0},"targets":[{"POSITION":1}]})", accessors, anim)));
  REQUIRE(ls.scene.meshes().size() == 1);
  CHECK(floats_of(ls, only_mesh(ls).positions) == std::vector<float>{0, 0, 0, 1, 0, 0, 0, 1, 0});  // the rest pose
  CHECK(ls.warnings.size() == 1);
  CHECK(warned(ls, "1 animation, 1 primitive with morph targets not played: the meshes are drawn in the file's rest pose"));
}

TEST_CASE("a glTF with no lights and no sky is dark and said so; with default lighting it gets a sun and a sky", "[gltf]") {
  TempDir dir;
  Bin bin;
  const int pos = bin.view(std::vector<float>{0, 0, 0, 1, 0, 0, 0, 1, 0});
  const std::string acc = accessor(pos, 5126, 3, "VEC3");
  const std::string white = R"(,"materials":[{"pbrMetallicRoughness":{"baseColorFactor":[1,1,1,1],"metallicFactor":0}}])";
  const std::string dark =
      dir.write("dark.gltf", gltf_of(dir, bin, R"({"attributes":{"POSITION":0},"material":0})", acc, white));
  auto render_red = [](LoadedScene& ls) {  // pixels with red above 40, and the corner's red
    RayTracer rt;
    std::vector<std::string> w;
    ls.scene.set_resolution(64, 64);
    rt.sync(ls.scene, w);
    TaskResult tr;
    rt.render({0, 0, 64, 64}, RenderSettings{}, tr);
    int lit = 0;
    for (int y = 0; y < 64; ++y)
      for (int x = 0; x < 64; ++x) lit += tr.image.pixel(x, y)[0] > 40 ? 1 : 0;
    return std::pair<int, int>{lit, tr.image.pixel(0, 0)[0]};
  };
  {  // As the file is: dark, as an XML3D page without lights shows it, and a note says so.
    LoadedScene ls = load_gltf(dark);
    CHECK(ls.dark);
    CHECK_FALSE(ls.default_lighting);
    CHECK(ls.warnings.empty());  // nothing was left out: the callers print a note
    CHECK(ls.scene.lights().empty());
    CHECK(lighting_note("dark.gltf", ls).find("render black") != std::string::npos);
    CHECK(render_red(ls).first == 0);
  }
  {  // Lit by default (the commands' --default-light).
    GltfOptions o;
    o.default_lighting = true;
    LoadedScene ls = load_gltf(dark, o);
    CHECK_FALSE(ls.dark);
    CHECK(ls.default_lighting);
    REQUIRE(ls.scene.lights().size() == 1);
    const Light& sun = ls.scene.lights().begin()->second.value;
    CHECK(sun.type == Light::Type::directional);
    CHECK(sun.direction.z < 0);  // the fitted camera looks down -z: the sun shines the same way, from above
    CHECK(sun.direction.y < 0);
    CHECK(ls.scene.environment().ambient.x > 0);
    CHECK(lighting_note("dark.gltf", ls).find("default sun") != std::string::npos);
    const auto [lit, corner] = render_red(ls);
    CHECK(lit > 500);  // the triangle covers about a third of the image
    CHECK(corner == 0);  // the background stays the file's
  }
  GltfOptions lights_on;
  lights_on.default_lighting = true;
  {  // A light of its own.
    const std::string light = R"(,"extensionsUsed":["KHR_lights_punctual"],"extensions":{"KHR_lights_punctual":{"lights":[{"type":"point"}]}})";
    std::string f = gltf_of(dir, bin, R"({"attributes":{"POSITION":0},"material":0})", acc, light + white);
    f.replace(f.find(R"("nodes":[{"mesh":0}])"), 20, R"("nodes":[{"mesh":0},{"extensions":{"KHR_lights_punctual":{"light":0}}}])");
    f.replace(f.find(R"("scenes":[{"nodes":[0]}])"), 24, R"("scenes":[{"nodes":[0,1]}])");
    LoadedScene ls = load_gltf(dir.write("lit.gltf", f), lights_on);
    CHECK_FALSE(ls.dark);
    CHECK_FALSE(ls.default_lighting);
    CHECK(ls.scene.lights().size() == 1);
    CHECK(ls.scene.lights().begin()->second.value.type == Light::Type::point);
    CHECK(ls.scene.environment().ambient.x == 0);
    CHECK(lighting_note("lit.gltf", ls).empty());
  }
  {  // Only unlit materials: nothing a light would change.
    std::string f = gltf_of(dir, bin, R"({"attributes":{"POSITION":0},"material":0})", acc,
                            R"(,"extensionsUsed":["KHR_materials_unlit"],"materials":[{"extensions":{"KHR_materials_unlit":{}}}])");
    LoadedScene ls = load_gltf(dir.write("unlit.gltf", f), lights_on);
    CHECK_FALSE(ls.dark);
    CHECK_FALSE(ls.default_lighting);
    CHECK(ls.scene.lights().empty());
  }
  {  // A sky of its own (the shared scenes' extras).
    std::string f = gltf_of(dir, bin, R"({"attributes":{"POSITION":0},"material":0})", acc, white);
    f.replace(f.find(R"("scenes":[{"nodes":[0]}])"), 24,
              R"("scenes":[{"nodes":[0],"extras":{"environment":{"analysis":{"integral_L_dOmega":3.14159}}}}])");
    LoadedScene ls = load_gltf(dir.write("sky.gltf", f), lights_on);
    CHECK_FALSE(ls.dark);
    CHECK_FALSE(ls.default_lighting);
    CHECK(ls.scene.lights().empty());
  }
}

TEST_CASE("a glTF with an orthographic camera before a perspective one is seen through the perspective one (as the web reader)", "[gltf]") {
  TempDir dir;
  const std::string j =
      R"({"asset":{"version":"2.0"},"cameras":[{"type":"orthographic","orthographic":{"xmag":2,"ymag":2,"znear":0.1,"zfar":100}},)"
      R"({"type":"perspective","perspective":{"yfov":0.5,"znear":0.1}}],)"
      R"("nodes":[{"camera":0,"translation":[0,0,5]},{"camera":1,"translation":[0,0,9]}],"scenes":[{"nodes":[0,1]}],"scene":0})";
  LoadedScene ls = load_gltf(dir.write("two.gltf", j));
  CHECK(ls.has_camera);
  CHECK(ls.scene.camera().to_world.m[14] == 9);
  CHECK(ls.scene.camera().fov_y == 0.5f);
  CHECK(ls.warnings.empty());  // the orthographic camera is not the one drawn
}

TEST_CASE("a glTF light index beyond int's range names no light", "[gltf][broken]") {
  // Converting 1e300 to int was undefined behaviour (UBSan: "outside the range of representable
  // values of type 'int'"); such a node now names no light, like any other bad index.
  TempDir dir;
  for (const char* index : {"1e300", "-1e300", "1e10", "1", "0"}) {
    INFO(index);
    const std::string j =
        R"({"asset":{"version":"2.0"},"extensionsUsed":["KHR_lights_punctual"],"extensions":{"KHR_lights_punctual":{"lights":[{"type":"point","intensity":2}]}},)"
        R"("nodes":[{"extensions":{"KHR_lights_punctual":{"light":)" + std::string(index) + R"(}}}],"scenes":[{"nodes":[0]}],"scene":0})";
    LoadedScene ls = load_gltf(dir.write("light.gltf", j));
    const bool named = std::string(index) == "0";  // the file has one light
    CHECK(ls.scene.lights().size() == (named ? 1u : 0u));
  }
}

TEST_CASE("broken glTF files throw std::runtime_error naming the file", "[gltf][broken]") {
  TempDir dir;
  dir.write("tri.bin", tri_bin());
  const std::string good = tri_gltf();

  expect_error(dir.path + "/does-not-exist.gltf", "nonexistent path");
  expect_error(dir.write("truncated.gltf", good.substr(0, good.size() / 2)), "truncated JSON");
  expect_error(dir.write("empty.gltf", ""), "empty file");
  expect_error(dir.write("garbage.gltf", "\x01\x02not json at all"), "not JSON");
  expect_error(dir.write("nobuffer.gltf", tri_gltf("missing.bin")), "buffer file missing");
  expect_error(dir.write("range.gltf", tri_gltf("tri.bin", 30)), "accessor reads past its buffer");
  expect_error(dir.write("badaccessor.gltf", tri_gltf("tri.bin", 3, 7)), "accessor index out of range");
  // Index 2 -> 5 in the data: the index accessor points at vertex 5 of 3.
  std::string bin = tri_bin();
  uint16_t five = 5;
  bin.replace(36 + 4, 2, reinterpret_cast<const char*>(&five), 2);
  dir.write("badindex.bin", bin);
  expect_error(dir.write("badindex.gltf", tri_gltf("badindex.bin", 3, 0, "5")), "index out of range");
  // A node that is its own child.
  std::string cyc = good;
  cyc.replace(cyc.find(R"({"mesh":0},)"), 11, R"({"mesh":0,"children":[0]},)");
  expect_error(dir.write("cycle.gltf", cyc), "node cycle");
  // A node reached twice (fuzz finding gltf_node_dag_hang): 64 nodes each listing the next one
  // twice as its child made 2^64 visits, so the load never ended. Refused at the second visit,
  // as are a node with two parents and a root listed twice; the message says which node.
  auto expect_reached_twice = [&](const std::string& name, const std::string& text, int node) {
    expect_error(dir.write(name, text), name.c_str(), "node " + std::to_string(node) + " is reached twice");
  };
  std::string dag = R"({"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0]}],"nodes":[)";
  for (int i = 0; i < 64; ++i) dag += R"({"children":[)" + std::to_string(i + 1) + "," + std::to_string(i + 1) + "]},";
  dag += "{}]}";
  expect_reached_twice("dag.gltf", dag, 64);  // depth first: 0..64, then 63's second child
  std::string two_parents = good;
  two_parents.replace(two_parents.find(R"({"mesh":0},)"), 11, R"({"mesh":0,"children":[1]},)");
  expect_reached_twice("two_parents.gltf", two_parents, 1);
  std::string root_twice = good;
  root_twice.replace(root_twice.find(R"("nodes":[0,1])"), 13, R"("nodes":[0,1,0])");
  expect_reached_twice("root_twice.gltf", root_twice, 0);
  // A .glb that is not one.
  expect_error(dir.write("fake.glb", std::string("glTF\x02\x00\x00\x00garbage", 15)), "bad binary glTF");
  expect_error(dir.write("empty.glb", ""), "empty binary file");
  // JSON nested 100000 deep in "extras" (fuzz finding gltf_deep_extras_stack): tinygltf's
  // recursive conversion overflowed the stack. Refused before parsing, in .gltf and .glb alike;
  // 256 levels still load, and brackets inside strings do not count.
  auto nested = [&](size_t depth, const std::string& in_string) {
    std::string t = good;
    t.pop_back();
    return t + R"(,"extras":{"s":")" + in_string + R"(","x":)" + std::string(depth - 2, '[') + std::string(depth - 2, ']') + "}}";
  };
  auto expect_too_deep = [&](const std::string& path) {
    expect_error(path, "too deep", path + ": JSON nested deeper than 256 levels");
  };
  expect_too_deep(dir.write("deep.gltf", nested(100000, "")));
  expect_too_deep(dir.write("deep257.gltf", nested(257, "")));
  CHECK(load_gltf(dir.write("deep256.gltf", nested(256, std::string(300, '[') + "\\\"{"))).scene.meshes().size() == 2);
  {
    std::string json = nested(100000, "");
    json.resize((json.size() + 3) / 4 * 4, ' ');
    std::string glb = "glTF";
    auto u32 = [&](uint32_t v) { glb.append(reinterpret_cast<const char*>(&v), 4); };
    u32(2);
    u32(uint32_t(20 + json.size()));
    u32(uint32_t(json.size()));
    glb += "JSON" + json;
    expect_too_deep(dir.write("deep.glb", glb));
  }
}

TEST_CASE("mutated glTF files never crash: they load or throw a runtime_error naming the file", "[gltf][broken]") {
  TempDir dir;
  dir.write("tri.bin", tri_bin());
  const std::string good = tri_gltf();
  int thrown = 0, loaded = 0;
  // Every prefix length (every truncation) and a byte flip at every 7th position.
  for (size_t n = 0; n < good.size(); n += 5) {
    for (int mode = 0; mode < 2; ++mode) {
      std::string text = mode == 0 ? good.substr(0, n) : good;
      if (mode == 1) text[n] = text[n] == '1' ? '9' : '1';
      std::string path = dir.write("m.gltf", text);
      try {
        LoadedScene ls = load_gltf(path);
        ++loaded;
      } catch (const std::runtime_error& e) {
        ++thrown;
        std::string msg = e.what();
        INFO("mutation " << mode << " at " << n << ": " << msg);
        REQUIRE(msg.find(path) != std::string::npos);
      }
    }
  }
  CHECK(thrown > 0);
  CHECK(loaded > 0);
}

TEST_CASE("broken camera loops throw std::runtime_error naming the file", "[gltf][broken]") {
  TempDir dir;
  auto expect = [&](const std::string& name, const std::string& text) {
    std::string path = dir.write(name, text);
    INFO(name);
    try {
      load_camera_loop(path);
      FAIL("loaded without an error");
    } catch (const std::runtime_error& e) {
      CHECK(std::string(e.what()).find(path) != std::string::npos);
    }
  };
  expect("truncated.json", R"({"fovY_deg": 45, "frames": [{"eye": [0,0,)");
  expect("empty.json", R"({"fovY_deg": 45, "frames": []})");
  expect("fov.json", R"({"fovY_deg": 0, "frames": [{"eye":[0,0,0],"target":[0,0,-1],"up":[0,1,0]}]})");
  expect("types.json", R"({"fovY_deg": "wide", "frames": 3})");
  try {
    load_camera_loop(dir.path + "/none.json");
    FAIL("loaded without an error");
  } catch (const std::runtime_error& e) {
    CHECK(std::string(e.what()).find(dir.path + "/none.json") != std::string::npos);
  }
}

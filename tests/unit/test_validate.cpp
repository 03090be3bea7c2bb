// Fault containment at every entry point (core/validate.h, docs/renderer.md "Fault
// containment: what may reach Embree"): transforms and cameras that are singular, nearly so
// or huge, lights beyond the world box, camera loops that overflow float, oversized glTF
// accessors and bufferViews, and external URIs that leave the glTF file's folder. Each is
// refused with an error naming the record, field, node or frame, and none reaches Embree.
// Before these checks the transforms below aborted the whole process inside Embree.
#include <catch2/catch.hpp>

#include "tests/unit/temp_files.h"

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>

#include "protocol/protocol.h"
#include "update/scene_update.h"
#include "core/gltf_loader.h"
#include "core/image.h"
#include "renderer/raytracer.h"
#include "core/validate.h"

using namespace tessera;

namespace {

const float kNaN = std::numeric_limits<float>::quiet_NaN();

Mat4 zero_matrix() {
  Mat4 z;
  z.m.fill(0);
  return z;
}
Mat4 one_element(int i, float v) {
  Mat4 m;
  m.m[size_t(i)] = v;
  return m;
}

bool has(const std::string& s, const std::string& what) { return s.find(what) != std::string::npos; }

// The transforms of the issue, each with the words its refusal must contain.
struct BadTransform {
  const char* name;
  Mat4 xf;
  const char* why;
};
const BadTransform kBadMeshTransforms[] = {
    {"all zero", zero_matrix(), "singular"},
    {"zero z-scale", Mat4::scale({1, 1, 0}), "singular"},
    {"uniform scale 1e-30", Mat4::scale(Vec3{1e-30f}), "nearly singular"},
    {"scale 1e19", Mat4::scale(Vec3{1e19f}), "scale too large"},
    {"3e38 in one element", one_element(9, 3e38f), "scale too large"},
    {"translation 1e30", Mat4::translate({0, 1e30f, 0}), "translation"},
    {"z-scale 1e-7 (condition 1e7)", Mat4::scale({1, 1, 1e-7f}), "ill-conditioned"},
};
const BadTransform kBadCameraTransforms[] = {
    {"all zero", zero_matrix(), "singular"},
    {"scale 1e19", Mat4::translate({0, 0, 5}) * Mat4::scale(Vec3{1e19f}), "scale too large"},
    {"3e38 in one element", one_element(0, 3e38f), "scale too large"},
    {"uniform scale 1e-30", Mat4::scale(Vec3{1e-30f}), "nearly singular"},
    {"translation 1e30", Mat4::translate({1e30f, 0, 0}), "translation"},
};

}  // namespace

// ---------------------------------------------------------------------------------------
// The checks themselves
// ---------------------------------------------------------------------------------------
TEST_CASE("check_transform: figures in double, bounds as documented", "[stability][validate]") {
  TransformFigures f = transform_figures(Mat4::scale({2, 4, 0.5f}));
  CHECK(f.det == Approx(4));
  CHECK(f.norm == Approx(4));
  CHECK(f.norm_inverse == Approx(2));
  CHECK(f.condition == Approx(8));
  f = transform_figures(Mat4::scale(Vec3{1e-30f}));  // no underflow: det 1e-90 in double
  CHECK(f.det > 0);
  CHECK(f.norm_inverse == Approx(1e30).epsilon(1e-6));
  CHECK(std::isinf(transform_figures(zero_matrix()).condition));

  // Ordinary transforms pass: rotations, mirrors, scenes scaled by 1e-4 or 1e5, moved 1e6 away.
  for (const Mat4& ok : {Mat4{}, Mat4::rotate({1, 2, 3}, 0.7f), Mat4::scale({-1, 1, 1}), Mat4::scale(Vec3{1e-4f}),
                         Mat4::scale(Vec3{1e5f}), Mat4::translate({1e6f, -1e6f, 4e9f}), Mat4::scale({1, 1, 1e-3f}),
                         Mat4::look_at({1, 2, 3}, {0, 0, 0}, {0, 1, 0})}) {
    CHECK(check_transform(ok, kMeshLimits).empty());
  }
  CHECK(check_camera(Camera{}).empty());
  for (const auto& c : kBadMeshTransforms) {
    INFO(c.name);
    CHECK(has(check_transform(c.xf, kMeshLimits), c.why));
  }
  CHECK(has(check_transform(one_element(15, kNaN), kMeshLimits), "NaN"));
  Camera wide;
  wide.fov_y = kPi;
  CHECK(has(check_camera(wide), "fov_y"));
  CHECK(has(check_point({0, 5e9f, 0}), "world limit"));
  CHECK(check_point({0, 4e9f, 0}).empty());
  CHECK(!check_direction({3e38f, 3e38f, 3e38f}).empty());  // its length overflows in float
  CHECK(!check_direction({0, 0, 0}).empty());
  CHECK(check_direction({0, 1e-10f, 0}).empty());
  // The bounds keep object-space rays under Embree's FLT_LARGE (docs/renderer.md).
  CHECK(kMeshLimits.max_inverse_norm * (double(kRayLimit) + kMeshLimits.max_translation) < double(kEmbreeLarge) / 4);
  CHECK(double(kRayLimit) >= 2.0 * kWorldLimit);
}

// ---------------------------------------------------------------------------------------
// The wire: decode_client refuses, nothing is applied, the error is not fatal
// ---------------------------------------------------------------------------------------
namespace {

protocol::Result<std::vector<protocol::ClientRecord>> decode(const std::vector<protocol::ClientRecord>& records) {
  auto bytes = protocol::encode(records);
  return protocol::decode_client(bytes.data(), bytes.size(), protocol::Limits{});
}

// A scene with a triangle mesh 1 and a camera; decoding `bad` after a good record must fail
// with out_of_range naming record 1 and `field`, and applying what decoded changes nothing.
void expect_refused(const protocol::ClientRecord& bad, const std::string& field, const std::string& why) {
  protocol::SetCamera good_cam;
  good_cam.camera.to_world = Mat4::look_at({0, 0, 5}, {0, 0, 0}, {0, 1, 0});
  auto res = decode({good_cam, bad});
  REQUIRE_FALSE(res.ok());
  INFO(res.error().message);
  CHECK(res.error().code == protocol::ErrorCode::out_of_range);
  CHECK_FALSE(protocol::is_fatal(res.error().code));
  CHECK(res.error().record == 1);
  CHECK(has(res.error().message, "record 1"));
  CHECK(has(res.error().message, field));
  CHECK(has(res.error().message, why));
}

}  // namespace

TEST_CASE("the client protocol refuses singular, nearly singular and huge mesh transforms", "[stability][validate]") {
  for (const auto& c : kBadMeshTransforms) {
    INFO(c.name);
    protocol::SetMesh m;
    m.id = 1;
    m.mesh.positions = 2;
    m.mesh.transform = c.xf;
    expect_refused(m, "(mesh): transform", c.why);
  }
  protocol::SetMesh ok;
  ok.id = 1;
  ok.mesh.positions = 2;
  ok.mesh.transform = Mat4::scale(Vec3{1e-4f});
  CHECK(decode({ok}).ok());
}

TEST_CASE("the client protocol refuses huge, singular and nearly singular cameras", "[stability][validate]") {
  for (const auto& c : kBadCameraTransforms) {
    INFO(c.name);
    protocol::SetCamera cam;
    cam.camera.to_world = c.xf;
    expect_refused(cam, "(camera): to_world", c.why);
  }
}

TEST_CASE("the client protocol refuses lights beyond the world box and directions that do not normalise",
          "[stability][validate]") {
  protocol::SetLight l;
  l.id = 1;
  l.light.type = Light::Type::point;
  l.light.position = {1e30f, 0, 0};
  expect_refused(l, "(light): position", "world limit");
  l.light.type = Light::Type::spot;
  l.light.position = {0, 0, 0};
  l.light.direction = {3e38f, 3e38f, 3e38f};
  expect_refused(l, "(light): direction", "normalised");
  l.light.type = Light::Type::directional;
  l.light.position = {1e30f, 0, 0};  // unused by a directional light: fine
  l.light.direction = {0, -1, 0};
  CHECK(decode({l}).ok());
}

TEST_CASE("apply refuses a mesh whose vertices its transform puts beyond the world box (bad_mesh), scene unchanged",
          "[stability][validate]") {
  Scene scene;
  protocol::Limits lim;
  protocol::SetBuffer b;
  b.id = 2;
  b.buffer.components = 3;
  b.buffer.f = {0, 0, 0, 1e6f, 0, 0, 0, 1e6f, 0};
  REQUIRE(apply(scene, b, lim).ok());
  protocol::SetMesh m;
  m.id = 1;
  m.mesh.positions = 2;
  m.mesh.transform = Mat4::scale(Vec3{1e4f});  // fine alone, but 1e6 x 1e4 = 1e10 > 2^32
  auto before = scene.version();
  auto st = apply(scene, m, lim);
  REQUIRE_FALSE(st.ok());
  CHECK(st.error().code == protocol::ErrorCode::bad_mesh);
  CHECK(has(st.error().message, "world limit"));
  CHECK(scene.meshes().empty());
  CHECK(scene.version() == before);
}

// ---------------------------------------------------------------------------------------
// glTF files
// ---------------------------------------------------------------------------------------
namespace {

using test::TempDir;
using test::tri_bin;

struct GltfParts {
  std::string nodes = R"({"mesh":0,"name":"good"})";
  std::string scene_nodes = "0";
  std::string pos_count = "3";
  std::string view0_length = "36";
  std::string extra;  // more top-level members, each followed by a comma
};
std::string tri_gltf(const GltfParts& p) {
  std::ostringstream j;
  j << R"({"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[)" << p.scene_nodes << "]}]," << p.extra
    << R"("nodes":[)" << p.nodes << "],"
    << R"("meshes":[{"primitives":[{"attributes":{"POSITION":0},"indices":1}]}],)"
    << R"("buffers":[{"uri":"tri.bin","byteLength":44}],)"
    << R"("bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":)" << p.view0_length
    << R"(},{"buffer":0,"byteOffset":36,"byteLength":6}],)"
    << R"("accessors":[{"bufferView":0,"componentType":5126,"count":)" << p.pos_count
    << R"(,"type":"VEC3","min":[0,0,0],"max":[1,1,0]},)"
    << R"({"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR","min":[0],"max":[2]}]})";
  return j.str();
}

std::string all(const std::vector<std::string>& w) {
  std::string s;
  for (auto& x : w) s += x + "\n";
  return s;
}

std::string load_error(const std::string& path) {
  try {
    load_gltf(path);
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "loaded without an error";
}

}  // namespace

TEST_CASE("glTF nodes with scale [1,1,0], a zero matrix or a nearly singular world transform lose their meshes, the rest loads and renders",
          "[stability][validate][gltf]") {
  TempDir dir;
  dir.write("tri.bin", tri_bin());
  const struct {
    const char* name;
    std::string node;
    const char* why;
  } cases[] = {
      {"scale [1,1,0]", R"({"mesh":0,"name":"hidden","scale":[1,1,0]})", "singular"},
      {"zero matrix", R"({"mesh":0,"name":"hidden","matrix":[0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0]})", "singular"},
      {"uniform scale 1e-30", R"({"mesh":0,"name":"hidden","scale":[1e-30,1e-30,1e-30]})", "nearly singular"},
      {"parent scale 1e-20 times child 1", R"({"name":"hidden","scale":[1e-20,1e-20,1e-20],"children":[2]},{"mesh":0})",
       "nearly singular"},
      {"scale 1e19", R"({"mesh":0,"name":"hidden","scale":[1e19,1e19,1e19]})", "scale too large"},
  };
  for (const auto& c : cases) {
    INFO(c.name);
    GltfParts p;
    p.nodes = R"({"mesh":0,"name":"good","translation":[-2,0,0]},)" + c.node;
    p.scene_nodes = "0,1";
    const std::string path = dir.write("hidden.gltf", tri_gltf(p));
    LoadedScene ls = load_gltf(path);
    const std::string w = all(ls.warnings);
    INFO("warnings:\n" << w);
    CHECK(ls.scene.meshes().size() == 1);  // the good node's
    CHECK(has(w, path));
    CHECK(has(w, c.name == std::string("parent scale 1e-20 times child 1") ? "node 2" : "node 1 'hidden'"));
    CHECK(has(w, c.why));
    CHECK(has(w, "left out"));
    // And it renders (it used to abort in Embree).
    ls.scene.set_resolution(16, 16);
    RayTracer rt;
    std::vector<std::string> warnings;
    rt.sync(ls.scene, warnings);
    TaskResult res;
    rt.render({0, 0, 16, 16}, RenderSettings{}, res);
    CHECK(res.image.width == 16);
  }
}

TEST_CASE("a glTF camera node that is degenerate is ignored with a warning", "[stability][validate][gltf]") {
  TempDir dir;
  dir.write("tri.bin", tri_bin());
  for (const char* cam : {R"("scale":[1,1,0])", R"("scale":[1e19,1e19,1e19])", R"("matrix":[0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0])"}) {
    INFO(cam);
    GltfParts p;
    p.nodes = R"({"mesh":0,"name":"good"},{"camera":0,"name":"eye",)" + std::string(cam) + "}";
    p.scene_nodes = "0,1";
    p.extra = R"("cameras":[{"type":"perspective","perspective":{"yfov":0.8,"znear":0.1}}],)";
    const std::string path = dir.write("cam.gltf", tri_gltf(p));
    LoadedScene ls = load_gltf(path);
    const std::string w = all(ls.warnings);
    INFO("warnings:\n" << w);
    CHECK_FALSE(ls.has_camera);
    CHECK(has(w, "node 1 'eye': camera ignored"));
    CHECK(check_camera(ls.scene.camera()).empty());  // the fitted default camera
  }
}

TEST_CASE("glTF accessor counts and bufferView lengths are checked before anything is allocated",
          "[stability][validate][gltf]") {
  TempDir dir;
  dir.write("tri.bin", tri_bin());
  GltfParts p;
  p.pos_count = "2147483647";  // 2^31 - 1: used to end in std::bad_alloc
  std::string path = dir.write("count.gltf", tri_gltf(p));
  std::string msg = load_error(path);
  INFO(msg);
  CHECK(has(msg, path));
  CHECK(has(msg, "2147483647 elements"));
  CHECK(has(msg, "reads past the end of bufferView 0"));

  p = GltfParts{};
  p.view0_length = "1099511627776";  // 2^40: used to be accepted without a word
  path = dir.write("view.gltf", tri_gltf(p));
  msg = load_error(path);
  INFO(msg);
  CHECK(has(msg, path));
  CHECK(has(msg, "bufferView 0"));
  CHECK(has(msg, "byteLength 1099511627776"));
  CHECK(has(msg, "exceeds buffer 0 (44 bytes)"));

  p = GltfParts{};
  p.pos_count = "18446744073709551615";  // 2^64 - 1: must not overflow the check
  msg = load_error(dir.write("huge.gltf", tri_gltf(p)));
  CHECK(msg != "loaded without an error");
}

TEST_CASE("glTF URIs that leave the file's folder are refused, inside ones and data: URIs load", "[stability][validate][gltf]") {
  TempDir dir;
  // A real PNG outside the glTF's folder, one inside it, and the glTF in dir/scene/.
  Image img(2, 2);
  for (auto& b : img.rgba) b = 200;
  write_png(dir.path + "/outside.png", img);
  std::system(("mkdir -p '" + dir.path + "/scene/tex'").c_str());
  write_png(dir.path + "/scene/tex/inside.png", img);
  dir.write("scene/tri.bin", tri_bin());
  auto with_image = [&](const std::string& uri) {
    GltfParts p;
    p.extra = R"("images":[{"uri":")" + uri + R"("}],"textures":[{"source":0}],)";
    return dir.write("scene/img.gltf", tri_gltf(p));
  };
  for (const std::string& uri : {std::string("../outside.png"), std::string("tex/../../outside.png"),
                                 std::string("../../../../etc/passwd"), std::string("%2e%2e/outside.png")}) {
    INFO(uri);
    LoadedScene ls = load_gltf(with_image(uri));
    const std::string w = all(ls.warnings);
    INFO("warnings:\n" << w);
    CHECK(ls.scene.textures().empty());
    CHECK(has(w, "outside the glTF file's folder"));
  }
  // tinygltf joins an absolute URI to the folder ("folder//abs/path"), so it never reads the
  // absolute file either (the folder holds no such file: not found).
  LoadedScene abs = load_gltf(with_image(dir.path + "/outside.png"));
  CHECK(abs.scene.textures().empty());
  LoadedScene ok = load_gltf(with_image("tex/inside.png"));
  CHECK(ok.scene.textures().size() == 1);
  ok = load_gltf(with_image("./tex/../tex/inside.png"));
  CHECK(ok.scene.textures().size() == 1);

  // A buffer outside the folder: the file does not load.
  dir.write("tri.bin", tri_bin());
  std::string text = tri_gltf(GltfParts{});
  text.replace(text.find("\"tri.bin\""), 9, "\"../tri.bin\"");
  const std::string path = dir.write("scene/buf.gltf", text);
  const std::string msg = load_error(path);
  INFO(msg);
  CHECK(has(msg, "outside the glTF file's folder"));
}

// ---------------------------------------------------------------------------------------
// Camera loops
// ---------------------------------------------------------------------------------------
TEST_CASE("camera loops with an eye at 1e39, eye == target, up along the view or a wild fov are refused naming the frame",
          "[stability][validate]") {
  TempDir dir;
  const std::string good = R"({"eye":[0,0,5],"target":[0,0,0],"up":[0,1,0]})";
  auto loop = [&](const std::string& frame1, const std::string& fov = "45") {
    return R"({"fovY_deg": )" + fov + R"(, "frames": [)" + good + "," + frame1 + "]}";
  };
  const struct {
    const char* name;
    std::string text;
    const char* why;
  } cases[] = {
      {"eye 1e39", loop(R"({"eye":[1e39,0,5],"target":[0,0,0],"up":[0,1,0]})"), "frame 1: eye"},
      {"target 1e30", loop(R"({"eye":[0,0,5],"target":[0,1e30,0],"up":[0,1,0]})"), "frame 1: target"},
      {"eye == target", loop(R"({"eye":[1,2,3],"target":[1,2,3],"up":[0,1,0]})"), "frame 1: eye and target"},
      {"up along the view", loop(R"({"eye":[0,0,5],"target":[0,0,0],"up":[0,0,2]})"), "frame 1: up is parallel"},
      {"up zero", loop(R"({"eye":[0,0,5],"target":[0,0,0],"up":[0,0,0]})"), "frame 1: up"},
      {"fov 180", loop(good, "180"), "fovY_deg"},
      {"fov 1e-9", loop(good, "1e-9"), "fovY_deg"},
  };
  for (const auto& c : cases) {
    INFO(c.name);
    const std::string path = dir.write("loop.json", c.text);
    try {
      load_camera_loop(path);
      FAIL("loaded without an error");
    } catch (const std::runtime_error& e) {
      INFO(e.what());
      CHECK(has(e.what(), path));
      CHECK(has(e.what(), c.why));
    }
  }
  CameraLoop ok = load_camera_loop(dir.write("ok.json", loop(good)));
  CHECK(ok.frames.size() == 2);
}

// Analytic scenes for the Embree ray tracer: every expected pixel comes from geometry
// computed here (ray-sphere, ray-plane, Snell's law), not from an earlier rendering.
//
// Colour convention: Environment.linear = false and exposure 1, so a shaded value c in
// 0..1 is written as round(c * 255) and can be predicted to +-1 (float rounding) or to
// the stated tolerance where tessellation enters.
#include <catch2/catch.hpp>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <map>
#include <stdexcept>
#include <thread>
#include <tuple>
#include <utility>

#include <tbb/task_arena.h>

#include "app/bench_kernels.h"
#include "renderer/raytracer.h"
#include "scene_builders.h"

using namespace tessera;
using namespace tessera::testing;

namespace {

constexpr float kDeg = kPi / 180.0f;

// Exact ray-sphere intersection (unit direction); returns t > 0 or -1.
float hit_sphere(Vec3 o, Vec3 d, Vec3 c, float r) {
  Vec3 oc = o - c;
  float b = dot(oc, d), cc = dot(oc, oc) - r * r;
  float disc = b * b - cc;
  if (disc < 0) return -1;
  float s = std::sqrt(disc);
  float t = -b - s;
  if (t > 1e-4f) return t;
  t = -b + s;
  return t > 1e-4f ? t : -1;
}

}  // namespace

// ---------------------------------------------------------------------------------------
// Sphere over a plane: silhouette, N.L shading, plane edges and the sphere's shadow,
// all against an exact analytic model, pixel by pixel.
// ---------------------------------------------------------------------------------------
TEST_CASE("sphere and plane: silhouette, N.L shading, plane edges and shadow match geometry", "[raytracer][analytic]") {
  Scene scene;
  const int W = 65, H = 65;
  scene.set_resolution(W, H);
  scene.set_environment(plain_env({0, 0, 1}));
  scene.set_material(1, diffuse({1, 1, 1}));
  scene.set_material(2, diffuse({1, 1, 0}));
  const float R = 1.0f;
  add_object(scene, 100, sphere(R, 128), 1);
  // Plane y = -1, x in [-10, 10], z in [-20, 0.5] (its near edge and far edge are in view).
  add_object(scene, 200, quad({-10, -1, 0.5f}, {20, 0, 0}, {0, 0, -20.5f}), 2);
  const Vec3 travel{0, -1, -1};
  scene.set_light(1, directional(travel));
  const Vec3 L = normalize(-travel);
  Camera cam = look({0, 0, 5}, {0, 0, 0}, 30 * kDeg);
  scene.set_camera(cam);

  RayTracer rt;
  std::vector<std::string> warnings;
  Image img = render_full(rt, scene, no_ao(), &warnings);
  REQUIRE(warnings.empty());
  REQUIRE(img.width == W);
  REQUIRE(img.height == H);

  // The analytic model: 0 background, 1 sphere, 2 lit plane, 3 shadowed plane.
  const Vec3 eye = cam_pos(cam);
  auto classify = [&](float x, float y, Vec3* n_out) {
    Vec3 d = pixel_dir(cam, W, H, x, y);
    float ts = hit_sphere(eye, d, {0, 0, 0}, R);
    float tp = -1;
    if (d.y < 0) {
      float t = (-1 - eye.y) / d.y;
      Vec3 p = eye + d * t;
      if (p.x >= -10 && p.x <= 10 && p.z >= -20 && p.z <= 0.5f) tp = t;
    }
    if (ts > 0 && (tp < 0 || ts < tp)) {
      if (n_out) *n_out = normalize(eye + d * ts);
      return 1;
    }
    if (tp > 0) {
      Vec3 p = eye + d * tp;
      return hit_sphere(p, L, {0, 0, 0}, R) > 0 ? 3 : 2;
    }
    return 0;
  };

  // Centre pixel: the ray through the sphere centre hits at normal (0,0,1): N.L = 1/sqrt(2).
  Rgb c = px(img, W / 2, H / 2);
  int expect_centre = int(std::lround(255 * dot(Vec3{0, 0, 1}, L)));
  INFO("centre pixel " << str(c) << " expected " << expect_centre);
  CHECK(std::abs(c.r - expect_centre) <= 2);
  CHECK(std::abs(c.g - expect_centre) <= 2);
  CHECK(std::abs(c.b - expect_centre) <= 2);

  int counted[4] = {0, 0, 0, 0};
  int bad = 0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      // Only pixels whose whole footprint (centre and the 4 pixel corners, i.e. +-0.5 pixel)
      // falls in one class are checked: "the silhouette is where geometry says within a pixel".
      Vec3 n;
      int k = classify(float(x), float(y), &n);
      bool robust = true;
      for (float dx : {-0.5f, 0.5f})
        for (float dy : {-0.5f, 0.5f})
          if (classify(x + dx, y + dy, nullptr) != k) robust = false;
      if (!robust) continue;
      ++counted[k];
      Rgb p = px(img, x, y);
      Rgb e{0, 0, 0};
      int tol = 1;
      switch (k) {
        case 0: e = {0, 0, 255}; break;
        case 1: {
          int v = int(std::lround(255 * std::max(0.0f, dot(n, L))));
          e = {v, v, v};
          tol = 4;  // 128-segment tessellation with interpolated normals
          break;
        }
        case 2: {
          int v = int(std::lround(255 * dot(Vec3{0, 1, 0}, L)));
          e = {v, v, 0};
          break;
        }
        case 3: e = {0, 0, 0}; break;
      }
      if (std::abs(p.r - e.r) > tol || std::abs(p.g - e.g) > tol || std::abs(p.b - e.b) > tol) {
        if (bad < 10) UNSCOPED_INFO("pixel " << x << "," << y << " class " << k << " got " << str(p) << " expected " << str(e));
        ++bad;
      }
    }
  CHECK(bad == 0);
  // Every class was actually exercised.
  CHECK(counted[0] > 100);
  CHECK(counted[1] > 1000);
  CHECK(counted[2] > 50);
  CHECK(counted[3] > 20);
}

// ---------------------------------------------------------------------------------------
// Textures: the renderer shares the scene's bytes (core/shared_bytes.h) and keeps them.
// ---------------------------------------------------------------------------------------
TEST_CASE("a renderer shares a texture's bytes with the scene and keeps showing them after the scene changed or went",
          "[raytracer][textures]") {
  const int W = 16, H = 16;
  auto make = [&](uint8_t r, uint8_t g) {
    auto scene = std::make_unique<Scene>();
    scene->set_resolution(W, H);
    scene->set_environment(plain_env({0, 0, 0}));
    Texture tex;
    tex.width = tex.height = 1;
    tex.rgba = {r, g, 0, 255};
    scene->set_texture(1, tex);
    Material m = matte({1, 1, 1});
    m.diffuse_texture = 1;
    scene->set_material(1, m);
    Mesh q = add_geometry(*scene, 100, quad({-4, -4, 0}, {8, 0, 0}, {0, 8, 0}));
    q.material = 1;
    scene->set_mesh(10, q);
    scene->set_camera(look({0, 0, 10}, {0, 0, 0}, 0.5f));
    return scene;
  };
  std::unique_ptr<Scene> red = make(200, 0);
  RayTracer rt;
  Image img = render_full(rt, *red, no_ao());
  CHECK(px(img, W / 2, H / 2).r > 20);
  CHECK(px(img, W / 2, H / 2).g == 0);
  // The scene's texture changes (its bytes copied on write: the renderer's stay), then the
  // scene goes; until its next sync the renderer shows what it synced (under ASan this also
  // proves it reads no freed memory).
  Texture changed = red->textures().at(1).value;
  changed.rgba[0] = 0;
  red->set_texture(1, changed);
  red.reset();
  TaskResult r;
  rt.render({0, 0, W, H}, no_ao(), r);
  CHECK(std::memcmp(r.image.rgba.data(), img.rgba.data(), img.rgba.size()) == 0);
  // A new scene: the next sync shows its texture.
  std::unique_ptr<Scene> green = make(0, 200);
  Image g = render_full(rt, *green, no_ao());
  CHECK(px(g, W / 2, H / 2).r == 0);
  CHECK(px(g, W / 2, H / 2).g > 20);
}

// ---------------------------------------------------------------------------------------
// Instancing: two meshes share one buffer set (one BLAS), placed by their transforms.
// ---------------------------------------------------------------------------------------
TEST_CASE("instances of one geometry appear at their exact offsets; moving one only updates its instance", "[raytracer][instancing]") {
  Scene scene;
  const int W = 80, H = 40;
  scene.set_resolution(W, H);
  scene.set_environment(plain_env({0, 0, 0}));
  // A 1x1 quad at z = 0 with a 2x2 texture so that the copies are not uniform.
  Texture tex;
  tex.width = tex.height = 2;
  tex.rgba = {200, 0, 0, 255, 0, 200, 0, 255, 0, 0, 200, 255, 200, 200, 200, 255};
  tex.sampler.filter = Sampler::Filter::nearest;
  tex.sampler.wrap_s = tex.sampler.wrap_t = Sampler::Wrap::clamp;
  scene.set_texture(1, tex);
  Material m = matte({1, 1, 1});
  m.diffuse_texture = 1;
  scene.set_material(1, m);
  Mesh base = add_geometry(scene, 100, quad({-0.5f, -0.5f, 0}, {1, 0, 0}, {0, 1, 0}));
  base.material = 1;
  Mesh a = base, b = base;
  a.transform = Mat4::translate({-2, 0, 0});
  b.transform = Mat4::translate({2, 0, 0});
  scene.set_mesh(10, a);
  scene.set_mesh(20, b);
  // tan(fov/2) = 0.25, aspect 2, distance 10: exactly 8 pixels per world unit at z = 0.
  scene.set_camera(look({0, 0, 10}, {0, 0, 0}, 2 * std::atan(0.25f)));

  RayTracer rt;
  std::vector<std::string> warnings;
  Image img = render_full(rt, scene, no_ao(), &warnings);
  REQUIRE(warnings.empty());
  // One BLAS for both instances.
  CHECK(rt.last_sync().geometries_built == 1);
  CHECK(rt.last_sync().instances_updated == 2);

  // Quad A covers x in [-2.5, -1.5] -> pixels [20, 28), y in [-0.5, 0.5] -> rows [16, 24).
  // Quad B covers pixels [52, 60): exactly 32 pixels to the right.
  auto covered = [](const Image& im, int x, int y) {
    Rgb p = px(im, x, y);
    return p.r + p.g + p.b > 0;
  };
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      bool in_a = x >= 20 && x < 28 && y >= 16 && y < 24;
      bool in_b = x >= 52 && x < 60 && y >= 16 && y < 24;
      INFO("pixel " << x << "," << y);
      REQUIRE(covered(img, x, y) == (in_a || in_b));
    }
  // The copies are pixel-identical (same texels at the same places).
  for (int y = 16; y < 24; ++y)
    for (int x = 20; x < 28; ++x) {
      INFO("pixel " << x << "," << y);
      REQUIRE(std::memcmp(img.pixel(x, y), img.pixel(x + 32, y), 4) == 0);
    }
  // The top-left texel of copy A is red, bottom-right grey.
  CHECK(px(img, 21, 17).r == 200);
  CHECK(px(img, 21, 17).g == 0);
  CHECK(px(img, 26, 22).g == 200);

  // Move B up by one unit (8 pixels): no BLAS rebuild, one instance update.
  b.transform = Mat4::translate({2, 1, 0});
  scene.set_mesh(20, b);
  Image moved = render_full(rt, scene, no_ao(), &warnings);
  REQUIRE(warnings.empty());
  CHECK(rt.last_sync().geometries_built == 0);
  CHECK(rt.last_sync().instances_updated == 1);
  CHECK(rt.last_sync().instances_removed == 0);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      bool in_a = x >= 20 && x < 28 && y >= 16 && y < 24;
      bool in_b = x >= 52 && x < 60 && y >= 8 && y < 16;
      INFO("pixel " << x << "," << y);
      REQUIRE(covered(moved, x, y) == (in_a || in_b));
    }
  for (int y = 16; y < 24; ++y)
    for (int x = 20; x < 28; ++x) REQUIRE(std::memcmp(moved.pixel(x, y), moved.pixel(x + 32, y - 8), 4) == 0);

  // A sync with nothing changed touches nothing.
  render_full(rt, scene, no_ao(), &warnings);
  CHECK(rt.last_sync().geometries_built == 0);
  CHECK(rt.last_sync().instances_updated == 0);
}

// ---------------------------------------------------------------------------------------
// Textures
// ---------------------------------------------------------------------------------------
TEST_CASE("a 2x2 nearest texture on a quad facing the camera shows its texels exactly (diffuse and emissive)", "[raytracer][texture]") {
  Scene scene;
  const int W = 64, H = 64;
  scene.set_resolution(W, H);
  scene.set_environment(plain_env({0, 0, 0}));
  Texture tex;
  tex.width = tex.height = 2;
  // Row 0 is the top of the image (v = 0).
  const uint8_t texels[4][4] = {{250, 10, 20, 255}, {15, 240, 30, 255}, {5, 25, 235, 255}, {123, 77, 201, 255}};
  tex.rgba.resize(16);
  for (int i = 0; i < 16; ++i) tex.rgba[size_t(i)] = texels[i / 4][i % 4];
  tex.sampler.filter = Sampler::Filter::nearest;
  scene.set_texture(7, tex);
  // Quad [-1,1]^2 at z = 0; its top-left corner has texcoord (0, 0).
  add_object(scene, 100, quad({-1, -1, 0}, {2, 0, 0}, {0, 2, 0}), 1);
  Camera cam = look({0, 0, 3}, {0, 0, 0}, 60 * kDeg);
  scene.set_camera(cam);

  // An unlit matte material shows its diffuse texture; a lit material without diffuse colour
  // and without lights shows its emissive colour (white) times its emissive texture.
  Material textured_matte = matte({1, 1, 1});
  textured_matte.diffuse_texture = 7;
  Material emissive = diffuse({0, 0, 0});
  emissive.emissive_color = {1, 1, 1};
  emissive.emissive_texture = 7;
  for (auto [linear, slot] : std::initializer_list<std::pair<bool, int>>{{false, 0}, {true, 0}, {false, 1}, {true, 1}}) {
    scene.set_material(1, slot == 0 ? textured_matte : emissive);
    Environment env = plain_env({0, 0, 0});
    env.linear = linear;  // sRGB decode on lookup, sRGB encode on output: the texel comes back
    scene.set_environment(env);
    RayTracer rt;
    Image img = render_full(rt, scene, no_ao());
    REQUIRE(rt.features().textures);
    const Vec3 centres[4] = {{-0.5f, 0.5f, 0}, {0.5f, 0.5f, 0}, {-0.5f, -0.5f, 0}, {0.5f, -0.5f, 0}};
    for (int q = 0; q < 4; ++q) {
      float fx, fy;
      project(cam, W, H, centres[q], fx, fy);
      // The quadrant's central 5x5 pixels.
      for (int dy = -2; dy <= 2; ++dy)
        for (int dx = -2; dx <= 2; ++dx) {
          Rgb p = px(img, int(std::lround(fx)) + dx, int(std::lround(fy)) + dy);
          INFO((slot == 0 ? "diffuse" : "emissive") << " linear " << linear << " texel " << q << " got " << str(p));
          int tol = linear ? 1 : 0;  // sRGB round trip through float
          CHECK(std::abs(p.r - texels[q][0]) <= tol);
          CHECK(std::abs(p.g - texels[q][1]) <= tol);
          CHECK(std::abs(p.b - texels[q][2]) <= tol);
        }
    }
  }
}

// Trilinear filtering: a linear texture is read from the mip level that matches the pixel's
// footprint (ray cones). A 256x256 checkerboard on a quad that faces the camera, seen with a 2
// degree field of view on 32x32 pixels from a distance where a pixel covers F x F texels:
// footprint F = d tan(fov / 2) T / H. The camera sits half a texel off the texel grid, so pixel
// centres fall on level-0 texel centres (level 0 alone shows pure black and white).
namespace {

Texture checkerboard(int size, int check) {
  Texture t;
  t.width = t.height = size;
  t.rgba.resize(size_t(size) * size_t(size) * 4);
  for (int y = 0; y < size; ++y)
    for (int x = 0; x < size; ++x) {
      const uint8_t v = ((x / check + y / check) % 2) ? 255 : 0;
      for (int c = 0; c < 3; ++c) t.rgba[(size_t(y) * size_t(size) + size_t(x)) * 4 + size_t(c)] = v;
      t.rgba[(size_t(y) * size_t(size) + size_t(x)) * 4 + 3] = 255;
    }
  return t;
}

// The 8-bit sRGB code of a linear value, from the exact curve.
int srgb_of(double linear) {
  const double e = linear <= 0.0031308 ? 12.92 * linear : 1.055 * std::pow(linear, 1 / 2.4) - 0.055;
  return int(std::lround(e * 255));
}

struct LodScene {
  static constexpr int kW = 32, kT = 256;
  static constexpr float kFov = 2 * kDeg;
  Scene scene;
  // Camera distance for a footprint of `texels` texels a pixel.
  static float distance(float texels) { return texels * float(kW) / (float(kT) * std::tan(kFov / 2)); }
  LodScene(int check, Sampler::Filter filter, bool linear) {
    scene.set_resolution(kW, kW);
    Environment env = plain_env();
    env.linear = linear;
    scene.set_environment(env);
    Texture tex = checkerboard(kT, check);
    tex.sampler.filter = filter;
    scene.set_texture(7, tex);
    Material m = matte({1, 1, 1});
    m.diffuse_texture = 7;
    scene.set_material(1, m);
  }
  void direct(float texels) {
    add_object(scene, 100, quad({-1, -1, 0}, {2, 0, 0}, {0, 2, 0}), 1);
    const float s = 1.0f / kT;  // half a texel
    scene.set_camera(look({s, s, distance(texels)}, {s, s, 0}, kFov));
  }
  // The same footprint through a mirror at z = 0: 30% of the path to the mirror, 70% back to
  // the textured quad at z = 0.7 d, behind the camera and facing it.
  void mirrored(float texels) {
    const float d = distance(texels);
    Material mirror = matte({0, 0, 0});
    mirror.reflection = 1;
    scene.set_material(2, mirror);
    add_object(scene, 200, quad({-1, -1, 0}, {2, 0, 0}, {0, 2, 0}), 2);
    add_object(scene, 100, quad({-1, -1, 0.7f * d}, {0, 2, 0}, {2, 0, 0}), 1);
    const float s = 1.0f / kT;
    scene.set_camera(look({s, s, 0.3f * d}, {s, s, 0}, kFov));
  }
  // Renders the whole frame with a fresh ray tracer (written to $TESSERA_TEST_DUMP as `name`).
  Image render(const RenderSettings& settings, const std::string& name) const {
    RayTracer rt;
    const Image img = render_full(rt, scene, settings);
    dump(name, img);
    return img;
  }
};

// Every pixel's red channel.
std::vector<int> reds(const Image& img) {
  std::vector<int> out;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) out.push_back(px(img, x, y).r);
  return out;
}

// Every pixel's red channel is `expected` within 1 (a uniform grey), or, with expected < 0,
// black or white (checks seen at level 0).
void require_reds(const Image& img, int expected, const std::string& what) {
  for (int r : reds(img)) {
    INFO(what << ": red " << r << " expected " << (expected < 0 ? std::string("0 or 255") : std::to_string(expected)));
    if (expected < 0) REQUIRE((r <= 1 || r >= 254));
    else REQUIRE(std::abs(r - expected) <= 1);
  }
}

}  // namespace

TEST_CASE("trilinear filtering reads the mip level of a pixel's footprint, averaged as linear light", "[raytracer][texture][mip]") {
  RenderSettings settings = no_ao();
  SECTION("1-texel checks, 2 texels a pixel: level 1 is a uniform grey of linear 0.5 (sRGB 188, not 128)") {
    for (bool linear : {true, false}) {
      LodScene ls(1, Sampler::Filter::linear, linear);
      ls.direct(2);
      const Image img = ls.render(settings, std::string("mip_grey_") + (linear ? "linear" : "plain"));
      // Linear scenes decode sRGB texels and average light (sRGB 188 is the code nearest linear
      // 0.5: 0.5029, against 0.4969 for 187); plain scenes average the codes: (0 + 255) / 2.
      require_reds(img, linear ? 188 : 128, linear ? "linear" : "plain");
      // Level 0 alone (the renderer before mip levels) shows the checks themselves.
      RenderSettings level0 = settings;
      level0.mip_levels = false;
      require_reds(ls.render(level0, "mip_level0"), -1, "level 0 alone");
    }
  }
  SECTION("2-texel checks: level 1 at 2 texels a pixel (checks of one pixel, blended 3:1 by the half-texel offset), "
          "level 2 at 4 texels (grey)") {
    LodScene near(2, Sampler::Filter::linear, true);
    near.direct(2);
    const Image img = near.render(settings, "mip_level1");
    // Level 1 has one-texel checks; a pixel centre sits a quarter texel off a level-1 texel
    // centre in x and in y: weights 3/4 and 1/4 each way, so 10/16 of its own check's colour.
    const int bright = srgb_of(0.625), dark = srgb_of(0.375);
    for (int y = 0; y < LodScene::kW; ++y)
      for (int x = 0; x < LodScene::kW; ++x) {
        const int r = px(img, x, y).r;
        INFO("pixel " << x << "," << y << " red " << r << " (" << bright << " or " << dark << ")");
        REQUIRE((std::abs(r - bright) <= 2 || std::abs(r - dark) <= 2));
        if (x > 0) REQUIRE(std::abs(r - px(img, x - 1, y).r) >= 30);  // neighbours alternate
      }
    LodScene far(2, Sampler::Filter::linear, true);
    far.direct(4);
    require_reds(far.render(settings, "mip_level2"), 188, "level 2");
  }
  SECTION("a nearest texture has no mip levels") {
    LodScene ls(1, Sampler::Filter::nearest, true);
    ls.direct(2);
    require_reds(ls.render(settings, "mip_nearest"), -1, "nearest");
  }
  SECTION("through a mirror the cone keeps the width it had at the mirror") {
    // With the cone restarted at the mirror the footprint would be 0.7 x 2 texels (level 0.49,
    // half checks); carried through it, 2 texels: level 1's uniform grey.
    LodScene ls(1, Sampler::Filter::linear, true);
    ls.mirrored(2);
    require_reds(ls.render(settings, "mip_mirror"), 188, "through a mirror");
  }
}

// XML3D's useVertexColor: a quad with red, green, blue and white corners; the vertex colour,
// interpolated with the hit's barycentrics, multiplies the diffuse colour where the material
// asks for it, and changes nothing where it does not or where the mesh has no colours.
TEST_CASE("vertex colours multiply the diffuse colour of materials with use_vertex_color", "[raytracer][vertex-color]") {
  const int W = 96, H = 96;
  const Camera cam = look({0, 0, 3}, {0, 0, 0}, 60 * kDeg);
  // quad()'s corners: (-1,-1) red, (1,-1) green, (1,1) blue, (-1,1) white; triangles 0 1 2 and 0 2 3.
  const float colors[12] = {1, 0, 0, 0, 1, 0, 0, 0, 1, 1, 1, 1};
  auto expected = [&](float x, float y) {  // the interpolated vertex colour at (x, y) on the quad
    const float* c = colors;
    Vec3 red{c[0], c[1], c[2]}, green{c[3], c[4], c[5]}, blue{c[6], c[7], c[8]}, white{c[9], c[10], c[11]};
    if (x >= y) return red * ((1 - x) / 2) + green * ((x - y) / 2) + blue * ((y + 1) / 2);
    return red * ((1 - y) / 2) + blue * ((x + 1) / 2) + white * ((y - x) / 2);
  };
  auto make_scene = [&](const Material& mat, bool with_colors) {
    Scene scene;
    scene.set_resolution(W, H);
    scene.set_environment(plain_env({0, 0, 0}));
    scene.set_camera(cam);
    scene.set_material(1, mat);
    Mesh m = add_geometry(scene, 100, quad({-1, -1, 0}, {2, 0, 0}, {0, 2, 0}));
    if (with_colors) {
      Buffer c;
      c.components = 3;
      c.f.assign(colors, colors + 12);
      scene.set_buffer(110, c);
      m.colors = 110;
    }
    m.material = 1;
    scene.set_mesh(100, m);
    REQUIRE(scene.validate_mesh(m).empty());
    return scene;
  };
  // Every pixel whose centre's ray hits the quad at least 0.05 inside its edges: the colour of
  // that hit point, times `tint`, or white times tint where `colored` is false.
  auto check = [&](const Image& img, Vec3 tint, bool colored, const char* what) {
    int checked = 0, bad = 0;
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const Vec3 o = cam_pos(cam), d = pixel_dir(cam, W, H, float(x), float(y));
        const float t = -o.z / d.z;
        const Vec3 hit = o + d * t;
        if (std::fabs(hit.x) > 0.95f || std::fabs(hit.y) > 0.95f) continue;
        const Vec3 c = colored ? expected(hit.x, hit.y) : Vec3{1, 1, 1};
        const int want[3] = {int(std::lround(std::fmin(c.x * tint.x, 1.0f) * 255)),
                             int(std::lround(std::fmin(c.y * tint.y, 1.0f) * 255)),
                             int(std::lround(std::fmin(c.z * tint.z, 1.0f) * 255))};
        const Rgb p = px(img, x, y);
        ++checked;
        if (std::abs(p.r - want[0]) > 2 || std::abs(p.g - want[1]) > 2 || std::abs(p.b - want[2]) > 2) {
          if (++bad <= 5)
            FAIL_CHECK(what << ": pixel (" << x << "," << y << ") at (" << hit.x << "," << hit.y << ") is " << str(p)
                            << ", expected (" << want[0] << "," << want[1] << "," << want[2] << ")");
        }
      }
    CHECK(checked > 2000);
    CHECK(bad == 0);
  };
  Material vc = matte({1, 1, 1});
  vc.use_vertex_color = true;
  for (PacketLayout layout : {PacketLayout{2, 2}, PacketLayout{4, 2}, PacketLayout{4, 4}}) {
    INFO("packet " << layout.w << "x" << layout.h);
    {
      RayTracer rt(layout);
      Image img = render_full(rt, make_scene(vc, true), no_ao());
      dump("vertex_color", img);
      CHECK(rt.features().vertex_colors);
      CHECK_FALSE(rt.plain_kernel(no_ao()));
      check(img, {1, 1, 1}, true, "use_vertex_color, white diffuse");
      // Near each corner its own colour dominates.
      float fx, fy;
      project(cam, W, H, {-0.85f, -0.85f, 0}, fx, fy);
      Rgb near_red = px(img, int(std::lround(fx)), int(std::lround(fy)));
      CHECK((near_red.r > 200 && near_red.g < 40 && near_red.b < 40));
      project(cam, W, H, {0.85f, -0.85f, 0}, fx, fy);
      Rgb near_green = px(img, int(std::lround(fx)), int(std::lround(fy)));
      CHECK((near_green.g > 200 && near_green.r < 40 && near_green.b < 40));
    }
    {
      Material tinted = vc;
      tinted.diffuse_color = {0.5f, 1, 0.25f};  // multiplied, not replaced
      RayTracer rt(layout);
      check(render_full(rt, make_scene(tinted, true), no_ao()), {0.5f, 1, 0.25f}, true, "use_vertex_color, tinted diffuse");
    }
    {
      RayTracer rt(layout);  // the flag off: the colours are ignored
      check(render_full(rt, make_scene(matte({1, 1, 1}), true), no_ao()), {1, 1, 1}, false, "flag off");
      CHECK_FALSE(rt.features().vertex_colors);
    }
    {
      RayTracer rt(layout);  // the flag on, but the mesh has no colours: the diffuse colour alone
      check(render_full(rt, make_scene(vc, false), no_ao()), {1, 1, 1}, false, "no colour buffer");
      CHECK_FALSE(rt.features().vertex_colors);
    }
  }
  // Lit: a diffuse material under a light from the camera's side is the vertex colour times
  // diffuse times N.L (1 here), as without vertex colours; a changed colour buffer is picked up.
  {
    Material lit = diffuse({1, 1, 1});
    lit.use_vertex_color = true;
    Scene scene = make_scene(lit, true);
    Light l = directional({0, 0, -1});
    scene.set_light(1, l);
    RayTracer rt;
    check(render_full(rt, scene, no_ao()), {1, 1, 1}, true, "diffuse, lit head-on");
    Buffer grey;
    grey.components = 3;
    grey.f.assign(12, 0.5f);
    scene.set_buffer(110, grey);
    check(render_full(rt, scene, no_ao()), {0.5f, 0.5f, 0.5f}, false, "colour buffer changed to grey");
  }
}

// ---------------------------------------------------------------------------------------
// Phong highlights
// ---------------------------------------------------------------------------------------
// Two Phong quads side by side facing the camera, lit from the camera's side: the right one
// with a specular colour shows the highlight dr N.L + sr (R.V)^e around the view axis, the
// left one (specular colour 0) is dr N.L everywhere: the kernel leaves the highlight's power
// out where no lane shows one, which must not change a pixel. Packets on the seam hold lanes
// of both materials.
TEST_CASE("a Phong highlight follows (R.V)^e; a zero specular colour shows none", "[raytracer][phong]") {
  const int W = 48, H = 32;
  Scene scene;
  scene.set_resolution(W, H);
  scene.set_environment(plain_env({0, 0, 0}));
  Material dull = diffuse({0.4f, 0.4f, 0.4f});
  dull.model = Material::Model::phong;  // a specular colour of 0
  Material shiny = diffuse({0.3f, 0.2f, 0.1f});
  shiny.model = Material::Model::phong;
  shiny.specular_color = {0.5f, 0.6f, 0.7f};
  shiny.shininess = 16.0f / 128.0f;  // exponent 16
  scene.set_material(1, dull);
  scene.set_material(2, shiny);
  add_object(scene, 100, quad({-3, -3, 0}, {3, 0, 0}, {0, 6, 0}), 1);
  add_object(scene, 200, quad({0, -3, 0}, {3, 0, 0}, {0, 6, 0}), 2);
  scene.set_light(1, directional({0, 0, -1}));
  Camera cam = look({0.3f, 0.2f, 2}, {0.3f, 0.2f, 0}, 60 * kDeg);
  scene.set_camera(cam);
  RayTracer rt;
  Image img = render_full(rt, scene, no_ao(1));
  const Vec3 eye = cam_pos(cam);
  int checked[2] = {0, 0}, bright = 0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const Vec3 d = pixel_dir(cam, W, H, float(x), float(y));
      const Vec3 p = eye + d * (-eye.z / d.z);
      if (std::fabs(p.x) < 0.05f) continue;  // the seam
      const bool right = p.x > 0;
      const Material& m = right ? shiny : dull;
      // N = L = (0, 0, 1): N.L = 1, R = (0, 0, 1), R.V = -d.z.
      const double rv = -d.z, highlight = std::pow(rv, 16.0);
      const double want[3] = {m.diffuse_color.x + m.specular_color.x * highlight,
                              m.diffuse_color.y + m.specular_color.y * highlight,
                              m.diffuse_color.z + m.specular_color.z * highlight};
      const Rgb got = px(img, x, y);
      const int g[3] = {got.r, got.g, got.b};
      for (int c = 0; c < 3; ++c) {
        INFO("pixel " << x << "," << y << (right ? " shiny" : " dull") << " channel " << c << " want "
                      << 255 * want[c] << " got " << g[c]);
        CHECK(std::abs(g[c] - 255 * std::min(want[c], 1.0)) <= 1.0);
      }
      ++checked[right];
      bright += right && highlight > 0.5;
    }
  CHECK(checked[0] > W * H / 4);
  CHECK(checked[1] > W * H / 4);
  CHECK(bright > 10);  // the highlight is in view
}

// ---------------------------------------------------------------------------------------
// Output encoding
// ---------------------------------------------------------------------------------------
// A linear scene's output is sRGB-encoded. An unlit matte quad filling the view shows its
// diffuse colour as it is, so each channel's code can be checked against the exact curve,
// rounded: off by at most one, and exact unless the curve passes within 0.05 of a half step
// (the encoder's stated error is 0.04). The sweep covers the linear segment, the joint at
// 0.0031308, dark values (where a table indexed in 1/4096 steps is off by up to 0.4 of a step),
// the bright end and clamping above 1, in every packet layout's copy of the kernel.
TEST_CASE("sRGB output codes are the exact curve's, rounded, over the whole range", "[raytracer][output]") {
  const int W = 4, H = 4;
  Scene scene;
  scene.set_resolution(W, H);
  Environment env = plain_env({0, 0, 0});
  env.linear = true;
  scene.set_environment(env);
  add_object(scene, 100, quad({-4, -4, 0}, {8, 0, 0}, {0, 8, 0}), 1);
  scene.set_camera(look({0, 0, 2}, {0, 0, 0}, 60 * kDeg));
  auto exact = [](double c) {  // the code's exact value, before rounding
    c = std::min(std::max(c, 0.0), 1.0);
    return 255.0 * (c <= 0.0031308 ? 12.92 * c : 1.055 * std::pow(c, 1 / 2.4) - 0.055);
  };
  for (PacketLayout layout : {PacketLayout{2, 2}, PacketLayout{4, 2}, PacketLayout{4, 4}}) {
    RayTracer rt(layout);
    int checked = 0, off_by_one = 0;
    for (int k = 0; k <= 300; ++k) {
      const float c[3] = {k / 256.0f,                       // 0 .. 1.17: the whole curve and clamping
                          (k / 300.0f) * (k / 300.0f) * 0.05f,  // dense in the dark
                          0.0031308f * (k / 150.0f)};           // across the joint of the two segments
      scene.set_material(1, matte({c[0], c[1], c[2]}));
      Image img = render_full(rt, scene, no_ao());
      const Rgb p = px(img, W / 2, H / 2);
      const int got[3] = {p.r, p.g, p.b};
      for (int ch = 0; ch < 3; ++ch) {
        const double v = exact(c[ch]);
        const int rounded = int(std::floor(v + 0.5));
        INFO("layout " << layout.w << "x" << layout.h << " channel value " << c[ch] << " exact code " << v
                       << " got " << got[ch]);
        CHECK(std::abs(got[ch] - rounded) <= 1);
        if (std::abs(v - std::floor(v) - 0.5) > 0.05) CHECK(got[ch] == rounded);
        off_by_one += got[ch] != rounded;
        ++checked;
      }
      for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) REQUIRE(std::memcmp(img.pixel(x, y), img.pixel(W / 2, H / 2), 3) == 0);
    }
    INFO(off_by_one << " of " << checked << " codes off by one");
    CHECK(off_by_one <= checked / 100);
  }
}

// The benchmarks' floor (bench::render_shading_floor, compiled into the app only): no shading,
// hits white, misses the background, and the task still gets its cost map and ray counts.
TEST_CASE("the shading floor renders hits white and misses as background, with a full cost map", "[raytracer][bench]") {
  const int W = 32, H = 16;
  Scene scene;
  scene.set_resolution(W, H);
  scene.set_environment(plain_env({0, 0, 1}));
  scene.set_material(1, diffuse({1, 0, 0}));
  scene.set_light(1, directional({0, 0, -1}));
  // A quad filling the left half of the view only.
  add_object(scene, 100, quad({-10, -10, 0}, {10, 0, 0}, {0, 20, 0}), 1);
  scene.set_camera(look({0, 0, 2}, {0, 0, 0}, 60 * kDeg));
  RayTracer rt;
  TaskResult shaded, bare;
  render_full(rt, scene, no_ao(1), nullptr, &shaded);
  bench::render_shading_floor(rt, {0, 0, W, H}, no_ao(1), bare);
  const Image& img = bare.image;
  int hits = 0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const Rgb p = px(img, x, y), s = px(shaded.image, x, y);
      INFO("pixel " << x << "," << y << " floor " << str(p) << " shaded " << str(s));
      if (x < W / 2) {
        CHECK((p.r == 255 && p.g == 255 && p.b == 255));
        CHECK((s.r > 0 && s.g == 0 && s.b == 0));  // the real shading: the lit red quad
        ++hits;
      } else {
        CHECK((p.r == 0 && p.g == 0 && p.b == 255));
        CHECK((s.r == p.r && s.g == p.g && s.b == p.b));
      }
    }
  CHECK(hits == W * H / 2);
  CHECK(bare.rays.primary == uint64_t(W * H));
  CHECK(bare.rays.shadow == 0);  // no light is evaluated
  CHECK(bare.cost.cost.size() == shaded.cost.cost.size());
  CHECK(bare.kernel_ms > 0);
}

// ---------------------------------------------------------------------------------------
// Alpha masks
// ---------------------------------------------------------------------------------------
TEST_CASE("alpha-masked cut-outs are transparent to camera rays and cast no shadow", "[raytracer][alpha]") {
  Scene scene;
  const int W = 101, H = 101;
  scene.set_resolution(W, H);
  // Left half opaque, right half cut out (alpha 0); light along (1, 0, -1): shadows fall one
  // unit to +x on the back quad.
  add_cutout(scene, 100, true);
  Camera cam = look({0, 0, 5}, {0, 0, 0}, 60 * kDeg);
  scene.set_camera(cam);
  RayTracer rt;
  std::vector<std::string> warnings;
  Image img = render_full(rt, scene, no_ao(), &warnings);
  REQUIRE(warnings.empty());
  REQUIRE(rt.features().alpha_masks);

  const int lit = int(std::lround(255 * (0.2f + std::sqrt(0.5f))));
  const int dark = int(std::lround(255 * 0.2f));
  struct Probe {
    Vec3 p;
    Rgb expect;
    const char* what;
  };
  const Probe probes[] = {
      {{-0.5f, 0, 0}, {lit, 0, 0}, "opaque half of the masked quad"},
      {{0.2f, 0, -1}, {0, dark, 0}, "back quad seen through the cut-out, shadowed by the opaque half"},
      {{1.1f, 0, -1}, {0, lit, 0}, "back quad seen through the cut-out, its light passing through the cut-out"},
      {{1.5f, 0, -1}, {0, lit, 0}, "back quad beside the masked quad, its light passing through the cut-out"},
      {{0.5f, 0.5f, -1}, {0, dark, 0}, "back quad through the cut-out, in the opaque half's shadow"},
      {{3.0f, 0, -1}, {0, lit, 0}, "back quad, unshadowed"},
  };
  for (const Probe& pr : probes) {
    float fx, fy;
    project(cam, W, H, pr.p, fx, fy);
    Rgb p = px(img, int(std::lround(fx)), int(std::lround(fy)));
    INFO(pr.what << ": got " << str(p) << " expected " << str(pr.expect));
    CHECK(std::abs(p.r - pr.expect.r) <= 1);
    CHECK(std::abs(p.g - pr.expect.g) <= 1);
    CHECK(std::abs(p.b - pr.expect.b) <= 1);
  }
}

// XML3D's castShadow: a light that does not cast shadows reaches every surface facing it and
// traces no shadow rays; casting, the same light leaves the back quad dark behind the front one.
TEST_CASE("a light with cast_shadow false lights what another surface hides from it, with no shadow rays", "[raytracer][shadow]") {
  const int W = 101, H = 101;
  Scene scene;
  scene.set_resolution(W, H);
  scene.set_environment(plain_env({0, 0, 0}, {0.2f, 0.2f, 0.2f}));
  scene.set_material(1, diffuse({1, 0, 0}));
  scene.set_material(2, diffuse({0, 1, 0}));
  add_object(scene, 100, quad({-1, -1, 0}, {2, 0, 0}, {0, 2, 0}), 1);
  add_object(scene, 200, quad({-4, -4, -1}, {8, 0, 0}, {0, 8, 0}), 2);
  Light sun = directional({1, 0, -1});  // its shadow falls one unit to +x on the back quad
  scene.set_light(1, sun);
  const Camera cam = look({0, 0, 5}, {0, 0, 0}, 60 * kDeg);
  scene.set_camera(cam);
  float fx, fy;
  project(cam, W, H, {1.5f, 0, -1}, fx, fy);  // beside the front quad, in its shadow
  const int x = int(std::lround(fx)), y = int(std::lround(fy));
  const int lit = int(std::lround(255 * (0.2f + std::sqrt(0.5f)))), dark = int(std::lround(255 * 0.2f));
  RayTracer rt;
  TaskResult casting, open;
  render_full(rt, scene, no_ao(), nullptr, &casting);
  CHECK(std::abs(px(casting.image, x, y).g - dark) <= 1);
  CHECK(casting.rays.shadow > 0);
  sun.cast_shadow = false;
  scene.set_light(1, sun);
  render_full(rt, scene, no_ao(), nullptr, &open);
  CHECK(std::abs(px(open.image, x, y).g - lit) <= 1);
  CHECK(open.rays.shadow == 0);
  // Everywhere else the two images agree: only shadows changed.
  int differ = 0;
  for (int32_t j = 0; j < H; ++j)
    for (int32_t i = 0; i < W; ++i) differ += px(open.image, i, j).g != px(casting.image, i, j).g && px(casting.image, i, j).g != dark;
  CHECK(differ == 0);
}

// A partly transparent surface (opacity < 1, no alpha mask) lets through 1 - opacity of the
// light a shadow ray carries (XML3D pages use opacity for glass panes and the like): a
// 50%-opaque pane casts a half shadow, two of them a quarter, an invisible one none. Refracting
// surfaces still cast none, and AO still counts such a pane as an occluder.
TEST_CASE("partly transparent surfaces cast shadows of matching transmission", "[raytracer][shadow]") {
  const int W = 101, H = 101;
  Scene scene;
  scene.set_resolution(W, H);
  scene.set_environment(plain_env({0, 0, 0}, {0.2f, 0.2f, 0.2f}));
  Material pane = diffuse({1, 0, 0});
  pane.opacity = 0.5f;
  scene.set_material(1, pane);
  scene.set_material(2, diffuse({0, 1, 0}));
  scene.set_material(3, pane);
  add_object(scene, 100, quad({-1, -1, 0}, {2, 0, 0}, {0, 2, 0}), 1);
  add_object(scene, 200, quad({-4, -4, -1}, {8, 0, 0}, {0, 8, 0}), 2);
  scene.set_light(1, directional({1, 0, -1}));  // the front pane's shadow falls one unit to +x
  const Camera cam = look({0, 0, 5}, {0, 0, 0}, 60 * kDeg);
  scene.set_camera(cam);
  // (1.5, 0, -1): the camera sees it directly (beside both panes); its shadow ray crosses the
  // front pane at x = 0.5 and the second pane (below) at x = 1.
  float fx, fy;
  project(cam, W, H, {1.5f, 0, -1}, fx, fy);
  const int x = int(std::lround(fx)), y = int(std::lround(fy));
  auto green = [&](float transmission) { return int(std::lround(255 * (0.2f + std::sqrt(0.5f) * transmission))); };
  RayTracer rt;
  auto probe = [&] {
    std::vector<std::string> warnings;
    Image img = render_full(rt, scene, no_ao(), &warnings);
    return px(img, x, y).g;
  };
  CHECK(std::abs(probe() - green(0.5f)) <= 1);
  // A second half-opaque pane on the shadow ray's way (out of the camera ray's): a quarter.
  add_object(scene, 300, quad({0.5f, -1, -0.5f}, {0.7f, 0, 0}, {0, 2, 0}), 3);
  CHECK(std::abs(probe() - green(0.25f)) <= 1);
  scene.remove_mesh(300);
  // Opacity 0.8: 20% through; an invisible pane: the full light; an opaque one: the ambient only.
  pane.opacity = 0.8f;
  scene.set_material(1, pane);
  CHECK(std::abs(probe() - green(0.2f)) <= 1);
  pane.opacity = 0;
  scene.set_material(1, pane);
  CHECK(std::abs(probe() - green(1)) <= 1);
  pane.opacity = 1;
  scene.set_material(1, pane);
  CHECK(std::abs(probe() - green(0)) <= 1);
  // Opacity 1, but a diffuse texture whose alpha is 64 of 255 and no alpha mask: shading makes
  // the pane that see-through, and its shadow lets 1 - 64/255 of the light through.
  Texture faint;
  faint.width = faint.height = 1;
  faint.rgba = {255, 255, 255, 64};
  scene.set_texture(1, faint);
  pane.diffuse_texture = 1;
  scene.set_material(1, pane);
  CHECK(std::abs(probe() - green(1 - 64 / 255.0f)) <= 1);
  // The same texture as an alpha mask (alpha below the cutoff): cut out, the full light.
  pane.alpha_mask = true;
  pane.alpha_cutoff = 0.5f;
  scene.set_material(1, pane);
  CHECK(std::abs(probe() - green(1)) <= 1);
  // An opaque texture: the full shadow.
  faint.rgba = {255, 255, 255, 255};
  scene.set_texture(1, faint);
  pane.alpha_mask = false;
  scene.set_material(1, pane);
  CHECK(std::abs(probe() - green(0)) <= 1);
  pane.diffuse_texture = kNoId;
  // A refracting pane casts none (as before).
  pane.opacity = 0.5f;
  pane.refraction = 0.5f;
  scene.set_material(1, pane);
  CHECK(std::abs(probe() - green(1)) <= 1);
}

// ---------------------------------------------------------------------------------------
// Refraction: Snell offset through a tilted slab, total internal reflection.
// ---------------------------------------------------------------------------------------
namespace {

// Snell refraction of unit d at a surface with unit normal n (any side), eta = n1 / n2.
bool refract_dir(Vec3 d, Vec3 n, float eta, Vec3& t) {
  if (dot(d, n) > 0) n = -n;
  float cosi = -dot(d, n);
  float k = 1 - eta * eta * (1 - cosi * cosi);
  if (k < 0) return false;
  t = normalize(d * eta + n * (eta * cosi - std::sqrt(k)));
  return true;
}

}  // namespace

TEST_CASE("a ray through a tilted glass slab leaves parallel to its entry, offset as Snell's law says", "[raytracer][refraction]") {
  const float ior = 1.5f, thickness = 1.0f, tilt = 30 * kDeg;
  const int W = 201, H = 11;
  Mat4 rot = Mat4::rotate({0, 1, 0}, tilt);
  Vec3 n = normalize(rot.transform_vector({0, 0, 1}));  // slab normal; faces at +-thickness/2 along n

  for (float target_z : {-5.0f, -30.0f}) {
    Scene scene;
    scene.set_resolution(W, H);
    scene.set_environment(plain_env({0, 0, 0}));
    Material glass;
    glass.diffuse_color = {0, 0, 0};
    glass.refraction = 1;
    glass.ior = ior;
    scene.set_material(1, glass);
    scene.set_material(2, matte({1, 1, 1}));
    add_object(scene, 100, box({-3, -20, -thickness / 2}, {3, 20, thickness / 2}), 1, rot);
    // A thin vertical stripe, 0.1 wide, centred on x = 0.
    add_object(scene, 200, quad({-0.05f, -10, target_z}, {0.1f, 0, 0}, {0, 20, 0}), 2);
    // 1/15 of the camera distance... the view spans x in [-1, 1] at z = -5.
    float tan_half_x = 1.0f / 15.0f;
    Camera cam = look({0, 0, 10}, {0, 0, 0}, 2 * std::atan(tan_half_x * H / W));
    scene.set_camera(cam);
    RayTracer rt;
    RenderSettings s = no_ao(4);
    Image img = render_full(rt, scene, s);
    REQUIRE(rt.features().secondary);

    // The analytic path of each pixel of the middle row: refract in, refract out, hit the target plane.
    const Vec3 eye = cam_pos(cam);
    auto hits_stripe = [&](float x, bool through_slab, Vec3* exit_dir, Vec3* entry_dir) {
      Vec3 d = pixel_dir(cam, W, H, x, float(H / 2));
      Vec3 o = eye;
      if (entry_dir) *entry_dir = d;
      if (through_slab) {
        // Front face: dot(p, n) = +thickness/2 (the camera is on the +n side).
        float t1 = (thickness / 2 - dot(o, n)) / dot(d, n);
        Vec3 p1 = o + d * t1, d1;
        REQUIRE(refract_dir(d, n, 1 / ior, d1));
        float t2 = (-thickness / 2 - dot(p1, n)) / dot(d1, n);
        Vec3 p2 = p1 + d1 * t2, d2;
        REQUIRE(refract_dir(d1, n, ior, d2));
        o = p2;
        d = d2;
      }
      if (exit_dir) *exit_dir = d;
      float t = (target_z - o.z) / d.z;
      float hx = o.x + d.x * t;
      return std::fabs(hx) <= 0.05f;
    };
    // Expected centroid of the stripe in the middle row, sampled at 1/16 pixel.
    double sum = 0, cnt = 0, sum_direct = 0, cnt_direct = 0;
    for (int i = 0; i < W * 16; ++i) {
      float x = (i + 0.5f) / 16.0f - 0.5f;
      if (hits_stripe(x, true, nullptr, nullptr)) { sum += x; cnt += 1; }
      if (hits_stripe(x, false, nullptr, nullptr)) { sum_direct += x; cnt_direct += 1; }
    }
    REQUIRE(cnt > 0);
    double expected = sum / cnt, direct = sum_direct / cnt_direct;
    // Parallel exit: the analytic exit direction equals the entry direction.
    Vec3 din, dout;
    hits_stripe(float(W / 2), true, &dout, &din);
    CHECK(length(dout - din) < 1e-5f);

    double wsum = 0, wcnt = 0;
    int peak = 0;
    for (int x = 0; x < W; ++x) {
      int v = px(img, x, H / 2).r;
      peak = std::max(peak, v);
      if (v > 20) { wsum += double(x) * v; wcnt += v; }
    }
    REQUIRE(wcnt > 0);
    double got = wsum / wcnt;
    INFO("target z " << target_z << ": stripe centroid " << got << " px, Snell predicts " << expected
                     << " px, without the slab " << direct << " px");
    // The slab shifts the stripe by many pixels; the renderer agrees to a quarter pixel.
    CHECK(std::fabs(expected - direct) > 5);
    CHECK(std::fabs(got - expected) < 0.25);
    // Two Fresnel transmissions at 30 degrees keep about 92% of the light.
    CHECK(peak > 200);
  }
}

TEST_CASE("total internal reflection past the critical angle shows the mirror image, not the outside", "[raytracer][refraction]") {
  // The camera sits inside a glass block (ior 1.5, critical angle 41.8 degrees) and looks
  // up at its top face. Outside, above: a red ceiling. Inside: a green wall, seen only by
  // rays reflected at the top face.
  const float ior = 1.5f;
  const float critical = std::asin(1 / ior) / kDeg;
  REQUIRE(critical == Approx(41.81f).margin(0.01f));
  Scene scene;
  const int W = 5, H = 5;
  scene.set_resolution(W, H);
  scene.set_environment(plain_env({0, 0, 0}));
  Material glass;
  glass.diffuse_color = {0, 0, 0};
  glass.refraction = 1;
  glass.ior = ior;
  scene.set_material(1, glass);
  scene.set_material(2, matte({1, 0, 0}));
  scene.set_material(3, matte({0, 1, 0}));
  add_object(scene, 100, box({-10, -1, -10}, {10, 1, 10}), 1);
  add_object(scene, 200, quad({-20, 3, -20}, {40, 0, 0}, {0, 0, 40}), 2);
  add_object(scene, 300, quad({-5, -1, -4.5f}, {10, 0, 0}, {0, 2, 0}), 3);
  for (float incidence : {20.0f, 38.0f, 44.0f, 70.0f}) {
    float e = (90 - incidence) * kDeg;  // elevation of the view direction
    scene.set_camera(look({0, 0, 0}, {0, std::sin(e), -std::cos(e)}, 1 * kDeg));
    RayTracer rt;
    Image img = render_full(rt, scene, no_ao(8));
    Rgb p = px(img, W / 2, H / 2);
    INFO("incidence " << incidence << " deg inside the glass: " << str(p));
    if (incidence > critical) {
      CHECK(p.r <= 2);     // nothing gets out
      CHECK(p.g >= 253);   // all of it is reflected (Fresnel = 1)
    } else {
      // Fresnel transmission from inside: ~0.95 at 20 degrees, ~0.86 at 38 degrees.
      CHECK(p.r >= 200);
      CHECK(p.g <= 40);
    }
  }
}

// ---------------------------------------------------------------------------------------
// Ambient occlusion
// ---------------------------------------------------------------------------------------
TEST_CASE("ambient occlusion is 1 on an open plane and 0 inside a closed box", "[raytracer][ao]") {
  RenderSettings s = no_ao();
  s.ao_samples = 8;
  s.ao_distance = 1;
  {
    Scene scene;
    scene.set_resolution(48, 32);
    scene.set_environment(plain_env({0, 0, 0}, {1, 1, 1}));
    scene.set_material(1, diffuse({1, 1, 1}));
    add_object(scene, 100, quad({-100, 0, 100}, {200, 0, 0}, {0, 0, -200}), 1);
    scene.set_camera(look({0, 3, 3}, {0, 0, 0}, 40 * kDeg));
    RayTracer rt;
    TaskResult r;
    Image img = render_full(rt, scene, s, nullptr, &r);
    CHECK(r.rays.ao == uint64_t(48 * 32 * 8));
    int lo = 255;
    for (int y = 0; y < 32; ++y)
      for (int x = 0; x < 48; ++x) lo = std::min({lo, px(img, x, y).r, px(img, x, y).g, px(img, x, y).b});
    CHECK(lo >= 254);
  }
  {
    Scene scene;
    scene.set_resolution(48, 32);
    scene.set_environment(plain_env({1, 1, 1}, {1, 1, 1}));
    scene.set_material(1, diffuse({1, 1, 1}));
    add_object(scene, 100, box({-1, -1, -1}, {1, 1, 1}), 1);
    scene.set_camera(look({0, 0, 0}, {0.3f, 0.2f, -1}, 90 * kDeg));
    s.ao_distance = 10;
    RayTracer rt;
    Image img = render_full(rt, scene, s);
    int hi = 0;
    for (int y = 0; y < 32; ++y)
      for (int x = 0; x < 48; ++x) hi = std::max({hi, px(img, x, y).r, px(img, x, y).g, px(img, x, y).b});
    CHECK(hi <= 1);
  }
}

// ---------------------------------------------------------------------------------------
// Tasks: cost maps, sub-rectangles, packet layouts
// ---------------------------------------------------------------------------------------
namespace {

// A scene that exercises every path: lights, shadows, AO, reflection, refraction, textures, masks.
Scene busy_scene(int W, int H) {
  Scene scene;
  scene.set_resolution(W, H);
  scene.set_environment(plain_env({0.2f, 0.3f, 0.5f}, {0.3f, 0.3f, 0.3f}));
  Material white = diffuse({0.8f, 0.8f, 0.8f});
  white.model = Material::Model::phong;
  white.specular_color = {0.5f, 0.5f, 0.5f};
  scene.set_material(1, white);
  Material mirror = diffuse({0.1f, 0.1f, 0.1f});
  mirror.reflection = 0.8f;
  scene.set_material(2, mirror);
  Material glass;
  glass.diffuse_color = {0, 0, 0};
  glass.refraction = 0.9f;
  glass.ior = 1.5f;
  scene.set_material(3, glass);
  Texture tex;
  tex.width = tex.height = 4;
  for (int i = 0; i < 16; ++i) {
    uint8_t a = (i % 3) ? 255 : 0;
    tex.rgba.insert(tex.rgba.end(), {uint8_t(40 * (i % 4) + 60), uint8_t(16 * i), uint8_t(200 - 10 * i), a});
  }
  scene.set_texture(1, tex);
  Material leaf = diffuse({1, 1, 1});
  leaf.diffuse_texture = 1;
  leaf.alpha_mask = true;
  scene.set_material(4, leaf);
  // The floor: a 128x128 texture over 10 x 10 units, minified towards the back (trilinear over
  // its mip levels, packets whose lanes span several levels included) and seen in the mirror.
  Texture fine;
  fine.width = fine.height = 128;
  for (int y = 0; y < 128; ++y)
    for (int x = 0; x < 128; ++x)
      fine.rgba.insert(fine.rgba.end(), {uint8_t(((x ^ y) & 1) ? 230 : 40), uint8_t(2 * x), uint8_t(2 * y), 255});
  scene.set_texture(2, fine);
  white.diffuse_texture = 2;
  scene.set_material(1, white);
  add_object(scene, 100, quad({-5, -1, 5}, {10, 0, 0}, {0, 0, -10}), 1);
  add_object(scene, 200, sphere(0.7f, 32), 2, Mat4::translate({-1, -0.3f, 0}));
  add_object(scene, 300, sphere(0.6f, 32), 3, Mat4::translate({0.8f, -0.4f, 0.8f}));
  add_object(scene, 400, quad({-1, -1, -1.5f}, {2.5f, 0, 0}, {0, 2.5f, 0}), 4);
  scene.set_light(1, directional({0.4f, -1, -0.3f}, 0.8f));
  Light pl;
  pl.type = Light::Type::point;
  pl.position = {1, 2, 2};
  pl.intensity = 3;
  scene.set_light(2, pl);
  scene.set_camera(look({0.5f, 1.2f, 4}, {0, -0.3f, 0}, 50 * kDeg));
  return scene;
}

RenderSettings busy_settings() {
  RenderSettings s;
  s.ao_samples = 4;
  s.ao_distance = 2;
  s.max_depth = 4;
  s.frame = 3;
  return s;
}

}  // namespace

TEST_CASE("the cost map covers exactly the task's packets and sums to the kernel time", "[raytracer][cost]") {
  const int W = 61, H = 37;  // not multiples of any packet size
  Scene scene = busy_scene(W, H);
  for (PacketLayout layout : {PacketLayout{2, 2}, PacketLayout{4, 2}, PacketLayout{4, 4}}) {
    RayTracer rt(layout);
    std::vector<std::string> warnings;
    rt.sync(scene, warnings);
    REQUIRE(warnings.empty());
    REQUIRE(rt.packet_layout().w == layout.w);
    REQUIRE(rt.packet_layout().h == layout.h);
    const Rect tasks[] = {{0, 0, W, H}, {3, 5, 37, 29}, {8, 8, 16, 16}, {50, 30, 200, 200}, {60, 36, 61, 37}};
    for (const Rect& task : tasks) {
      TaskResult r;
      rt.render(task, busy_settings(), r);
      Rect px_rect = intersect(task, {0, 0, W, H});
      INFO("layout " << layout.w << "x" << layout.h << " task " << task.x0 << "," << task.y0 << "," << task.x1 << "," << task.y1);
      CHECK(r.pixels == px_rect);
      CHECK(r.image.width == px_rect.width());
      CHECK(r.image.height == px_rect.height());
      // The packets whose footprint meets the task, and no others.
      Rect want{px_rect.x0 / layout.w, px_rect.y0 / layout.h, (px_rect.x1 + layout.w - 1) / layout.w,
                (px_rect.y1 + layout.h - 1) / layout.h};
      CHECK(r.cost.packets == want);
      CHECK(r.cost.cost.size() == size_t(want.area()));
      CHECK(packet_space(W, H, layout).contains(r.cost.packets));
      for (uint32_t c : r.cost.cost) CHECK(c > 0);  // every packet did work
      // kernel_ms is the sum of the cost map in ms (cost unit: ns at the nominal TSC rate).
      CHECK(r.kernel_ms == double(r.cost.total()) * 1e-6);
      CHECK(r.kernel_ms > 0);
      CHECK(r.rays.primary == uint64_t(px_rect.area()));
    }
    // Without a cost map: no entries and no kernel time.
    RenderSettings s = busy_settings();
    s.cost_map = false;
    TaskResult r;
    rt.render({0, 0, W, H}, s, r);
    CHECK(r.cost.cost.empty());
    CHECK(r.kernel_ms == 0);
  }
}

// The bench's split of the kernel time (tessera bench --compare bare, bench::
// render_timing_intersections): the time inside Embree's primary-ray intersections is part of
// the packets' time, and the bare loop times its own calls the same way.
TEST_CASE("an abandoned task stops early: at once when its frame is cancelled before it starts, mid-render when the "
          "mark rises during it, and not at all for a mark below its frame", "[raytracer][cancel]") {
  const int W = 96, H = 64;
  Scene scene = busy_scene(W, H);
  RayTracer rt(PacketLayout{4, 2});
  std::vector<std::string> warnings;
  rt.sync(scene, warnings);
  REQUIRE(warnings.empty());
  RenderSettings s = busy_settings();
  s.radiance = true;
  TaskResult full;
  rt.render({0, 0, W, H}, s, full);
  REQUIRE_FALSE(full.cancelled);
  REQUIRE(full.rays.total() > 0);

  std::atomic<uint32_t> mark{6};
  s.cancel_through = &mark;
  s.cancel_frame = 7;  // a later frame: not abandoned, the same bytes
  TaskResult later;
  rt.render({0, 0, W, H}, s, later);
  CHECK_FALSE(later.cancelled);
  CHECK(later.image.rgba == full.image.rgba);
  CHECK(later.radiance == full.radiance);
  CHECK(later.rays.total() == full.rays.total());

  s.cancel_frame = 6;  // abandoned before it began: no ray at all
  TaskResult before;
  rt.render({0, 0, W, H}, s, before);
  CHECK(before.cancelled);
  CHECK(before.rays.total() == 0);
  CHECK(before.pixels == full.pixels);  // the task's size, as a complete one
  CHECK(before.radiance.size() == full.radiance.size());

  // Raised while packet (0, 0) stalls (the test hook) on one thread, which renders that block
  // first: the packets after it are skipped.
  mark = 0;
  s.stall_us = 1500000;
  s.stall_px = s.stall_py = 0;
  TaskResult during;
  std::thread raise([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    mark = 6;
  });
  tbb::task_arena one(1);
  one.execute([&] { rt.render({0, 0, W, H}, s, during); });
  raise.join();
  CHECK(during.cancelled);
  CHECK(during.rays.total() > 0);
  CHECK(during.rays.total() < full.rays.total() / 2);
}

TEST_CASE("timed primary intersections are a part of the kernel time, in render() and in the bare loop",
          "[raytracer][cost]") {
  const int W = 61, H = 37;
  Scene scene = busy_scene(W, H);
  for (PacketLayout layout : {PacketLayout{2, 2}, PacketLayout{4, 4}}) {
    RayTracer rt(layout);
    std::vector<std::string> warnings;
    rt.sync(scene, warnings);
    TaskResult timed, plain;
    // Raw timings on both sides: with the disturbance check on, a packet preempted inside an
    // intersection keeps its stall in isect_ms but has its cost replaced in kernel_ms (seen in
    // a loaded test run: 21.5 ms of intersections in a 5.1 ms kernel).
    RenderSettings settings = busy_settings();
    settings.disturbance_check = false;
    const double isect_ms = bench::render_timing_intersections(rt, {0, 0, W, H}, settings, timed);
    rt.render({0, 0, W, H}, settings, plain);
    INFO("layout " << layout.w << "x" << layout.h << ": intersections " << isect_ms << " ms of " << timed.kernel_ms
                   << " ms");
    CHECK(isect_ms > 0);
    CHECK(isect_ms < timed.kernel_ms);            // busy_scene shades, shadows and reflects too
    CHECK(timed.image.rgba == plain.image.rgba);  // timing changes nothing else
    CHECK(timed.rays.total() == plain.rays.total());
    uint64_t rays = 0;
    double bare_isect = 0;
    bench::trace_primary_only(rt, {0, 0, W, H}, &rays, &bare_isect);
    CHECK(rays == uint64_t(W * H));
    CHECK(bare_isect > 0);
  }
}

TEST_CASE("a sub-rectangle renders exactly the same pixels as the full image", "[raytracer][tasks]") {
  const int W = 61, H = 37;
  Scene scene = busy_scene(W, H);
  RayTracer rt;
  TaskResult full;
  std::vector<std::string> warnings;
  rt.sync(scene, warnings);
  rt.render({0, 0, W, H}, busy_settings(), full);
  const Rect tasks[] = {{0, 0, 16, 16}, {16, 0, 61, 16}, {3, 5, 37, 29}, {1, 1, 2, 2}, {30, 20, 61, 37}, {0, 36, 61, 37}, {7, 0, 8, 37}};
  for (const Rect& t : tasks) {
    TaskResult r;
    rt.render(t, busy_settings(), r);
    REQUIRE(r.image.width == t.width());
    REQUIRE(r.image.height == t.height());
    int diff = 0;
    for (int y = t.y0; y < t.y1; ++y)
      for (int x = t.x0; x < t.x1; ++x)
        if (std::memcmp(r.image.pixel(x - t.x0, y - t.y0), full.image.pixel(x, y), 4) != 0) ++diff;
    INFO("task " << t.x0 << "," << t.y0 << "," << t.x1 << "," << t.y1);
    CHECK(diff == 0);
  }
  // Tiling the frame with unaligned tasks reassembles the full image byte for byte.
  Image tiled(W, H);
  for (int y = 0; y < H; y += 7)
    for (int x = 0; x < W; x += 13) {
      TaskResult r;
      rt.render({x, y, x + 13, y + 7}, busy_settings(), r);
      blit(tiled, r.image, r.pixels.x0, r.pixels.y0);
    }
  CHECK(tiled.rgba == full.image.rgba);
}

TEST_CASE("textures with inconsistent or oversized dimensions are ignored with a warning", "[raytracer][textures]") {
  const int W = 32, H = 24;
  for (auto [w, h, texels] : {std::tuple<int32_t, int32_t, size_t>{4, 4, 15}, {1 << 16, 1 << 15, 0}, {0, 4, 0}, {-4, 4, 16}})
  for (bool linear : {false, true}) {  // linear: sRGB textures are decoded when synced
    Scene scene = busy_scene(W, H);
    Environment env = scene.environment();
    env.linear = linear;
    scene.set_environment(env);
    Texture bad;
    bad.width = w;
    bad.height = h;
    bad.rgba.assign(texels * 4, 200);
    scene.set_texture(1, bad);  // the alpha-masked leaf's texture
    RayTracer rt;
    std::vector<std::string> warnings;
    rt.sync(scene, warnings);
    INFO("texture " << w << "x" << h << " with " << texels << " texels, linear " << linear);
    REQUIRE(warnings.size() == 1);
    CHECK(warnings[0].find("texture 1") != std::string::npos);
    CHECK(rt.features().alpha_masks);  // the mask filter stays; it finds no texture to sample
    rt.sync(scene, warnings);
    CHECK(warnings.size() == 1);  // an unchanged bad texture is not reported again
    TaskResult r;
    rt.render({0, 0, W, H}, busy_settings(), r);
    CHECK(r.image.width == W);
  }
}

// Each layout runs its own copy of the kernel where the CPU has the instruction set (2x2:
// SSE2, 4x2: AVX2, 4x4: AVX-512), with vector loops for packets that hit one instance and
// lane-by-lane code for mixed ones: all of them must agree to the byte.
TEST_CASE("packet layouts 2x2, 4x2 and 4x4 give identical images", "[raytracer][packets]") {
  const int W = 61, H = 37;
  Scene scene = busy_scene(W, H);
  std::vector<Image> images;
  for (PacketLayout layout : {PacketLayout{2, 2}, PacketLayout{4, 2}, PacketLayout{4, 4}}) {
    RayTracer rt(layout);
    images.push_back(render_full(rt, scene, busy_settings()));
  }
  for (size_t i = 1; i < images.size(); ++i) {
    int diff = 0;
    for (size_t k = 0; k < images[0].rgba.size(); ++k) diff += images[i].rgba[k] != images[0].rgba[k];
    INFO("layout " << i << " differs from 2x2 in " << diff << " bytes");
    CHECK(diff == 0);
  }
  // The floor's texture is minified: its mip levels change the image (so the layouts above
  // agreed on trilinear lookups, not only on level 0).
  {
    RayTracer rt;
    RenderSettings level0 = busy_settings();
    level0.mip_levels = false;
    const Image flat = render_full(rt, scene, level0);
    int diff = 0;
    for (size_t k = 0; k < flat.rgba.size(); ++k) diff += flat.rgba[k] != images[0].rgba[k];
    INFO("level 0 alone differs from trilinear in " << diff << " bytes");
    CHECK(diff > 200);
  }
  CHECK_THROWS_AS(RayTracer(PacketLayout{3, 3}), std::invalid_argument);
}

// ---------------------------------------------------------------------------------------
// Incremental sync
// ---------------------------------------------------------------------------------------
TEST_CASE("incremental sync: late materials, hidden and removed meshes, changed shared buffers", "[raytracer][sync]") {
  Scene scene;
  const int W = 80, H = 40;
  scene.set_resolution(W, H);
  scene.set_environment(plain_env({0, 0, 0}));
  Mesh base = add_geometry(scene, 100, quad({-0.5f, -0.5f, 0}, {1, 0, 0}, {0, 1, 0}));
  Mesh a = base, b = base;
  a.transform = Mat4::translate({-2, 0, 0});
  a.material = 5;  // not there yet: the default material (matte red) until it arrives
  b.transform = Mat4::translate({2, 0, 0});
  b.material = 6;
  scene.set_material(6, matte({0, 0, 1}));
  scene.set_mesh(10, a);
  scene.set_mesh(20, b);
  scene.set_camera(look({0, 0, 10}, {0, 0, 0}, 2 * std::atan(0.25f)));
  RayTracer rt;
  std::vector<std::string> warnings;
  Image img = render_full(rt, scene, no_ao(), &warnings);
  CHECK(warnings.empty());
  // Quad A covers pixels [20, 28) x [16, 24), quad B [52, 60) x [16, 24) (8 px per unit).
  CHECK(px(img, 24, 20).r == 255);
  CHECK(px(img, 24, 20).b == 0);
  CHECK(px(img, 56, 20).b == 255);

  // The material arrives: no geometry work, the colour changes.
  scene.set_material(5, matte({0, 1, 0}));
  img = render_full(rt, scene, no_ao(), &warnings);
  CHECK(rt.last_sync().geometries_built == 0);
  CHECK(px(img, 24, 20).g == 255);
  CHECK(px(img, 24, 20).r == 0);

  // Hiding B removes its instance; showing it again restores it.
  b.visible = false;
  scene.set_mesh(20, b);
  img = render_full(rt, scene, no_ao(), &warnings);
  CHECK(rt.last_sync().instances_removed == 1);
  CHECK(px(img, 56, 20).b == 0);
  b.visible = true;
  scene.set_mesh(20, b);
  img = render_full(rt, scene, no_ao(), &warnings);
  CHECK(rt.last_sync().instances_updated == 1);
  CHECK(px(img, 56, 20).b == 255);

  // Changing the shared positions rebuilds one BLAS and updates both instances: the quad
  // doubles in size (now [-1, 1]^2 around each centre: pixels [16, 32) and [48, 64)).
  Buffer pos = *scene.buffer(100);
  for (float& v : pos.f) v *= 2;
  scene.set_buffer(100, pos);
  img = render_full(rt, scene, no_ao(), &warnings);
  CHECK(rt.last_sync().geometries_built == 1);
  CHECK(rt.last_sync().instances_updated == 2);
  CHECK(px(img, 17, 13).g == 255);
  CHECK(px(img, 62, 26).b == 255);
  CHECK(px(img, 40, 20).r + px(img, 40, 20).g + px(img, 40, 20).b == 0);

  // Removing the index buffer makes both meshes invalid: warned about, not drawn.
  scene.remove_buffer(103);
  img = render_full(rt, scene, no_ao(), &warnings);
  CHECK(warnings.size() == 2);
  CHECK(rt.last_sync().instances_removed == 2);
  for (size_t i = 0; i < img.rgba.size(); i += 4) REQUIRE(img.rgba[i] + img.rgba[i + 1] + img.rgba[i + 2] == 0);

  // Removing a mesh.
  Buffer idx;
  idx.type = Buffer::Type::u32;
  idx.u = {0, 1, 2, 0, 2, 3};
  scene.set_buffer(103, idx);
  scene.remove_mesh(10);
  img = render_full(rt, scene, no_ao(), &warnings);
  CHECK(warnings.empty());
  CHECK(px(img, 24, 20).g == 0);
  CHECK(px(img, 56, 20).b == 255);
}

TEST_CASE("opacity below 1 is see-through along the straight ray", "[raytracer][opacity]") {
  Scene scene;
  scene.set_resolution(21, 21);
  scene.set_environment(plain_env({0, 0, 1}));
  Material glassy = matte({1, 1, 1});
  glassy.opacity = 0.5f;
  scene.set_material(1, glassy);
  scene.set_material(2, matte({0, 1, 0}));
  add_object(scene, 100, quad({-1, -1, 0}, {2, 0, 0}, {0, 2, 0}), 1);          // half-transparent white
  add_object(scene, 200, quad({0, -1, -1}, {2, 0, 0}, {0, 2, 0}), 2);          // green behind, right half
  scene.set_camera(look({0, 0, 5}, {0, 0, 0}, 20 * kDeg));
  RayTracer rt;
  Image img = render_full(rt, scene, no_ao(4));
  CHECK(rt.features().secondary);
  Rgb left = px(img, 6, 10), right = px(img, 14, 10);
  INFO("left " << str(left) << " right " << str(right));
  // 0.5 white + 0.5 of what is behind: the blue background, or the green quad.
  CHECK(std::abs(left.r - 128) <= 1);
  CHECK(std::abs(left.g - 128) <= 1);
  CHECK(std::abs(left.b - 255) <= 1);
  CHECK(std::abs(right.r - 128) <= 1);
  CHECK(std::abs(right.g - 255) <= 1);
  CHECK(std::abs(right.b - 128) <= 1);
  // With max_depth 1 (primary rays only) the see-through share shows the background.
  Image flat = render_full(rt, scene, no_ao(1));
  CHECK(std::abs(px(flat, 14, 10).g - 128) <= 1);
}

// The thread-level schedules of bench::render_scheduled (tessera threadbench) render exactly
// what render() renders, time every packet, and refuse static tiles that do not cover the task.
TEST_CASE("render_scheduled: every schedule gives render()'s image and a full cost map", "[raytracer][schedule]") {
  using bench::ThreadSchedule;
  const int W = 61, H = 37;
  Scene scene = busy_scene(W, H);
  RayTracer rt;
  std::vector<std::string> warnings;
  rt.sync(scene, warnings);
  const PacketLayout pl = rt.packet_layout();
  const Rect space = packet_space(W, H, pl);
  const Rect tasks[] = {{0, 0, W, H}, {3, 5, 37, 29}};
  for (const Rect& task : tasks) {
    TaskResult ref;
    rt.render(task, busy_settings(), ref);
    // Uneven static tiles over the whole packet space (clipped to the task), one of them empty.
    const int mx = space.x1 / 3, my = space.y1 / 2;
    const std::vector<Rect> tiles = {{0, 0, mx, space.y1}, {mx, 0, space.x1, my}, {mx, my, space.x1, space.y1}, {}};
    struct Case { ThreadSchedule s; int threads; };
    for (Case c : {Case{ThreadSchedule::work_stealing, 0}, Case{ThreadSchedule::static_tiles, 0},
                   Case{ThreadSchedule::shared_queue, 1}, Case{ThreadSchedule::shared_queue, 3}}) {
      INFO(bench::schedule_name(c.s) << ", " << c.threads << " threads, task " << task.x0 << "," << task.y0);
      TaskResult r;
      bench::render_scheduled(rt, task, busy_settings(), c.s, tiles, c.threads, r);
      CHECK(r.pixels == ref.pixels);
      CHECK(r.image.rgba == ref.image.rgba);
      CHECK(r.cost.packets == ref.cost.packets);
      REQUIRE(r.cost.cost.size() == ref.cost.cost.size());
      for (uint32_t v : r.cost.cost) CHECK(v > 0);  // every packet rendered and timed once
      CHECK(r.rays.primary == ref.rays.primary);
      CHECK(r.rays.total() == ref.rays.total());
      CHECK(r.kernel_ms > 0);
    }
  }
  TaskResult r;
  const Rect full{0, 0, W, H};
  CHECK_THROWS_AS(bench::render_scheduled(rt, full, busy_settings(), ThreadSchedule::static_tiles,
                                          {{0, 0, space.x1, space.y1 - 1}}, 0, r), std::invalid_argument);  // a row missing
  CHECK_THROWS_AS(bench::render_scheduled(rt, full, busy_settings(), ThreadSchedule::static_tiles,
                                          {{0, 0, space.x1, space.y1}, {0, 0, 1, 1}}, 0, r), std::invalid_argument);  // overlap
  CHECK_THROWS_AS(bench::render_scheduled(rt, full, busy_settings(), ThreadSchedule::static_tiles, {}, 0, r),
                  std::invalid_argument);
  CHECK_THROWS_AS(bench::render_scheduled(rt, full, busy_settings(), ThreadSchedule::shared_queue, {}, 0, r),
                  std::invalid_argument);
}

TEST_CASE("a scene without AO, secondary rays and textures runs the kernel with them compiled out, with the same bytes",
          "[raytracer][features]") {
  Scene scene;
  const int W = 48, H = 32;
  scene.set_resolution(W, H);
  scene.set_environment(plain_env({0.1f, 0.2f, 0.3f}, {0.2f, 0.2f, 0.2f}));
  scene.set_material(1, diffuse({0.8f, 0.6f, 0.4f}));
  add_object(scene, 100, sphere(1.0f, 32), 1);
  add_object(scene, 200, quad({-5, -1, 5}, {10, 0, 0}, {0, 0, -10}), 1);
  scene.set_light(1, directional({0, -1, -1}));
  scene.set_camera(look({0, 1, 5}, {0, 0, 0}, 40 * kDeg));
  const Rect all{0, 0, W, H};

  RayTracer rt;
  Image img = render_full(rt, scene, no_ao());
  REQUIRE(rt.plain_kernel(no_ao()));
  TaskResult general, specialised;
  bench::render_general(rt, all, no_ao(), general);
  bench::render_specialised(rt, all, no_ao(), specialised);
  CHECK(general.image.rgba == img.rgba);
  CHECK(specialised.image.rgba == img.rgba);
  CHECK(general.rays.primary == specialised.rays.primary);
  CHECK(general.rays.shadow == specialised.rays.shadow);

  // AO asked for, a reflecting material or a texture: the general kernel, and the specialised
  // one refuses the scene.
  RenderSettings ao = no_ao();
  ao.ao_samples = 4;
  CHECK_FALSE(rt.plain_kernel(ao));
  CHECK_THROWS_AS(bench::render_specialised(rt, all, ao, specialised), std::invalid_argument);
  Material mirror = diffuse({0.8f, 0.6f, 0.4f});
  mirror.reflection = 0.5f;
  scene.set_material(1, mirror);
  render_full(rt, scene, no_ao());
  CHECK_FALSE(rt.plain_kernel(no_ao()));
  CHECK_THROWS_AS(bench::render_specialised(rt, all, no_ao(), specialised), std::invalid_argument);
}

TEST_CASE("a spot light lights its cone on a plane: a hard edge at the cutoff, a smoothstep over the soft edge",
          "[raytracer][lights]") {
  // A white diffuse plane y = 0 seen from straight above, a spot light 2 units over its centre
  // pointing down, constant attenuation: a pixel's value is 255 (N.L) (L.axis) times the
  // edge factor, all computed here from the plane point the pixel's ray hits.
  Scene scene;
  const int W = 64, H = 64;
  scene.set_resolution(W, H);
  scene.set_environment(plain_env());
  scene.set_material(1, diffuse({1, 1, 1}));
  add_object(scene, 100, quad({-5, 0, 5}, {10, 0, 0}, {0, 0, -10}), 1);
  const Camera cam = look({0, 4, 0}, {0, 0, 0}, 60 * kDeg, {0, 0, -1});
  scene.set_camera(cam);
  const Vec3 light_pos{0, 2, 0};
  const float cutoff = 30 * kDeg;
  for (float softness : {0.0f, 0.5f}) {
    Light spot;
    spot.type = Light::Type::spot;
    spot.position = light_pos;
    spot.direction = {0, -1, 0};
    spot.attenuation = {1, 0, 0};
    spot.cutoff = cutoff;
    spot.softness = softness;
    scene.set_light(1, spot);
    RayTracer rt;
    const Image img = render_full(rt, scene, no_ao());
    const float cos_outer = std::cos(cutoff), cos_inner = std::cos(cutoff * (1 - softness));
    int lit = 0, dark = 0, partial = 0, bad = 0;
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const Vec3 d = pixel_dir(cam, W, H, float(x), float(y));
        const Vec3 eye = cam_pos(cam), p = eye + d * (-eye.y / d.y);
        const Vec3 l = normalize(light_pos - p);
        const float c = l.y;  // cosine to the spot's axis; also N.L on the plane
        float edge;
        if (softness == 0) {
          edge = c >= cos_outer ? 1.0f : 0.0f;
          if (std::fabs(c - cos_outer) < 2e-3f) continue;  // a pixel on the edge itself
        } else {
          const float t = std::fmin(std::fmax((c - cos_outer) / (cos_inner - cos_outer), 0.0f), 1.0f);
          edge = t * t * (3 - 2 * t);
        }
        const int expect = int(std::lround(255 * c * edge));
        const Rgb got = px(img, x, y);
        if (std::abs(got.r - expect) > 2 || got.g != got.r || got.b != got.r) {
          if (bad < 6) WARN("px " << x << "," << y << " got " << str(got) << " expected " << expect << " c " << c);
          ++bad;
        }
        (expect == 0 ? dark : expect >= int(std::lround(255 * c)) ? lit : partial)++;
      }
    INFO("softness " << softness << ": " << lit << " fully lit, " << partial << " on the soft edge, " << dark
                     << " dark, " << bad << " off the prediction by more than 2");
    CHECK(bad == 0);
    CHECK(lit > 100);
    CHECK(dark > 1000);
    if (softness == 0) CHECK(partial == 0);
    else CHECK(partial > 100);
  }
}

// ineffective_settings says AO changes nothing where it really does not: on a scene without
// sky or ambient light the render with AO rays is the render without them, and no AO ray is
// traced; with a sky, AO shows and nothing is said.
TEST_CASE("AO on a scene without sky or ambient light is reported as changing nothing, and it does not", "[raytracer][settings]") {
  Scene scene;
  scene.set_resolution(32, 32);
  scene.set_environment(plain_env({0, 0, 1}));
  scene.set_material(1, diffuse({1, 1, 1}));
  add_object(scene, 100, sphere(1.0f, 32), 1);
  add_object(scene, 200, quad({-10, -1, 0.5f}, {20, 0, 0}, {0, 0, -20.5f}), 1);
  scene.set_light(1, directional({0, -1, -1}));
  scene.set_camera(look({0, 0, 5}, {0, 0, 0}, 30 * kDeg));
  CHECK(ineffective_settings(scene, 0, false).empty());
  auto said = ineffective_settings(scene, 4, false);
  REQUIRE(said.size() == 1);
  CHECK(said[0].find("no sky or ambient light") != std::string::npos);
  CHECK(ineffective_settings(scene, 4, true).size() == 1);  // the rasterizer: never any AO

  RayTracer rt;
  RenderSettings with_ao = no_ao();
  with_ao.ao_samples = 4;
  TaskResult a, b;
  std::vector<std::string> w;
  rt.sync(scene, w);
  rt.render({0, 0, 32, 32}, no_ao(), a);
  rt.render({0, 0, 32, 32}, with_ao, b);
  CHECK(b.rays.ao == 0);
  CHECK(a.image.rgba == b.image.rgba);

  scene.set_environment(plain_env({0, 0, 1}, {0.5f, 0.5f, 0.5f}));
  CHECK(ineffective_settings(scene, 4, false).empty());
  TaskResult c;
  rt.sync(scene, w);
  rt.render({0, 0, 32, 32}, with_ao, c);
  CHECK(c.rays.ao > 0);
}

// Adaptive refinement (RenderSettings::block_samples, renderer/adaptive.h): each packet renders
// the sample the plan gives its 4x4 block, exactly as a whole render of that sample would, and a
// skipped packet traces nothing and leaves zeros; whatever the packet layout.
TEST_CASE("a plan of blocks renders each packet's own sample as a whole render of it would and skips the others",
          "[raytracer][adaptive]") {
  const int W = 61, H = 37;  // not multiples of the packet: the last packets are partial
  Scene scene = busy_scene(W, H);
  const Rect blocks = plan_blocks_of({0, 0, W, H});
  REQUIRE(blocks == Rect{0, 0, 16, 10});
  // A plan that mixes samples 0, 1 and 5 and skips every fourth block.
  std::vector<uint32_t> plan(size_t(blocks.area()));
  for (size_t i = 0; i < plan.size(); ++i) plan[i] = i % 4 == 3 ? kSkipPacket : std::array<uint32_t, 3>{0, 1, 5}[i % 3];
  auto planned = [&](int x, int y) { return plan[size_t(y / kPlanBlock) * size_t(blocks.width()) + size_t(x / kPlanBlock)]; };
  for (PacketLayout layout : {PacketLayout{4, 4}, PacketLayout{4, 2}, PacketLayout{2, 2}}) {
    CAPTURE(layout.w, layout.h);
    RayTracer rt(layout);
    std::vector<std::string> warnings;
    rt.sync(scene, warnings);
    RenderSettings s = busy_settings();
    s.radiance = true;
    s.guides = true;
    std::map<uint32_t, TaskResult> whole;  // whole renders of samples 0, 1 and 5
    for (uint32_t k : {0u, 1u, 5u}) {
      s.sample = k;
      rt.render({0, 0, W, H}, s, whole[k]);
    }
    s.sample = 9;  // overridden by the plan everywhere
    // The whole image's plan, and a task's own part of it (the blocks its pixels touch, one
    // block less on the right: those packets are outside the plan, so skipped).
    const Rect task{9, 5, 45, 33};
    const Rect part{task.x0 / 4, task.y0 / 4, (task.x1 + 3) / 4 - 1, (task.y1 + 3) / 4};
    std::vector<uint32_t> cropped;
    for (int by = part.y0; by < part.y1; ++by)
      for (int bx = part.x0; bx < part.x1; ++bx) cropped.push_back(plan[size_t(by) * size_t(blocks.width()) + size_t(bx)]);
    for (const auto& [pixels, rect, values] : {std::tuple{Rect{0, 0, W, H}, blocks, &plan}, std::tuple{task, part, &cropped}}) {
      CAPTURE(pixels.x0, pixels.y0);
      s.block_samples = values->data();
      s.plan_blocks = rect;
      TaskResult r;
      rt.render(pixels, s, r);
      uint64_t primary = 0;
      for (int y = pixels.y0; y < pixels.y1; ++y)
        for (int x = pixels.x0; x < pixels.x1; ++x) {
          // A packet renders its block's sample: its first pixel's block (a packet lies in one block).
          const int px0 = x / layout.w * layout.w, py0 = y / layout.h * layout.h;
          const bool inside = rect.contains(px0 / kPlanBlock, py0 / kPlanBlock);
          const uint32_t k = inside ? planned(px0, py0) : kSkipPacket;
          const size_t at = size_t(y - pixels.y0) * size_t(pixels.width()) + size_t(x - pixels.x0);
          const size_t full = size_t(y) * size_t(W) + size_t(x);
          if (k == kSkipPacket) {
            CHECK(std::memcmp(r.image.pixel(x - pixels.x0, y - pixels.y0), "\0\0\0\0", 4) == 0);
            CHECK(r.radiance[at * 3] == 0.0f);
            CHECK(r.guides[at * kGuideFloats + 3] == -1.0f);  // what a task's untouched pixel holds
            continue;
          }
          ++primary;
          const TaskResult& w = whole.at(k);
          CHECK(std::memcmp(r.image.pixel(x - pixels.x0, y - pixels.y0), w.image.pixel(x, y), 4) == 0);
          for (int c = 0; c < 3; ++c) CHECK(r.radiance[at * 3 + size_t(c)] == w.radiance[full * 3 + size_t(c)]);
          for (int g = 0; g < kGuideFloats; ++g)
            CHECK(r.guides[at * kGuideFloats + size_t(g)] == w.guides[full * kGuideFloats + size_t(g)]);
        }
      CHECK(r.rays.primary == primary);
      CHECK(primary > 0);
      for (int py = r.cost.packets.y0; py < r.cost.packets.y1; ++py)
        for (int pxx = r.cost.packets.x0; pxx < r.cost.packets.x1; ++pxx) {
          const int bx = pxx * layout.w / kPlanBlock, by = py * layout.h / kPlanBlock;
          const bool skipped = !rect.contains(bx, by) || planned(bx * kPlanBlock, by * kPlanBlock) == kSkipPacket;
          CHECK((r.cost.at(pxx, py) == 0) == skipped);
        }
    }
  }
  // Packets wider than a block cannot follow a plan of blocks.
  RayTracer wide(PacketLayout{8, 2});
  std::vector<std::string> warnings;
  wide.sync(scene, warnings);
  RenderSettings s = busy_settings();
  s.block_samples = plan.data();
  s.plan_blocks = blocks;
  TaskResult r;
  CHECK_THROWS_AS(wide.render({0, 0, W, H}, s, r), std::invalid_argument);
}

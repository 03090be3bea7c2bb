// Stiff and extreme cases for the ray tracer (label "stability"): scale and distance
// invariance, self-intersection acne on shadow / AO / secondary rays, degenerate and
// invalid geometry, grazing rays, cameras inside geometry, extreme fields of view and
// empty or tiny images and tasks.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include "app/bench_kernels.h"
#include "renderer/raytracer.h"
#include "scene_builders.h"

using namespace tessera;
using namespace tessera::testing;

namespace {

constexpr float kDeg = kPi / 180.0f;
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr float kInf = std::numeric_limits<float>::infinity();

// The reference scene of the invariance tests, placed by `place` (applied to every mesh
// transform, the camera and point lights): a diffuse sphere and a mirror sphere on a
// plane, a sun with shadows, a point light. Every coordinate is a multiple of 1/8, so that
// offsets of 2^20 compose exactly in float (the spacing of floats at 2^20 is 1/8).
Scene reference_scene(const Mat4& place, int W = 96, int H = 64) {
  Scene scene;
  scene.set_resolution(W, H);
  scene.set_environment(plain_env({0.3f, 0.5f, 0.8f}, {0.15f, 0.15f, 0.15f}));
  scene.set_material(1, diffuse({0.9f, 0.8f, 0.7f}));
  Material mirror = diffuse({0.1f, 0.1f, 0.1f});
  mirror.reflection = 0.7f;
  scene.set_material(2, mirror);
  scene.set_material(3, diffuse({0.5f, 0.9f, 0.5f}));
  add_object(scene, 100, sphere(1, 48), 1, place * Mat4::translate({-1.25f, 0, 0}));
  add_object(scene, 200, sphere(1, 48), 2, place * Mat4::translate({1.25f, 0, 0}));
  add_object(scene, 300, quad({-8, -1, 8}, {16, 0, 0}, {0, 0, -16}), 3, place);
  scene.set_light(1, directional({0.5f, -1, -0.4f}, 0.7f));
  Light pl;
  pl.type = Light::Type::point;
  pl.position = place.transform_point({0, 3, 2});
  pl.attenuation = {1, 0, 0};  // constant: the same at every scale
  pl.intensity = 0.4f;
  scene.set_light(2, pl);
  Camera cam = look(place.transform_point({0.5f, 1.5f, 6}), place.transform_point({0, -0.25f, 0}), 45 * kDeg);
  scene.set_camera(cam);
  return scene;
}

struct Diff {
  ImageError err;
  int over2 = 0;  // pixels with a channel differing by more than 2
};
Diff diff(const Image& a, const Image& b) {
  Diff d;
  d.err = compare(a, b);
  for (size_t i = 0; i < a.rgba.size(); i += 4)
    for (int c = 0; c < 3; ++c)
      if (std::abs(int(a.rgba[i + c]) - int(b.rgba[i + c])) > 2) {
        ++d.over2;
        break;
      }
  return d;
}

bool has_black(const Image& img) {
  for (size_t i = 0; i < img.rgba.size(); i += 4)
    if (img.rgba[i] == 0 && img.rgba[i + 1] == 0 && img.rgba[i + 2] == 0) return true;
  return false;
}

}  // namespace

// ---------------------------------------------------------------------------------------
// Scale and distance invariance
// ---------------------------------------------------------------------------------------
TEST_CASE("the same scene scaled by 1e-4 or 1e5 or moved 2^20 units away renders the same image", "[stability][scale]") {
  RenderSettings s = no_ao(4);  // AO's sample rotation hashes hit positions, so it is checked separately
  RayTracer rt0;
  Image ref = render_full(rt0, reference_scene(Mat4{}), s);
  REQUIRE_FALSE(has_black(ref));
  const float off = 1048576.0f;  // 2^20: exactly representable, as are all offsets of it used here
  struct Case {
    const char* what;
    Mat4 place;
  };
  const Case cases[] = {
      {"scaled by 1e-4", Mat4::scale(Vec3{1e-4f})},
      {"scaled by 1e5", Mat4::scale(Vec3{1e5f})},
      {"moved by 2^20 in x, y, z", Mat4::translate({off, off, off})},
      {"moved by -2^20 in x", Mat4::translate({-off, 0, 0})},
      {"scaled by 1e3 and moved by 2^20", Mat4::translate({off, 0, off}) * Mat4::scale(Vec3{1e3f})},
  };
  for (const Case& c : cases) {
    RayTracer rt;
    std::vector<std::string> warnings;
    Image img = render_full(rt, reference_scene(c.place), s, &warnings);
    CHECK(warnings.empty());
    Diff d = diff(ref, img);
    dump(std::string("invariance_ref"), ref);
    dump(std::string("invariance_") + c.what, img);
    INFO(c.what << ": PSNR " << d.err.psnr << " dB, RMSE " << d.err.rmse << ", pixels off by more than 2: " << d.over2);
    // Float rounding may flip pixels whose centre lies on a silhouette or shadow edge;
    // anything systematic (acne, lost precision, wrong offsets) costs far more.
    CHECK(d.err.psnr >= 40.0);
    CHECK(d.over2 <= int(ref.rgba.size() / 4 / 200));  // at most 0.5% of the pixels
  }
}

// ---------------------------------------------------------------------------------------
// Self-intersection acne
// ---------------------------------------------------------------------------------------
TEST_CASE("no self-intersection acne: a lit plane with shadows is uniform, AO on an open plane is 1, a mirror shows the sky", "[stability][acne]") {
  const float off = 1048576.0f;
  const Mat4 places[] = {
      Mat4{},
      Mat4::rotate(normalize(Vec3{1, 0.3f, -0.5f}), 0.7f),
      Mat4::translate({1000, -2000, 3000}) * Mat4::rotate(normalize(Vec3{-0.2f, 1, 0.4f}), 1.1f),
      Mat4::translate({off, off, -off}) * Mat4::rotate(normalize(Vec3{0.6f, 0.1f, 1}), 0.4f),
      Mat4::scale(Vec3{1e-3f}),
      Mat4::scale(Vec3{1e4f}),
  };
  int index = 0;
  for (const Mat4& place : places) {
    ++index;
    // A 200x200 plane at y = 0 (object space), camera looking down at 45 degrees: every
    // pixel sees the plane.
    Scene scene;
    const int W = 64, H = 48;
    scene.set_resolution(W, H);
    add_object(scene, 100, quad({-100, 0, 100}, {200, 0, 0}, {0, 0, -200}), 1, place);
    Vec3 up = normalize(place.transform_vector({0, 1, 0}));
    scene.set_camera(look(place.transform_point({0, 3, 3}), place.transform_point({0, 0, 0}), 40 * kDeg, up));
    INFO("placement " << index);

    // (1) Shadows: a grazing sun (75 degrees from the normal); every pixel is lit alike.
    scene.set_environment(plain_env({0, 0, 0}));
    scene.set_material(1, diffuse({1, 1, 1}));
    Vec3 travel = place.transform_vector({std::sin(75 * kDeg), -std::cos(75 * kDeg), 0});
    scene.set_light(1, directional(travel));
    {
      RayTracer rt;
      TaskResult r;
      Image img = render_full(rt, scene, no_ao(), nullptr, &r);
      CHECK(r.rays.shadow == uint64_t(W * H));
      int lo = 255, hi = 0;
      for (size_t i = 0; i < img.rgba.size(); i += 4) {
        lo = std::min(lo, int(img.rgba[i]));
        hi = std::max(hi, int(img.rgba[i]));
      }
      int expect = int(std::lround(255 * std::cos(75 * kDeg)));
      INFO("shadowed plane: min " << lo << " max " << hi << " expected " << expect);
      CHECK(lo >= expect - 1);
      CHECK(hi <= expect + 1);
    }
    scene.remove_light(1);

    // (2) AO on an open plane is 1 everywhere (ao_distance automatic: 10% of the extent).
    scene.set_environment(plain_env({0, 0, 0}, {1, 1, 1}));
    {
      RenderSettings s = no_ao();
      s.ao_samples = 8;
      RayTracer rt;
      Image img = render_full(rt, scene, s);
      int lo = 255;
      for (size_t i = 0; i < img.rgba.size(); i += 4) lo = std::min(lo, int(img.rgba[i]));
      INFO("AO on an open plane: darkest pixel " << lo);
      CHECK(lo >= 254);
    }

    // (3) Secondary rays: a perfect mirror shows the background everywhere.
    scene.set_environment(plain_env({0.2f, 0.4f, 0.6f}));
    Material mirror = diffuse({0, 0, 0});
    mirror.reflection = 1;
    scene.set_material(1, mirror);
    {
      RayTracer rt;
      Image img = render_full(rt, scene, no_ao(4));
      int bad = 0;
      for (size_t i = 0; i < img.rgba.size(); i += 4)
        if (std::abs(img.rgba[i] - 51) > 1 || std::abs(img.rgba[i + 1] - 102) > 1 || std::abs(img.rgba[i + 2] - 153) > 1) ++bad;
      INFO("mirror pixels not showing the sky: " << bad);
      CHECK(bad == 0);
    }
  }
}

// ---------------------------------------------------------------------------------------
// Degenerate and invalid geometry
// ---------------------------------------------------------------------------------------
TEST_CASE("degenerate triangles (zero area, repeated vertices, zero normals) are harmless", "[stability][degenerate]") {
  Scene scene;
  const int W = 32, H = 32;
  scene.set_resolution(W, H);
  scene.set_environment(plain_env({0, 0, 1}, {0.2f, 0.2f, 0.2f}));
  scene.set_material(1, diffuse({1, 1, 1}));
  scene.set_light(1, directional({0, 0, -1}, 0.5f));
  // One good triangle (left), then: all three vertices equal, collinear, repeated index.
  Geometry g;
  g.pos = {-1, -1, 0, 0, -1, 0, -1, 1, 0,   // good
           0.5f, 0.5f, 0, 0.5f, 0.5f, 0, 0.5f, 0.5f, 0,  // one point
           0.2f, -0.5f, 0, 0.5f, 0, 0, 0.8f, 0.5f, 0,    // collinear
           0.3f, 0.3f, 0, 0.9f, 0.3f, 0};                // for a repeated index
  g.nrm.assign(g.pos.size(), 0.0f);
  for (int v = 0; v < 3; ++v) g.nrm[size_t(v) * 3 + 2] = 1;  // the good triangle's normals; the rest zero
  g.idx = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 10, 10, 9, 10};
  add_object(scene, 100, g, 1);
  // A mesh made only of degenerate triangles.
  Geometry only;
  only.pos = {0, 0, 0.5f, 0, 0, 0.5f, 0, 0, 0.5f};
  add_object(scene, 200, only, 1);
  scene.set_camera(look({0, 0, 3}, {0, 0, 0}, 60 * kDeg));
  for (int ao : {0, 4}) {
    RayTracer rt;
    std::vector<std::string> warnings;
    RenderSettings s = no_ao();
    s.ao_samples = ao;
    Image img = render_full(rt, scene, s, &warnings);
    CHECK(warnings.empty());
    Camera cam = scene.camera();
    // Inside the good triangle: lit (0.5 N.L + 0.2 ambient); far right: background only.
    float fx, fy;
    project(cam, W, H, {-0.7f, -0.7f, 0}, fx, fy);
    Rgb in = px(img, int(fx), int(fy));
    INFO("AO " << ao << " inside the good triangle " << str(in));
    CHECK(std::abs(in.r - 179) <= 1);
    int blue = 0;
    for (int y = 0; y < H; ++y)
      for (int x = W / 2 + 1; x < W; ++x) {
        Rgb p = px(img, x, y);
        blue += p.r == 0 && p.g == 0 && p.b == 255;
      }
    CHECK(blue == (W / 2 - 1) * H);  // the degenerate triangles cover nothing
  }
}

TEST_CASE("NaN or Inf coordinates, bad transforms and out-of-range indices are rejected with a clear message", "[stability][invalid]") {
  Scene scene;
  const int W = 32, H = 32;
  scene.set_resolution(W, H);
  scene.set_environment(plain_env({0, 0, 1}));
  scene.set_material(1, matte({0, 1, 0}));
  scene.set_camera(look({0, 0, 3}, {0, 0, 0}, 60 * kDeg));
  Geometry tri;
  tri.pos = {-1, -1, 0, 1, -1, 0, 0, 1, 0};
  tri.idx = {0, 1, 2};

  Geometry nan_pos = tri;
  nan_pos.pos[4] = kNaN;
  add_object(scene, 100, nan_pos, 1);
  Geometry inf_pos = tri;
  inf_pos.pos[0] = -kInf;
  add_object(scene, 200, inf_pos, 1);
  Geometry bad_index = tri;
  bad_index.idx = {0, 1, 7};
  add_object(scene, 300, bad_index, 1);
  add_object(scene, 400, tri, 1, Mat4::translate({kNaN, 0, 0}));
  Geometry partial = tri;
  partial.idx = {0, 1, 2, 0};
  add_object(scene, 500, partial, 1);
  Mesh missing;
  missing.positions = 9999;
  scene.set_mesh(600, missing);

  RayTracer rt;
  std::vector<std::string> warnings;
  Image img = render_full(rt, scene, no_ao(), &warnings);
  auto warned = [&](const std::string& a, const std::string& b) {
    for (const std::string& w : warnings)
      if (w.find(a) != std::string::npos && w.find(b) != std::string::npos) return true;
    return false;
  };
  std::string all;
  for (auto& w : warnings) all += w + "\n";
  INFO("warnings:\n" << all);
  CHECK(warnings.size() == 6);
  CHECK(warned("mesh 100 not rendered", "holds NaN or Inf"));
  CHECK(warned("mesh 200 not rendered", "holds NaN or Inf"));
  CHECK(warned("mesh 300 not rendered", "index 7 out of range (vertex count 3)"));
  CHECK(warned("mesh 400 not rendered", "transform holds NaN or Inf"));
  CHECK(warned("mesh 500 not rendered", "not a multiple of 3"));
  CHECK(warned("mesh 600 not rendered", "missing position buffer 9999"));
  // None of them is drawn: the whole image is background.
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      Rgb p = px(img, x, y);
      REQUIRE((p.r == 0 && p.g == 0 && p.b == 255));
    }

  // Fixing a mesh's buffer makes it appear on the next sync.
  Mesh m = add_geometry(scene, 100, tri);
  m.material = 1;
  scene.set_mesh(100, m);
  img = render_full(rt, scene, no_ao(), &warnings);
  CHECK(warnings.size() == 5);
  CHECK(px(img, W / 2, H / 2).g == 255);
}

TEST_CASE("NaN normals, NaN texcoords and NaN lights give finite shading", "[stability][invalid]") {
  Scene scene;
  const int W = 32, H = 32;
  scene.set_resolution(W, H);
  scene.set_environment(plain_env({0, 0, 1}, {0.2f, 0.2f, 0.2f}));
  Texture tex;
  tex.width = tex.height = 1;
  tex.rgba = {255, 255, 255, 255};
  scene.set_texture(1, tex);
  Material m = diffuse({1, 0.5f, 0.5f});
  m.diffuse_texture = 1;
  scene.set_material(1, m);
  Geometry q = quad({-2, -2, 0}, {4, 0, 0}, {0, 4, 0});
  for (float& v : q.nrm) v = kNaN;
  for (float& v : q.uv) v = kInf;
  add_object(scene, 100, q, 1);
  scene.set_light(1, directional({0, 0, -1}, 0.5f));
  Light bad = directional({0, 0, -1});
  bad.direction = {kNaN, 0, 0};
  scene.set_light(2, bad);
  Light zero = directional({0, 0, -1});
  zero.direction = {0, 0, 0};
  scene.set_light(3, zero);
  scene.set_camera(look({0, 0, 3}, {0, 0, 0}, 60 * kDeg));
  RayTracer rt;
  RenderSettings s = no_ao();
  s.ao_samples = 2;
  Image img = render_full(rt, scene, s);
  // Flat normal (0,0,1), N.L = 1: 0.5 + 0.2 ambient; the bad lights are ignored.
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      Rgb p = px(img, x, y);
      INFO("pixel " << x << "," << y << " " << str(p));
      REQUIRE(std::abs(p.r - 179) <= 1);
      REQUIRE(std::abs(p.g - 89) <= 1);
    }
}

// ---------------------------------------------------------------------------------------
// Grazing rays, cameras inside geometry
// ---------------------------------------------------------------------------------------
TEST_CASE("grazing rays: a camera in the plane of a quad sees the quad edge-on or the background", "[stability][grazing]") {
  Scene scene;
  const int W = 33, H = 33;  // the middle row's rays lie exactly in the quad's plane
  scene.set_resolution(W, H);
  scene.set_environment(plain_env({0.2f, 0.4f, 0.6f}, {0.1f, 0.1f, 0.1f}));
  Material m = diffuse({1, 0.5f, 0});
  scene.set_material(1, m);
  Material mirror = diffuse({0.5f, 0.5f, 0.5f});
  mirror.reflection = 0.5f;
  scene.set_material(2, mirror);
  add_object(scene, 100, quad({-5, 0, 5}, {10, 0, 0}, {0, 0, -10}), 1);
  add_object(scene, 200, quad({-5, -5, -3}, {0, 10, 0}, {0, 0, 6}), 2, Mat4::translate({2, 0, 0}));
  scene.set_light(1, directional({0.3f, -1, -0.2f}));
  for (Vec3 eye : {Vec3{0, 0, 8}, Vec3{0, 0, 0}, Vec3{2, 0, 0}, Vec3{5, 0, 5}}) {
    scene.set_camera(look(eye, eye + Vec3{-0.3f, 0, -1}, 60 * kDeg));
    RenderSettings s = no_ao(4);
    s.ao_samples = 4;
    RayTracer rt;
    Image img = render_full(rt, scene, s);
    INFO("eye " << eye.x << "," << eye.y << "," << eye.z);
    // Nothing in this scene is black unless something produced NaN (NaN encodes as 0).
    CHECK_FALSE(has_black(img));
  }
}

TEST_CASE("a camera inside geometry renders finite images", "[stability][inside]") {
  SECTION("inside a closed diffuse sphere lit by a point light inside it") {
    Scene scene;
    scene.set_resolution(32, 24);
    scene.set_environment(plain_env({0, 0, 0}, {0.3f, 0.3f, 0.3f}));
    scene.set_material(1, diffuse({0.8f, 0.6f, 0.4f}));
    add_object(scene, 100, sphere(2, 32), 1);
    Light pl;
    pl.type = Light::Type::point;
    pl.position = {0.3f, 0.5f, 0.2f};
    pl.attenuation = {1, 0, 0};
    scene.set_light(1, pl);
    scene.set_camera(look({0, 0, 0}, {0, 0, -1}, 90 * kDeg));
    RenderSettings s = no_ao(4);
    s.ao_samples = 4;
    RayTracer rt;
    Image img = render_full(rt, scene, s);
    CHECK_FALSE(has_black(img));
  }
  SECTION("inside a glass sphere looking out at the sky") {
    Scene scene;
    scene.set_resolution(32, 24);
    scene.set_environment(plain_env({0.2f, 0.4f, 0.6f}));
    Material glass;
    glass.diffuse_color = {0, 0, 0};
    glass.refraction = 1;
    glass.ior = 1.5f;
    scene.set_material(1, glass);
    add_object(scene, 100, sphere(1, 32), 1);
    scene.set_camera(look({0, 0, 0}, {0, 0, -1}, 60 * kDeg));
    RayTracer rt;
    Image img = render_full(rt, scene, no_ao(4));
    // From the centre every ray leaves at normal incidence: 96% is transmitted to the sky and
    // the reflected 4% comes back through the sphere to the sky as well: the sky, undimmed.
    for (int y = 0; y < 24; ++y)
      for (int x = 0; x < 32; ++x) {
        Rgb c = px(img, x, y);
        INFO("pixel " << x << "," << y << " " << str(c));
        CHECK(std::abs(c.r - 51) <= 1);
        CHECK(std::abs(c.g - 102) <= 1);
        CHECK(std::abs(c.b - 153) <= 1);
      }
    CHECK_FALSE(has_black(img));
  }
}

// ---------------------------------------------------------------------------------------
// Extreme fields of view
// ---------------------------------------------------------------------------------------
TEST_CASE("fields of view near 0 and near 180 degrees (and invalid ones) give finite images", "[stability][fov]") {
  Scene scene;
  const int W = 24, H = 16;
  scene.set_resolution(W, H);
  scene.set_environment(plain_env({0.2f, 0.4f, 0.6f}, {0.3f, 0.3f, 0.3f}));
  scene.set_material(1, diffuse({0.9f, 0.3f, 0.3f}));
  scene.set_material(2, diffuse({0.3f, 0.9f, 0.3f}));
  add_object(scene, 100, sphere(1, 32), 1);
  add_object(scene, 200, box({-10, -10, -10}, {10, 10, 10}), 2);
  scene.set_light(1, directional({0.2f, -1, -0.5f}));
  RenderSettings s = no_ao(4);  // AO off: inside the box, ambient must reach every pixel
  for (float fov : {1e-7f, 1e-3f * kDeg, 0.0f, -1.0f, kNaN, 179.999f * kDeg, kPi, 200 * kDeg, kInf}) {
    scene.set_camera(look({0, 0, 5}, {0, 0, 0}, fov));
    RayTracer rt;
    Image img = render_full(rt, scene, s);
    INFO("fov " << fov);
    REQUIRE(img.width == W);
    CHECK_FALSE(has_black(img));
    if (fov > 0 && fov < 1e-3f) {
      // Every pixel looks at the sphere's centre.
      for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) CHECK(std::memcmp(img.pixel(x, y), img.pixel(W / 2, H / 2), 4) == 0);
    }
  }
}

// ---------------------------------------------------------------------------------------
// Tiny and empty images and tasks
// ---------------------------------------------------------------------------------------
TEST_CASE("1x1 images, 0-sized images and 0-sized tasks", "[stability][sizes]") {
  Scene scene;
  scene.set_environment(plain_env({0, 0, 1}));
  scene.set_material(1, matte({0, 1, 0}));
  add_object(scene, 100, sphere(1, 16), 1);
  scene.set_camera(look({0, 0, 5}, {0, 0, 0}, 45 * kDeg));
  RenderSettings s = no_ao(4);
  s.ao_samples = 2;

  for (PacketLayout layout : {PacketLayout{2, 2}, PacketLayout{4, 2}, PacketLayout{4, 4}}) {
    RayTracer rt(layout);
    std::vector<std::string> warnings;
    scene.set_resolution(1, 1);
    rt.sync(scene, warnings);
    TaskResult r;
    rt.render({0, 0, 1, 1}, s, r);
    REQUIRE(r.image.width == 1);
    REQUIRE(r.image.height == 1);
    CHECK(px(r.image, 0, 0).g == 255);  // the single ray goes through the sphere's centre
    CHECK(r.cost.packets == Rect{0, 0, 1, 1});
    CHECK(r.cost.cost.size() == 1);

    // Empty tasks in a 1x1 and a 20x10 image: empty result, no cost, no rays.
    scene.set_resolution(20, 10);
    rt.sync(scene, warnings);
    for (Rect t : {Rect{0, 0, 0, 0}, Rect{5, 5, 5, 9}, Rect{5, 5, 9, 5}, Rect{9, 9, 2, 2}, Rect{20, 0, 40, 10},
                   Rect{0, 10, 20, 30}, Rect{-10, -10, 0, 0}}) {
      TaskResult e;
      e.kernel_ms = 123;
      rt.render(t, s, e);
      INFO("task " << t.x0 << "," << t.y0 << "," << t.x1 << "," << t.y1);
      CHECK(e.pixels.empty());
      CHECK(e.image.width * e.image.height == 0);
      CHECK(e.image.rgba.empty());
      CHECK(e.cost.cost.empty());
      CHECK(e.kernel_ms == 0);
      CHECK(e.rays.total() == 0);
    }
    // A task partly outside the image is clipped.
    TaskResult c;
    rt.render({-5, -5, 3, 2}, s, c);
    CHECK(c.pixels == Rect{0, 0, 3, 2});
    CHECK(c.image.width == 3);
    CHECK(c.image.height == 2);

    // 0-sized images.
    for (auto [w, h] : {std::pair{0, 0}, std::pair{0, 10}, std::pair{10, 0}}) {
      scene.set_resolution(w, h);
      rt.sync(scene, warnings);
      TaskResult e;
      rt.render({0, 0, 10, 10}, s, e);
      CHECK(e.image.rgba.empty());
      CHECK(e.cost.cost.empty());
      CHECK(bench::trace_primary_only(rt, {0, 0, 10, 10}, nullptr) == 0);
    }
  }
  // An empty scene renders the background.
  Scene empty;
  empty.set_resolution(4, 4);
  empty.set_environment(plain_env({0, 0, 1}));
  RayTracer rt;
  Image img = render_full(rt, empty, s);
  CHECK(px(img, 3, 3).b == 255);
}

// ---------------------------------------------------------------------------------------
// Fault containment (core/validate.h): a scene built in code, never validated, with
// transforms and cameras that made Embree abort the process (`all(valid, ray.valid())`,
// `diag[dim] > 0.0f`): it renders, the bad entries left out, and every pixel is written.
// ---------------------------------------------------------------------------------------
namespace {

Scene containment_scene() {
  Scene scene;
  scene.set_resolution(32, 24);
  scene.set_environment(plain_env({0, 0, 1}, {0.2f, 0.2f, 0.2f}));
  scene.set_material(1, matte({0, 1, 0}));
  Material mirror = diffuse({0.2f, 0.2f, 0.2f});
  mirror.reflection = 0.5f;
  scene.set_material(2, mirror);
  scene.set_camera(look({0, 0, 5}, {0, 0, 0}, 50 * kDeg));
  scene.set_light(1, directional({0.2f, -1, -0.5f}));
  add_object(scene, 10, sphere(1, 16), 2, Mat4::translate({-1.5f, 0, 0}));  // a good mesh
  return scene;
}

Mat4 one_element(int i, float v) {
  Mat4 m;
  m.m[size_t(i)] = v;
  return m;
}

}  // namespace

TEST_CASE("meshes with singular, nearly singular or huge transforms set directly on a Scene are left out, the rest renders",
          "[stability][containment]") {
  const struct {
    const char* name;
    Mat4 xf;
    const char* why;
  } cases[] = {
      {"all zero", [] { Mat4 z; z.m.fill(0); return z; }(), "singular"},
      {"zero z-scale", Mat4::scale({1, 1, 0}), "singular"},
      {"uniform scale 1e-30", Mat4::scale(Vec3{1e-30f}), "nearly singular"},
      {"scale 1e19", Mat4::scale(Vec3{1e19f}), "scale too large"},
      {"3e38 in one element", one_element(4, 3e38f), "scale too large"},
      {"translation 1e30", Mat4::translate({1e30f, 0, 0}), "translation"},
      {"z-scale 1e-7", Mat4::scale({1, 1, 1e-7f}), "ill-conditioned"},
      {"z-scale 1e-8", Mat4::scale({1, 1, 1e-8f}), "nearly singular"},
      {"condition 2e6 within the scale bounds", Mat4::scale({2e3f, 2e3f, 1e-3f}), "ill-conditioned"},
  };
  for (const auto& c : cases) {
    Scene scene = containment_scene();
    add_object(scene, 20, sphere(1, 16), 1, Mat4::translate({1.5f, 0, 0}) * c.xf);
    RayTracer rt;
    std::vector<std::string> warnings;
    INFO(c.name);
    Image img = render_full(rt, scene, no_ao(3), &warnings);
    std::string all;
    for (auto& w : warnings) all += w + "\n";
    INFO("warnings:\n" << all);
    REQUIRE(warnings.size() == 1);
    CHECK(warnings[0].find("mesh 20 not rendered") != std::string::npos);
    CHECK(warnings[0].find(c.why) != std::string::npos);
    REQUIRE(img.width == 32);
    for (size_t i = 3; i < img.rgba.size(); i += 4) REQUIRE(img.rgba[i] == 255);  // every pixel written
    CHECK(px(img, 27, 12).b == 255);  // where the bad sphere would be: the background
  }
}

TEST_CASE("a mesh whose vertices land beyond the world box is left out", "[stability][containment]") {
  Scene scene = containment_scene();
  Geometry far = sphere(1, 8);
  for (float& v : far.pos) v *= 1e30f;  // finite, but Embree's bounds and hit points would not be
  add_object(scene, 20, far, 1);
  Geometry big = sphere(1, 8);
  add_object(scene, 30, big, 1, Mat4::scale(Vec3{3e9f}));  // 3e9 x 1 is fine alone ...
  add_object(scene, 40, big, 1, Mat4::translate({3e9f, 0, 0}) * Mat4::scale(Vec3{3e9f}));  // ... but not plus 3e9
  RayTracer rt;
  std::vector<std::string> warnings;
  Image img = render_full(rt, scene, no_ao(3), &warnings);
  std::string all;
  for (auto& w : warnings) all += w + "\n";
  INFO("warnings:\n" << all);
  CHECK(warnings.size() == 2);
  CHECK(all.find("mesh 20 not rendered: mesh transform: places vertices") != std::string::npos);
  CHECK(all.find("mesh 40 not rendered: mesh transform: places vertices") != std::string::npos);
  REQUIRE(img.width == 32);
}

TEST_CASE("a camera that is huge or singular set directly on a Scene renders the background", "[stability][containment]") {
  const struct {
    const char* name;
    Mat4 xf;
  } cases[] = {
      {"scale 1e19", Mat4::translate({0, 0, 5}) * Mat4::scale(Vec3{1e19f})},
      {"3e38 in one element", Mat4::translate({0, 0, 5}) * one_element(0, 3e38f)},
      {"translation 1e30", Mat4::translate({1e30f, 0, 5})},
      {"all zero", [] { Mat4 z; z.m.fill(0); return z; }()},
      {"uniform scale 1e-30", Mat4::translate({0, 0, 5}) * Mat4::scale(Vec3{1e-30f})},
  };
  for (const auto& c : cases) {
    INFO(c.name);
    Scene scene = containment_scene();
    Camera cam;
    cam.to_world = c.xf;
    scene.set_camera(cam);
    RayTracer rt;
    std::vector<std::string> warnings;
    Image img = render_full(rt, scene, no_ao(3), &warnings);
    REQUIRE(warnings.size() == 1);
    CHECK(warnings[0].find("camera not used") != std::string::npos);
    for (int y = 0; y < img.height; ++y)
      for (int x = 0; x < img.width; ++x) REQUIRE(str(px(img, x, y)) == str(Rgb{0, 0, 255}));
    // The next good camera renders the scene again.
    scene.set_camera(look({0, 0, 5}, {0, 0, 0}, 50 * kDeg));
    img = render_full(rt, scene, no_ao(3), &warnings);
    CHECK(warnings.empty());
    CHECK(str(px(img, 8, 12)) != str(Rgb{0, 0, 255}));  // the good sphere
  }
}

TEST_CASE("the kernel drops rays that are not finite or beyond kRayLimit instead of passing them to Embree",
          "[stability][containment]") {
  // The camera check is switched off, so the camera's rays reach the kernel: directions of
  // 1e19 (beyond Embree's FLT_LARGE of 1.844e18), infinite ones (3e38 x sx overflows), NaN
  // ones, and origins of 1e30, 3e38 and NaN. Each lane is dropped and shows the background.
  const struct {
    const char* name;
    Mat4 xf;
  } cases[] = {
      {"scale 1e19", Mat4::translate({0, 0, 5}) * Mat4::scale(Vec3{1e19f})},
      {"scale 3e38", Mat4::translate({0, 0, 5}) * Mat4::scale(Vec3{3e38f})},
      {"NaN directions", Mat4::translate({0, 0, 5}) * one_element(8, kNaN)},
      {"NaN origin", Mat4::translate({kNaN, 0, 5})},
      {"origin 1e30", Mat4::translate({1e30f, 0, 5})},
      {"origin 3e38", Mat4::translate({3e38f, 3e38f, 3e38f})},
  };
  for (int depth : {1, 3})
    for (int ao : {0, 4})
      for (const auto& c : cases) {
        INFO(c.name << ", depth " << depth << ", AO " << ao);
        Scene scene = containment_scene();
        Camera cam;
        cam.to_world = c.xf;
        scene.set_camera(cam);
        RayTracer rt;
        rt.set_camera_check(false);
        std::vector<std::string> warnings;
        RenderSettings s = no_ao(depth);
        s.ao_samples = ao;
        TaskResult res;
        rt.sync(scene, warnings);
        CHECK(warnings.empty());
        rt.render({0, 0, 32, 24}, s, res);
        REQUIRE(res.image.width == 32);
        for (int y = 0; y < 24; ++y)
          for (int x = 0; x < 32; ++x) REQUIRE(str(px(res.image, x, y)) == str(Rgb{0, 0, 255}));
        CHECK(res.rays.primary == 0);  // none reached Embree
      }
}

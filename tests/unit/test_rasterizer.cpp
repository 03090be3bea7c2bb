// The rasterizer (renderer/rasterizer.h): it shades as the ray tracer with reflection,
// refraction, AO and shadows off (the WebGL fallback's lighting model), renders any task
// rectangle so that tiles compose into exactly the full image, and syncs incrementally.
//
// Exits 77 (skip) with the reason when no EGL surfaceless GLES 3 context can be created.
//
// Tolerance of the comparison with the ray tracer (shared scenes). What legitimately
// differs between the two renderers, besides geometric edges (a rasterizer and a ray tracer
// hit different triangles along silhouettes and creases), is:
//  - texture minification: the rasterizer samples trilinear mipmaps as the WebGL fallback
//    does, the ray tracer bilinear texels without mipmaps (aliasing noise on far textures);
//  - surfaces seen from behind: the ray tracer turns the shading normal to the viewer and
//    drops light from behind the geometric normal, WebGL uses the interpolated normal as is;
//  - llvmpipe's float vs Embree's barycentric interpolation (a level or two).
// So pixels next to a strong edge of either image (3x3 neighbourhood step > 48 levels) are
// left out, and on the rest we require mean |difference| <= 4 levels and at most 3% of
// pixels differing by more than 24 levels. Measured (320x180, frames 0 and 60, Mesa 22.3.6
// llvmpipe): mean 0.6-3.1 levels (3.1: pavilion's minified floor texture), 0.27-1.3% over
// 24. Controls that must fail the same bound: the ray tracer's image from a camera ten loop
// steps away, and with the other colour convention (XML3D's instead of glTF's).
#include <catch2/catch.hpp>

#include "tests/catch_runner.h"

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "core/gltf_loader.h"
#include "core/image.h"
#include "renderer/rasterizer.h"
#include "renderer/raytracer.h"
#include "scene_builders.h"

using namespace tessera;
using namespace tessera::testing;

namespace {

struct Diff {
  double mean = 0;        // mean |difference| per channel over compared pixels
  double over24 = 0;      // fraction of compared pixels with a channel differing by > 24
  double compared = 0;    // fraction of pixels compared (not near an edge)
  int max = 0;
};

int channel_step(const Image& im, int x, int y) {
  int m = 0;
  const uint8_t* c = im.pixel(x, y);
  for (int dy = -1; dy <= 1; ++dy)
    for (int dx = -1; dx <= 1; ++dx) {
      int xx = x + dx, yy = y + dy;
      if (xx < 0 || yy < 0 || xx >= im.width || yy >= im.height) continue;
      const uint8_t* p = im.pixel(xx, yy);
      for (int k = 0; k < 3; ++k) m = std::max(m, std::abs(int(p[k]) - int(c[k])));
    }
  return m;
}

Diff compare_off_edges(const Image& a, const Image& b, int edge = 48) {
  Diff d;
  REQUIRE(a.width == b.width);
  REQUIRE(a.height == b.height);
  long n = 0, over = 0;
  double sum = 0;
  for (int y = 0; y < a.height; ++y)
    for (int x = 0; x < a.width; ++x) {
      if (channel_step(a, x, y) > edge || channel_step(b, x, y) > edge) continue;
      const uint8_t *p = a.pixel(x, y), *q = b.pixel(x, y);
      int m = 0;
      for (int k = 0; k < 3; ++k) {
        int e = std::abs(int(p[k]) - int(q[k]));
        sum += e;
        m = std::max(m, e);
      }
      d.max = std::max(d.max, m);
      over += m > 24;
      ++n;
    }
  d.compared = double(n) / (double(a.width) * a.height);
  d.mean = n ? sum / (3.0 * n) : 0;
  d.over24 = n ? double(over) / n : 0;
  return d;
}

bool within(const Diff& d) { return d.mean <= 4.0 && d.over24 <= 0.03 && d.compared >= 0.5; }

Image render(Renderer& r, const Scene& scene, const RenderSettings& s, Rect rect = {0, 0, 0, 0}) {
  std::vector<std::string> w;
  r.sync(scene, w);
  if (rect.empty()) rect = {0, 0, scene.width(), scene.height()};
  TaskResult res;
  r.render(rect, s, res);
  return res.image;
}

RenderSettings primary_only(bool shadows = false) {
  RenderSettings s;
  s.ao_samples = 0;
  s.max_depth = 1;
  s.shadows = shadows;
  return s;
}

// A shared scene with reflection and refraction switched off in every material.
LoadedScene shared_scene(const std::string& name, CameraLoop& loop) {
  const std::string dir = std::string(TESSERA_SCENES_DIR) + "/" + name;
  LoadedScene ls = load_gltf(dir + "/scene.gltf");
  loop = load_camera_loop(dir + "/camera-loop.json");
  std::vector<std::pair<Id, Material>> mats;
  for (auto& [id, e] : ls.scene.materials()) mats.emplace_back(id, e.value);
  for (auto& [id, m] : mats) {
    m.reflection = 0;
    m.refraction = 0;
    ls.scene.set_material(id, m);
  }
  ls.scene.set_resolution(320, 180);
  return ls;
}

void matches_raytracer(const std::string& name) {
  CameraLoop loop;
  LoadedScene ls = shared_scene(name, loop);
  RayTracer rt;
  Rasterizer gl;
  for (size_t frame : {size_t(0), size_t(60)}) {
    ls.scene.set_camera(loop.camera(frame));
    Image a = render(gl, ls.scene, primary_only());
    Image b = render(rt, ls.scene, primary_only());
    dump("raster_" + name + "_" + std::to_string(frame), a);
    dump("rt_" + name + "_" + std::to_string(frame), b);
    Diff d = compare_off_edges(a, b);
    INFO(name << " frame " << frame << ": mean " << d.mean << ", >24: " << d.over24 * 100 << "%, compared "
              << d.compared * 100 << "%, max " << d.max);
    CHECK(within(d));
    // Controls: the bound does tell images apart. A camera ten loop steps away, and the
    // ray tracer with the other colour convention (no 1/pi, no sRGB encoding).
    Scene other = ls.scene;
    other.set_camera(loop.camera(frame + 10));
    Diff dm = compare_off_edges(a, render(rt, other, primary_only()));
    INFO("control, ten camera steps away: mean " << dm.mean << ", >24: " << dm.over24 * 100 << "%");
    CHECK_FALSE(within(dm));
    other = ls.scene;
    Environment env = other.environment();
    env.linear = !env.linear;
    other.set_environment(env);
    Diff dl = compare_off_edges(a, render(rt, other, primary_only()));
    INFO("control, other colour convention: mean " << dl.mean << ", >24: " << dl.over24 * 100 << "%");
    CHECK_FALSE(within(dl));
  }
}

// The rasterizer's and the ray tracer's primary-ray renders of `scene` (dumped as raster_<name>
// and rt_<name>), checked to agree off the edges: a mean difference of at most 1 and at most
// 0.2% of the pixels off by more than 24.
std::pair<Image, Image> agreeing_renders(const Scene& scene, const std::string& name) {
  RayTracer rt;
  Rasterizer gl;
  Image a = render(gl, scene, primary_only());
  Image b = render(rt, scene, primary_only());
  dump("raster_" + name, a);
  dump("rt_" + name, b);
  Diff d = compare_off_edges(a, b);
  INFO("mean " << d.mean << ", >24: " << d.over24 * 100 << "%, max " << d.max << ", compared " << d.compared * 100 << "%");
  CHECK(d.mean <= 1.0);
  CHECK(d.over24 <= 0.002);
  return {std::move(a), std::move(b)};
}

// The pixel of `im` where world point p lies, seen from the scene's camera.
Rgb pixel_at(const Scene& scene, const Image& im, Vec3 p) {
  float x, y;
  project(scene.camera(), im.width, im.height, p, x, y);
  return px(im, int(std::lround(x)), int(std::lround(y)));
}

}  // namespace

TEST_CASE("rasterizer vs ray tracer: kitchen") {
  matches_raytracer("kitchen");
}
TEST_CASE("rasterizer vs ray tracer: living-room") {
  matches_raytracer("living-room");
}
TEST_CASE("rasterizer vs ray tracer: pavilion") {
  matches_raytracer("pavilion");
}

TEST_CASE("rasterizer tiles compose into exactly the full image") {
  CameraLoop loop;
  LoadedScene ls = shared_scene("kitchen", loop);
  ls.scene.set_camera(loop.camera(30));
  ls.scene.set_resolution(301, 173);  // odd sizes: no alignment to anything
  Rasterizer gl;
  Image full = render(gl, ls.scene, primary_only());
  Image composed(301, 173);
  const Rect tiles[] = {{0, 0, 97, 173}, {97, 0, 301, 61}, {97, 61, 98, 173}, {98, 61, 250, 173}, {250, 61, 301, 173}};
  for (const Rect& t : tiles) {
    TaskResult r;
    gl.render(t, primary_only(), r);
    REQUIRE(r.pixels == t);
    REQUIRE(r.image.width == t.width());
    REQUIRE(r.image.height == t.height());
    CHECK(r.cost.cost.empty());  // no cost map: the tiler splits by area
    for (int y = 0; y < t.height(); ++y)
      std::memcpy(composed.pixel(t.x0, t.y0 + y), r.image.pixel(0, y), size_t(t.width()) * 4);
  }
  CHECK(composed.rgba == full.rgba);
  TaskResult clipped;  // a rectangle reaching outside the image is clipped to it
  gl.render({250, 150, 400, 400}, primary_only(), clipped);
  CHECK(clipped.pixels == Rect{250, 150, 301, 173});
  TaskResult empty;
  gl.render({10, 10, 10, 50}, primary_only(), empty);
  CHECK(empty.image.rgba.empty());
}

TEST_CASE("rasterizer syncs incrementally: moving an instance re-uploads nothing and changes the image") {
  Scene scene;
  scene.set_resolution(96, 64);
  scene.set_environment(plain_env({0.1f, 0.1f, 0.1f}));
  scene.set_camera(look({0, 1, 6}, {0, 0, 0}, 0.8f));
  scene.set_material(1, diffuse({0.8f, 0.6f, 0.2f}));
  scene.set_light(1, directional({-0.3f, -1, -0.5f}));
  add_object(scene, 10, sphere(0.7f, 24), 1, Mat4::translate({-1.2f, 0, 0}));
  Mesh second = scene.meshes().at(10).value;  // an instance of the same geometry
  second.transform = Mat4::translate({1.2f, 0, 0});
  scene.set_mesh(20, second);
  Rasterizer gl;
  Image before = render(gl, scene, primary_only());
  CHECK(gl.last_sync().geometries_uploaded == 1);
  CHECK(gl.last_sync().instances_updated == 2);
  std::vector<std::string> w;
  gl.sync(scene, w);
  CHECK(gl.last_sync().geometries_uploaded == 0);
  CHECK(gl.last_sync().instances_updated == 0);
  second.transform = Mat4::translate({1.2f, 0.8f, 0});
  scene.set_mesh(20, second);
  Image after = render(gl, scene, primary_only());
  CHECK(gl.last_sync().geometries_uploaded == 0);
  CHECK(gl.last_sync().instances_updated == 1);
  CHECK(after.rgba != before.rgba);
  Rasterizer fresh;  // the incremental result equals a from-scratch render
  CHECK(render(fresh, scene, primary_only()).rgba == after.rgba);
  scene.remove_mesh(10);
  Image removed = render(gl, scene, primary_only());
  CHECK(gl.last_sync().instances_removed == 1);
  CHECK(removed.rgba != after.rgba);
}

TEST_CASE("rasterizer shades point, directional and spot lights, phong, textures and alpha masks as the ray tracer") {
  Scene scene;
  scene.set_resolution(160, 120);
  scene.set_environment(plain_env({0.2f, 0.3f, 0.4f}, {0.05f, 0.05f, 0.05f}));
  scene.set_camera(look({0, 2.5f, 6}, {0, 0.3f, 0}, 0.9f));
  Material phong = diffuse({0.7f, 0.3f, 0.2f});
  phong.model = Material::Model::phong;
  phong.specular_color = {0.6f, 0.6f, 0.6f};
  phong.shininess = 0.3f;
  phong.ambient_intensity = 0.1f;
  scene.set_material(1, phong);
  Material floor = diffuse({1, 1, 1});
  floor.diffuse_texture = 5;
  scene.set_material(2, floor);
  Material cut = diffuse({0.3f, 0.8f, 0.3f});
  cut.diffuse_texture = 6;
  cut.alpha_mask = true;
  scene.set_material(3, cut);
  scene.set_material(4, matte({0.2f, 0.4f, 0.9f}));
  Texture checker;  // 8x8 checker, nearest: both renderers sample the same texels
  checker.width = checker.height = 8;
  checker.sampler.filter = Sampler::Filter::nearest;
  checker.srgb = false;
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 8; ++x) {
      uint8_t v = (x + y) % 2 ? 220 : 90;
      checker.rgba.insert(checker.rgba.end(), {v, v, uint8_t(v / 2), 255});
    }
  scene.set_texture(5, checker);
  Texture mask = checker;  // left half transparent
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 4; ++x) mask.rgba[size_t(y * 8 + x) * 4 + 3] = 0;
  scene.set_texture(6, mask);
  add_object(scene, 10, quad({-4, 0, -4}, {8, 0, 0}, {0, 0, 8}), 2);
  add_object(scene, 20, sphere(0.8f, 48), 1, Mat4::translate({-1.2f, 0.8f, 0}));
  add_object(scene, 30, quad({0.3f, 0, -0.5f}, {1.6f, 0, 0}, {0, 1.6f, 0}), 3);
  add_object(scene, 40, box({2.2f, 0, -1}, {2.8f, 0.6f, -0.4f}), 4);
  scene.set_light(1, directional({-0.4f, -1, -0.3f}, 0.6f));
  Light point;
  point.type = Light::Type::point;
  point.position = {1.5f, 2, 2};
  point.color = {1, 0.9f, 0.8f};
  point.attenuation = {1, 0.1f, 0.05f};
  scene.set_light(2, point);
  Light spot = point;
  spot.type = Light::Type::spot;
  spot.position = {-2, 3, 1};
  spot.direction = normalize(Vec3{0.5f, -1, -0.3f});
  spot.cutoff = 0.5f;
  spot.softness = 0.3f;
  spot.color = {0.4f, 0.4f, 1};
  scene.set_light(3, spot);
  const Image a = agreeing_renders(scene, "lights").first;
  // The alpha mask cuts: the floor shows through the quad's left half, not its right.
  Rgb left = pixel_at(scene, a, {0.7f, 0.8f, -0.5f}), right = pixel_at(scene, a, {1.5f, 0.8f, -0.5f});
  INFO("left " << str(left) << ", right " << str(right));
  CHECK(right.g > right.r + 40);  // green quad
  CHECK(!(left.g > left.r + 40));  // cut out: floor or background
}

TEST_CASE("rasterizer shows vertex colours where the material uses them, as the ray tracer") {
  Scene scene;
  const int W = 160, H = 80;
  scene.set_resolution(W, H);
  scene.set_environment(plain_env({0, 0, 0}));
  scene.set_camera(look({0, 0, 4}, {0, 0, 0}, 0.9f));
  Material vc = matte({1, 1, 1});
  vc.use_vertex_color = true;
  scene.set_material(1, vc);
  scene.set_material(2, matte({1, 1, 1}));
  Material lit = diffuse({0.5f, 1, 1});
  lit.use_vertex_color = true;
  scene.set_material(3, lit);
  scene.set_light(1, directional({0, 0, -1}));
  Buffer colors;  // quad()'s corners: red, green, blue, white
  colors.components = 3;
  colors.f = {1, 0, 0, 0, 1, 0, 0, 0, 1, 1, 1, 1};
  scene.set_buffer(99, colors);
  const Id materials[3] = {1, 2, 3};
  for (int i = 0; i < 3; ++i) {
    Mesh m = add_geometry(scene, Id(10 * (i + 1)), quad({-3.3f + 2.2f * float(i), -1, 0}, {2, 0, 0}, {0, 2, 0}));
    m.colors = 99;
    m.material = materials[i];
    scene.set_mesh(Id(10 * (i + 1)), m);
  }
  const Image a = agreeing_renders(scene, "vertex_colors").first;
  auto at = [&](const Image& im, Vec3 p) { return pixel_at(scene, im, p); };
  // Left quad near its red corner: red; middle quad (flag off): white; right quad near its
  // green corner: green (lit head-on, diffuse 0.5 1 1).
  Rgb red = at(a, {-3.3f + 0.15f, -0.85f, 0}), white = at(a, {0.15f - 1.1f, -0.85f, 0}),
      green = at(a, {1.1f + 2 - 0.15f, -0.85f, 0});
  INFO("red " << str(red) << ", white " << str(white) << ", green " << str(green));
  CHECK((red.r > 200 && red.g < 50 && red.b < 50));
  CHECK((white.r > 240 && white.g > 240 && white.b > 240));
  CHECK((green.g > 200 && green.r < 50 && green.b < 50));
}

int test_prelude() {
  std::string why;
  if (!rasterizer_available(&why)) {
    std::printf("SKIP: %s\n", why.c_str());
    return 77;
  }
  return 0;
}

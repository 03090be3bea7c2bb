#pragma once
// Analytic scene builders for the ray tracer tests: tessellated spheres, quads, boxes and
// slabs as Scene buffers + meshes, a camera helper, full-frame rendering and pixel access.
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <vector>

#include "core/image.h"
#include "renderer/raytracer.h"
#include "core/scene.h"

namespace tessera::testing {

// Raw triangle geometry in object space.
struct Geometry {
  std::vector<float> pos, nrm, uv;  // nrm / uv may be empty
  std::vector<uint32_t> idx;
};

// UV sphere with poles on +-Y, smooth normals. `seg` segments around, seg/2 rings.
inline Geometry sphere(float radius, int seg = 64) {
  Geometry g;
  int rings = seg / 2;
  for (int r = 0; r <= rings; ++r) {
    float theta = kPi * float(r) / float(rings);  // 0 at +Y
    for (int s = 0; s <= seg; ++s) {
      float phi = 2 * kPi * float(s) / float(seg);
      Vec3 n{std::sin(theta) * std::sin(phi), std::cos(theta), std::sin(theta) * std::cos(phi)};
      g.pos.insert(g.pos.end(), {n.x * radius, n.y * radius, n.z * radius});
      g.nrm.insert(g.nrm.end(), {n.x, n.y, n.z});
      g.uv.insert(g.uv.end(), {float(s) / float(seg), float(r) / float(rings)});
    }
  }
  auto at = [&](int r, int s) { return uint32_t(r * (seg + 1) + s); };
  for (int r = 0; r < rings; ++r)
    for (int s = 0; s < seg; ++s) {
      // Counter-clockwise seen from outside.
      if (r != 0) g.idx.insert(g.idx.end(), {at(r, s), at(r + 1, s), at(r, s + 1)});
      if (r != rings - 1) g.idx.insert(g.idx.end(), {at(r, s + 1), at(r + 1, s), at(r + 1, s + 1)});
    }
  return g;
}

// Quad p, p+u, p+u+v, p+v (counter-clockwise seen from the side u x v points to).
// Texcoords: p -> (0,1), p+u -> (1,1), p+u+v -> (1,0), p+v -> (0,0) (v = 0 at the top when v points up).
inline Geometry quad(Vec3 p, Vec3 u, Vec3 v) {
  Geometry g;
  Vec3 c[4] = {p, p + u, p + u + v, p + v};
  Vec3 n = normalize(cross(u, v));
  float uv[8] = {0, 1, 1, 1, 1, 0, 0, 0};
  for (int i = 0; i < 4; ++i) {
    g.pos.insert(g.pos.end(), {c[i].x, c[i].y, c[i].z});
    g.nrm.insert(g.nrm.end(), {n.x, n.y, n.z});
    g.uv.insert(g.uv.end(), {uv[2 * i], uv[2 * i + 1]});
  }
  g.idx = {0, 1, 2, 0, 2, 3};
  return g;
}

// Axis-aligned box [lo, hi], flat faces with outward normals (counter-clockwise from outside).
inline Geometry box(Vec3 lo, Vec3 hi) {
  Geometry g;
  auto face = [&](Vec3 p, Vec3 u, Vec3 v) {
    Geometry q = quad(p, u, v);
    uint32_t base = uint32_t(g.pos.size() / 3);
    g.pos.insert(g.pos.end(), q.pos.begin(), q.pos.end());
    g.nrm.insert(g.nrm.end(), q.nrm.begin(), q.nrm.end());
    g.uv.insert(g.uv.end(), q.uv.begin(), q.uv.end());
    for (uint32_t i : q.idx) g.idx.push_back(base + i);
  };
  Vec3 d = hi - lo;
  Vec3 ex{d.x, 0, 0}, ey{0, d.y, 0}, ez{0, 0, d.z};
  face(lo, ey, ex);                                // -Z
  face({lo.x, lo.y, hi.z}, ex, ey);                // +Z
  face(lo, ez, ey);                                // -X
  face({hi.x, lo.y, lo.z}, ey, ez);                // +X
  face(lo, ex, ez);                                // -Y
  face({lo.x, hi.y, lo.z}, ez, ex);                // +Y
  return g;
}

// A slab of the given thickness along Z (z in [-thickness/2, thickness/2]), half-size `half` in X and Y.
inline Geometry slab(float half, float thickness) {
  return box({-half, -half, -thickness / 2}, {half, half, thickness / 2});
}

// Adds the geometry's buffers under ids base..base+3 (positions, normals, texcoords,
// indices) and returns a mesh referencing them (not yet added).
inline Mesh add_geometry(Scene& scene, Id base, const Geometry& g, bool normals = true, bool uvs = true) {
  Mesh m;
  Buffer p;
  p.components = 3;
  p.f = g.pos;
  scene.set_buffer(base, p);
  m.positions = base;
  if (normals && !g.nrm.empty()) {
    Buffer n;
    n.components = 3;
    n.f = g.nrm;
    scene.set_buffer(base + 1, n);
    m.normals = base + 1;
  }
  if (uvs && !g.uv.empty()) {
    Buffer t;
    t.components = 2;
    t.f = g.uv;
    scene.set_buffer(base + 2, t);
    m.texcoords = base + 2;
  }
  if (!g.idx.empty()) {
    Buffer i;
    i.type = Buffer::Type::u32;
    i.components = 1;
    i.u = g.idx;
    scene.set_buffer(base + 3, i);
    m.indices = base + 3;
  }
  return m;
}

// Adds geometry + mesh (mesh id = base) with a material and transform.
inline void add_object(Scene& scene, Id base, const Geometry& g, Id material, const Mat4& xf = Mat4{}) {
  Mesh m = add_geometry(scene, base, g);
  m.material = material;
  m.transform = xf;
  scene.set_mesh(base, m);
}

inline Material matte(Vec3 c) {
  Material m;
  m.model = Material::Model::matte;
  m.diffuse_color = c;
  return m;
}
inline Material diffuse(Vec3 c) {
  Material m;
  m.model = Material::Model::diffuse;
  m.diffuse_color = c;
  return m;
}

// XML3D/WebGL convention (colours written as given), exposure 1.
inline Environment plain_env(Vec3 background = {0, 0, 0}, Vec3 ambient = {0, 0, 0}) {
  Environment e;
  e.linear = false;
  e.exposure = 1;
  e.background = background;
  e.ambient = ambient;
  return e;
}

inline Light directional(Vec3 travel, float intensity = 1, Vec3 color = {1, 1, 1}) {
  Light l;
  l.type = Light::Type::directional;
  l.direction = normalize(travel);
  l.intensity = intensity;
  l.color = color;
  return l;
}

// A red quad (x, y in [-1, 1], z = 0) textured with a 2x2 nearest texture (id 1) whose right
// half has alpha 0, masked at 0.5 when `alpha_mask`, in front of a green quad (x, y in [-4, 4],
// z = -1), under a blue sky with 0.2 ambient and a directional light (id 1) travelling along
// (1, 0, -1): shadows fall one unit to +x on the back quad. Meshes and buffers from `base`
// (front) and base + 100 (back); materials 1 and 2. Resolution and camera are the caller's.
inline void add_cutout(Scene& scene, Id base, bool alpha_mask) {
  scene.set_environment(plain_env({0, 0, 1}, {0.2f, 0.2f, 0.2f}));
  Texture tex;
  tex.width = tex.height = 2;
  tex.rgba = {255, 255, 255, 255, 255, 255, 255, 0, 255, 255, 255, 255, 255, 255, 255, 0};
  tex.sampler.filter = Sampler::Filter::nearest;
  scene.set_texture(1, tex);
  Material front = diffuse({1, 0, 0});
  front.diffuse_texture = 1;
  front.alpha_mask = alpha_mask;
  front.alpha_cutoff = 0.5f;
  scene.set_material(1, front);
  scene.set_material(2, diffuse({0, 1, 0}));
  add_object(scene, base, quad({-1, -1, 0}, {2, 0, 0}, {0, 2, 0}), 1);
  add_object(scene, base + 100, quad({-4, -4, -1}, {8, 0, 0}, {0, 8, 0}), 2);
  scene.set_light(1, directional({1, 0, -1}));
}

inline Camera look(Vec3 eye, Vec3 target, float fov_y, Vec3 up = {0, 1, 0}) {
  Camera c;
  c.to_world = Mat4::look_at(eye, target, up);
  c.fov_y = fov_y;
  return c;
}

inline RenderSettings no_ao(int depth = 4) {
  RenderSettings s;
  s.ao_samples = 0;
  s.max_depth = depth;
  s.shadows = true;
  return s;
}

// Syncs and renders the whole frame; fails loudly if sync warned and warnings is null.
inline Image render_full(RayTracer& rt, const Scene& scene, const RenderSettings& s,
                         std::vector<std::string>* warnings = nullptr, TaskResult* result = nullptr) {
  std::vector<std::string> w;
  rt.sync(scene, w);
  if (warnings) *warnings = w;
  TaskResult r;
  rt.render({0, 0, scene.width(), scene.height()}, s, r);
  Image img = r.image;
  if (result) *result = std::move(r);
  return img;
}

// Writes img to $TESSERA_TEST_DUMP/name.png when that variable is set (for looking at failures).
inline void dump(const std::string& name, const Image& img) {
  if (const char* dir = std::getenv("TESSERA_TEST_DUMP"))
    if (img.width > 0 && img.height > 0) write_png(std::string(dir) + "/" + name + ".png", img);
}

struct Rgb {
  int r, g, b;
};
inline Rgb px(const Image& img, int x, int y) {
  const uint8_t* p = img.pixel(x, y);
  return {p[0], p[1], p[2]};
}
inline std::string str(Rgb c) {
  return "(" + std::to_string(c.r) + "," + std::to_string(c.g) + "," + std::to_string(c.b) + ")";
}

// The camera ray through pixel (x, y) (pixel centres), as the ray tracer generates it.
inline Vec3 pixel_dir(const Camera& cam, int w, int h, float x, float y) {
  float tan_half = std::tan(cam.fov_y * 0.5f);
  float aspect = float(w) / float(h);
  float sx = (2.0f * (x + 0.5f) / float(w) - 1.0f) * tan_half * aspect;
  float sy = (1.0f - 2.0f * (y + 0.5f) / float(h)) * tan_half;
  Vec3 cx = cam.to_world.transform_vector({1, 0, 0}), cy = cam.to_world.transform_vector({0, 1, 0}),
       cz = cam.to_world.transform_vector({0, 0, -1});
  return normalize(cz + cx * sx + cy * sy);
}
inline Vec3 cam_pos(const Camera& cam) { return cam.to_world.transform_point({0, 0, 0}); }

// Projects a world point to continuous pixel coordinates (pixel centres at integer + 0.5 - 0.5 = integer).
inline void project(const Camera& cam, int w, int h, Vec3 p, float& x, float& y) {
  Mat4 inv = inverse(cam.to_world);
  Vec3 q = inv.transform_point(p);
  float tan_half = std::tan(cam.fov_y * 0.5f);
  float aspect = float(w) / float(h);
  float sx = q.x / -q.z, sy = q.y / -q.z;
  x = (sx / (tan_half * aspect) + 1.0f) * 0.5f * float(w) - 0.5f;
  y = (1.0f - sy / tan_half) * 0.5f * float(h) - 0.5f;
}

}  // namespace tessera::testing

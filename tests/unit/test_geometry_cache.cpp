// Bottom-level BVHs shared between ray tracers (renderer/geometry_cache.h, issue 20): found by
// content, never by a hash alone; kept within a byte limit; and a session's images do not
// depend on what other sessions hold.
#include <catch2/catch.hpp>

#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "renderer/embree_device.h"
#include "renderer/geometry_cache.h"
#include "renderer/raytracer.h"
#include "scene_builders.h"

using namespace tessera;
using namespace tessera::testing;

namespace {

// An entry without an Embree scene: the cache itself never looks at it.
std::shared_ptr<SharedGeometry> entry(const GeometryCache& cache, std::vector<float> pos, std::vector<uint32_t> idx,
                                      bool filter = false) {
  auto e = std::make_shared<SharedGeometry>();
  e->vertex_count = pos.size() / 3;
  e->triangle_count = idx.size() / 3;
  e->positions = std::move(pos);
  e->indices = std::move(idx);
  e->filter = filter;
  e->hash = cache.hash({e->positions.data(), e->vertex_count, e->indices.data(), e->triangle_count, filter, false});
  e->bytes = GeometryCache::estimate_bytes(e->vertex_count, e->triangle_count);
  return e;
}

GeometryContent content(const std::vector<float>& pos, const std::vector<uint32_t>& idx, bool filter = false) {
  return {pos.data(), pos.size() / 3, idx.data(), idx.size() / 3, filter, false};
}

uint64_t same_hash(const GeometryContent&) { return 42; }  // every content collides

bool same_image(const Image& a, const Image& b) {
  return a.width == b.width && a.height == b.height && a.rgba == b.rgba;
}

// The alpha-mask scene of test_raytracer (scene_builders.h add_cutout): a quad whose right half
// is cut out, over a back quad, lit at an angle. Buffers and meshes from id `base`.
Scene cutout_scene(Id base, bool alpha_mask) {
  Scene scene;
  scene.set_resolution(64, 64);
  add_cutout(scene, base, alpha_mask);
  scene.set_camera(look({0, 0, 5}, {0, 0, 0}, 60 * kPi / 180));
  return scene;
}

}  // namespace

TEST_CASE("the geometry cache finds an entry by its content, never by its hash alone", "[geometry-cache]") {
  GeometryCache cache(uint64_t(1) << 30, same_hash);
  const std::vector<float> pa = {0, 0, 0, 1, 0, 0, 0, 1, 0}, pb = {0, 0, 0, 2, 0, 0, 0, 2, 0};
  const std::vector<uint32_t> idx = {0, 1, 2}, flipped = {0, 2, 1};
  auto a = cache.insert(entry(cache, pa, idx));
  CHECK(cache.find(content(pa, idx), 42) == a);
  CHECK(cache.find(content(pb, idx), 42) == nullptr);         // same hash, other positions
  CHECK(cache.find(content(pa, flipped), 42) == nullptr);     // other indices
  CHECK(cache.find(content(pa, idx, true), 42) == nullptr);   // other filter functions
  auto b = cache.insert(entry(cache, pb, idx));
  CHECK(b != a);
  CHECK(cache.find(content(pb, idx), 42) == b);
  CHECK(cache.find(content(pa, idx), 42) == a);
  // An equal entry built meanwhile by another session: the first one wins.
  auto again = cache.insert(entry(cache, pa, idx));
  CHECK(again == a);
  const auto st = cache.stats();
  CHECK(st.entries == 2);
  CHECK(st.hits == 3);
  CHECK(st.misses == 3);
}

TEST_CASE("the geometry cache drops unused entries beyond its limit, oldest first, and keeps used ones", "[geometry-cache]") {
  const std::vector<uint32_t> idx = {0, 1, 2};
  auto pos = [](float s) { return std::vector<float>{0, 0, 0, s, 0, 0, 0, s, 0}; };
  const uint64_t one = GeometryCache::estimate_bytes(3, 1);
  GeometryCache cache(2 * one);
  auto a = cache.insert(entry(cache, pos(1), idx));
  auto b = cache.insert(entry(cache, pos(2), idx));
  CHECK(cache.stats().entries == 2);
  a.reset();
  b.reset();
  // Touch the first: the second is now the least recently used.
  CHECK(cache.find(content(pos(1), idx), cache.hash(content(pos(1), idx))) != nullptr);
  auto c = cache.insert(entry(cache, pos(3), idx));  // over the limit: one must go
  CHECK(cache.stats().entries == 2);
  CHECK(cache.stats().evictions == 1);
  CHECK(cache.find(content(pos(2), idx), cache.hash(content(pos(2), idx))) == nullptr);
  CHECK(cache.find(content(pos(1), idx), cache.hash(content(pos(1), idx))) != nullptr);
  // Entries in use stay whatever the limit; they go once released and trimmed.
  auto held = cache.find(content(pos(1), idx), cache.hash(content(pos(1), idx)));
  cache.set_limit(0);
  CHECK(cache.stats().entries == 2);  // both in use (c and held)
  c.reset();
  cache.trim();
  CHECK(cache.stats().entries == 1);
  CHECK(cache.stats().bytes == one);
  held.reset();
  cache.trim();
  CHECK(cache.stats().entries == 0);
  CHECK(cache.stats().bytes == 0);
}

TEST_CASE("ray tracers of equal geometry share its BVHs, and each renders its own materials", "[geometry-cache][raytracer]") {
  auto device = EmbreeDevice::acquire();
  device->geometries().clear();
  std::vector<std::string> warnings;
  const Scene masked = cutout_scene(100, true);
  RayTracer a;
  const Image img_a = render_full(a, masked, no_ao(), &warnings);
  REQUIRE(warnings.empty());
  CHECK(a.last_sync().geometries_built == 2);
  CHECK(a.last_sync().geometries_shared == 0);

  // The same content under other ids: both BVHs come from the cache, and the image is the same.
  RayTracer b;
  const Image img_b = render_full(b, cutout_scene(500, true), no_ao(), &warnings);
  CHECK(b.last_sync().geometries_built == 2);
  CHECK(b.last_sync().geometries_shared == 2);
  CHECK(same_image(img_a, img_b));

  // Without the alpha mask the front quad needs no filter function: its BVH is built apart
  // (the back quad's is shared), and the cut-out is opaque here while it stays open in `a`.
  RayTracer c;
  const Image img_c = render_full(c, cutout_scene(900, false), no_ao(), &warnings);
  CHECK(c.last_sync().geometries_shared == 1);
  CHECK(!same_image(img_a, img_c));
  const Rgb open = px(img_a, 40, 32), closed = px(img_c, 40, 32);  // the front quad's right half
  CHECK(open.r == 0);
  CHECK(closed.r > 100);

  // A session whose positions changed (a new scene object: every entry is new to `b`, since
  // versions are process-wide) builds that geometry anew and takes the other from the cache;
  // the others render as before.
  Scene moved = cutout_scene(500, true);
  Buffer p = *moved.buffer(500);
  for (size_t i = 0; i < p.f.size(); i += 3) p.f[i] += 0.5f;
  moved.set_buffer(500, p);
  const Image img_moved = render_full(b, moved, no_ao(), &warnings);
  CHECK(b.last_sync().geometries_built == 2);
  CHECK(b.last_sync().geometries_shared == 1);
  CHECK(!same_image(img_a, img_moved));
  CHECK(same_image(render_full(a, masked, no_ao(), &warnings), img_a));
  CHECK(same_image(render_full(c, cutout_scene(900, false), no_ao(), &warnings), img_c));
}

TEST_CASE("a later session finds what an ended one built while the device lives, unless the limit is 0",
          "[geometry-cache][raytracer]") {
  auto device = EmbreeDevice::acquire();  // as a node holds it
  device->geometries().clear();
  std::vector<std::string> warnings;
  Image first;
  {
    RayTracer a;
    first = render_full(a, cutout_scene(100, true), no_ao(), &warnings);
  }
  CHECK(device->geometries().stats().entries == 2);
  {
    RayTracer b;
    CHECK(same_image(render_full(b, cutout_scene(100, true), no_ao(), &warnings), first));
    CHECK(b.last_sync().geometries_shared == 2);
  }
  EmbreeDevice::set_geometry_cache_limit(0);
  CHECK(device->geometries().stats().entries == 0);  // nobody uses them now
  {
    RayTracer c;
    CHECK(same_image(render_full(c, cutout_scene(100, true), no_ao(), &warnings), first));
    CHECK(c.last_sync().geometries_shared == 0);
    CHECK(device->geometries().stats().entries == 2);  // in use: kept while c lives
  }
  CHECK(device->geometries().stats().entries == 0);
  EmbreeDevice::set_geometry_cache_limit(uint64_t(1) << 30);
}

TEST_CASE("the BVH quality is part of a cached geometry: medium-quality BVHs render the same picture", "[geometry-cache][raytracer]") {
  const std::vector<float> pa = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  const std::vector<uint32_t> idx = {0, 1, 2};
  {
    GeometryCache cache(uint64_t(1) << 30, same_hash);
    auto a = cache.insert(entry(cache, pa, idx));  // built at HIGH (SharedGeometry's default)
    GeometryContent medium = content(pa, idx);
    medium.high_quality = false;
    CHECK(cache.find(medium, 42) == nullptr);  // not what a MEDIUM build asks for
    CHECK(cache.find(content(pa, idx), 42) == a);
  }
  auto device = EmbreeDevice::acquire();
  device->geometries().clear();
  std::vector<std::string> warnings;
  REQUIRE(!EmbreeDevice::high_quality_bvh());  // the default: medium
  EmbreeDevice::set_high_quality_bvh(true);
  RayTracer high;
  const Image img_high = render_full(high, cutout_scene(100, true), no_ao(), &warnings);
  EmbreeDevice::set_high_quality_bvh(false);
  RayTracer medium;
  const Image img_medium = render_full(medium, cutout_scene(100, true), no_ao(), &warnings);
  REQUIRE(warnings.empty());
  CHECK(high.last_sync().geometries_built == 2);
  CHECK(medium.last_sync().geometries_built == 2);
  CHECK(medium.last_sync().geometries_shared == 0);  // the HIGH ones are not taken
  CHECK(same_image(img_high, img_medium));            // the same closest hits
}

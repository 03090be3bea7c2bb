#pragma once
// Bottom-level BVHs shared between the ray tracers of a process (issue 20): a mesh whose
// positions, indices and filter functions equal those of a mesh that another session (or an
// earlier one) built is not built again. The second visitor of a page whose scene the node
// already holds gets its BVHs at once instead of after seconds of building.
//
// An entry is found by a 64-bit hash of its contents and taken only when the contents compare
// equal byte for byte: a hash collision, chosen or not, can never hand one session another's
// geometry. Entries nobody uses are kept within a byte limit (tessera.geometry-cache-mb),
// least recently used first out; entries in use are never dropped (their memory is spent
// anyway) but count towards the limit.
//
// Thread-safe: sessions sync on their own threads.
#include <cstddef>
#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <vector>

#include <embree3/rtcore.h>

namespace tessera {

// One mesh's committed Embree scene and the data it was built from (Embree reads both
// vectors in place: they are shared buffers, so the geometry exists once).
struct SharedGeometry {
  RTCScene blas = nullptr;
  std::vector<float> positions;   // 3 per vertex, then padding (Embree reads 16 bytes at the last vertex)
  std::vector<uint32_t> indices;  // 3 per triangle
  size_t vertex_count = 0;
  size_t triangle_count = 0;
  bool filter = false;       // the alpha-mask intersection filter is attached
  bool see_through = false;  // the occlusion filter is attached
  bool high_quality = true;  // built with RTC_BUILD_QUALITY_HIGH (else MEDIUM; EmbreeDevice::high_quality_bvh)
  uint64_t hash = 0;
  uint64_t bytes = 0;        // what it holds, with an estimate of the BVH's size

  SharedGeometry() = default;
  SharedGeometry(const SharedGeometry&) = delete;
  SharedGeometry& operator=(const SharedGeometry&) = delete;
  ~SharedGeometry() {
    if (blas) rtcReleaseScene(blas);
  }
};

// What a lookup compares: the mesh's vertex positions (3 floats each) and triangle indices.
struct GeometryContent {
  const float* positions = nullptr;
  size_t vertex_count = 0;
  const uint32_t* indices = nullptr;
  size_t triangle_count = 0;
  bool filter = false;
  bool see_through = false;
  bool high_quality = true;
};

class GeometryCache {
 public:
  using HashFn = uint64_t (*)(const GeometryContent&);
  // The default hash reads every byte (several GB/s); tests pass a colliding one.
  static uint64_t default_hash(const GeometryContent& c);
  // The bytes an entry is charged: its vectors and an estimate of Embree's BVH (about 64
  // bytes per triangle at high quality with spatial splits).
  static uint64_t estimate_bytes(size_t vertex_count, size_t triangle_count);

  explicit GeometryCache(uint64_t limit_bytes, HashFn hash = default_hash) : limit_(limit_bytes), hash_(hash) {}
  GeometryCache(const GeometryCache&) = delete;
  GeometryCache& operator=(const GeometryCache&) = delete;

  uint64_t hash(const GeometryContent& c) const { return hash_(c); }
  // The entry with exactly this content (hash h from hash()), or null.
  std::shared_ptr<const SharedGeometry> find(const GeometryContent& c, uint64_t h);
  // Keeps a built and committed entry (its hash set) and returns the one to use: an equal
  // entry inserted meanwhile by another session wins, and `e` is then dropped.
  std::shared_ptr<const SharedGeometry> insert(std::shared_ptr<SharedGeometry> e);

  void set_limit(uint64_t bytes);
  // Drops unused entries beyond the limit: ray tracers call it after releasing entries.
  void trim();
  // Drops every entry (the cache's references; users keep theirs).
  void clear();
  struct Stats {
    size_t entries = 0;
    uint64_t bytes = 0;
    uint64_t hits = 0, misses = 0, evictions = 0;
  };
  Stats stats() const;

 private:
  static bool same(const SharedGeometry& e, const GeometryContent& c);
  void evict_locked();

  mutable std::mutex mu_;
  uint64_t limit_;
  HashFn hash_;
  // Most recently used first; the map finds entries by hash (several may share one).
  std::list<std::shared_ptr<const SharedGeometry>> lru_;
  std::unordered_multimap<uint64_t, std::list<std::shared_ptr<const SharedGeometry>>::iterator> by_hash_;
  Stats stats_;
};

}  // namespace tessera

#include "renderer/geometry_cache.h"

#include <cstring>

namespace tessera {

namespace {

constexpr uint64_t kP1 = 0x9E3779B185EBCA87ull, kP2 = 0xC2B2AE3D27D4EB4Full, kP3 = 0x165667B19E3779F9ull;

inline uint64_t rotl(uint64_t x, int r) { return x << r | x >> (64 - r); }
inline uint64_t round(uint64_t acc, uint64_t v) { return rotl(acc + v * kP2, 31) * kP1; }

// Four independent lanes of multiply-rotate over 8-byte words, then the tail: fast enough
// that hashing a scene's geometry costs milliseconds. Not a cryptographic hash: a lookup
// compares the contents as well.
uint64_t hash_bytes(const void* data, size_t n, uint64_t seed) {
  const auto* p = static_cast<const unsigned char*>(data);
  uint64_t a = seed + kP1 + kP2, b = seed + kP2, c = seed, d = seed - kP1;
  size_t i = 0;
  for (; i + 32 <= n; i += 32) {
    uint64_t w[4];
    std::memcpy(w, p + i, 32);
    a = round(a, w[0]); b = round(b, w[1]); c = round(c, w[2]); d = round(d, w[3]);
  }
  uint64_t h = rotl(a, 1) + rotl(b, 7) + rotl(c, 12) + rotl(d, 18) + uint64_t(n) * kP3;
  for (; i + 8 <= n; i += 8) {
    uint64_t w;
    std::memcpy(&w, p + i, 8);
    h = rotl(h ^ round(0, w), 27) * kP1 + kP3;
  }
  for (; i < n; ++i) h = rotl(h ^ (p[i] * kP3), 11) * kP1;
  h ^= h >> 33; h *= kP2; h ^= h >> 29; h *= kP3; h ^= h >> 32;
  return h;
}

}  // namespace

uint64_t GeometryCache::default_hash(const GeometryContent& c) {
  uint64_t h = hash_bytes(c.positions, c.vertex_count * 3 * sizeof(float), 0x7e55e7a);
  h = hash_bytes(c.indices, c.triangle_count * 3 * sizeof(uint32_t), h);
  return h ^ (uint64_t(c.high_quality) << 2 | uint64_t(c.filter) << 1 | uint64_t(c.see_through));
}

uint64_t GeometryCache::estimate_bytes(size_t vertex_count, size_t triangle_count) {
  return uint64_t(vertex_count) * 12 + uint64_t(triangle_count) * (12 + 64) + 256;
}

bool GeometryCache::same(const SharedGeometry& e, const GeometryContent& c) {
  return e.vertex_count == c.vertex_count && e.triangle_count == c.triangle_count && e.filter == c.filter &&
         e.see_through == c.see_through && e.high_quality == c.high_quality &&
         std::memcmp(e.positions.data(), c.positions, c.vertex_count * 3 * sizeof(float)) == 0 &&
         std::memcmp(e.indices.data(), c.indices, c.triangle_count * 3 * sizeof(uint32_t)) == 0;
}

std::shared_ptr<const SharedGeometry> GeometryCache::find(const GeometryContent& c, uint64_t h) {
  std::lock_guard<std::mutex> l(mu_);
  auto [lo, hi] = by_hash_.equal_range(h);
  for (auto it = lo; it != hi; ++it) {
    if (!same(**it->second, c)) continue;
    lru_.splice(lru_.begin(), lru_, it->second);  // the iterator stays valid
    ++stats_.hits;
    return *it->second;
  }
  ++stats_.misses;
  return nullptr;
}

std::shared_ptr<const SharedGeometry> GeometryCache::insert(std::shared_ptr<SharedGeometry> e) {
  std::lock_guard<std::mutex> l(mu_);
  GeometryContent c{e->positions.data(), e->vertex_count, e->indices.data(), e->triangle_count, e->filter, e->see_through,
                    e->high_quality};
  auto [lo, hi] = by_hash_.equal_range(e->hash);
  for (auto it = lo; it != hi; ++it)
    if (same(**it->second, c)) return *it->second;
  lru_.push_front(std::move(e));
  by_hash_.emplace(lru_.front()->hash, lru_.begin());
  stats_.bytes += lru_.front()->bytes;
  ++stats_.entries;
  std::shared_ptr<const SharedGeometry> kept = lru_.front();  // held: not evictable below
  evict_locked();
  return kept;
}

void GeometryCache::set_limit(uint64_t bytes) {
  std::lock_guard<std::mutex> l(mu_);
  limit_ = bytes;
  evict_locked();
}

void GeometryCache::trim() {
  std::lock_guard<std::mutex> l(mu_);
  evict_locked();
}

void GeometryCache::clear() {
  std::lock_guard<std::mutex> l(mu_);
  stats_.evictions += lru_.size();
  by_hash_.clear();
  lru_.clear();
  stats_.entries = 0;
  stats_.bytes = 0;
}

void GeometryCache::evict_locked() {
  // Oldest first; an entry some ray tracer holds (use count above the cache's own) stays.
  for (auto it = lru_.end(); stats_.bytes > limit_ && it != lru_.begin();) {
    --it;
    if (it->use_count() > 1) continue;
    auto [lo, hi] = by_hash_.equal_range((*it)->hash);
    for (auto m = lo; m != hi; ++m)
      if (m->second == it) {
        by_hash_.erase(m);
        break;
      }
    stats_.bytes -= (*it)->bytes;
    --stats_.entries;
    ++stats_.evictions;
    it = lru_.erase(it);
  }
}

GeometryCache::Stats GeometryCache::stats() const {
  std::lock_guard<std::mutex> l(mu_);
  return stats_;
}

}  // namespace tessera

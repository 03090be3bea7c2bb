#pragma once
// One Embree device per process, shared by every ray tracer (issue 17): a session no longer
// makes its own. The device lives while some ray tracer holds it (acquire()), and records the
// errors Embree reports through its error callback: a count and the last message. Embree has
// one callback per device, not per scene, so a ray tracer notices an error by the count moving
// during its own sync or render; with several ray tracers at work at once, an error in one may
// be seen by another as well (it then fails a frame it could have rendered: never the reverse).
#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>

#include <embree3/rtcore.h>

#include "renderer/geometry_cache.h"

namespace tessera {

class EmbreeDevice {
 public:
  // The process's device, made on first use and again after the last holder released it.
  // Throws std::runtime_error when Embree cannot make one.
  static std::shared_ptr<EmbreeDevice> acquire();
  // How many devices exist now (0 or 1; for tests).
  static size_t live();

  ~EmbreeDevice();
  EmbreeDevice(const EmbreeDevice&) = delete;
  EmbreeDevice& operator=(const EmbreeDevice&) = delete;

  RTCDevice get() const { return device_; }
  uint64_t errors() const { return errors_.load(std::memory_order_acquire); }
  // "embree: <code name>: <message>" of the last error reported; empty before the first.
  std::string last_error() const;

  // The bottom-level BVHs its ray tracers share (renderer/geometry_cache.h). They live as
  // long as the device: a node holds the device for its lifetime, so that a later session
  // finds what an earlier one built.
  GeometryCache& geometries() { return geometries_; }
  // The cache's byte limit, for the device now live and every later one (default 1 GiB).
  static void set_geometry_cache_limit(uint64_t bytes);
  // The quality of the meshes' BVHs built from now on, for every ray tracer of the process
  // (tessera.bvh-quality, --bvh-quality): false RTC_BUILD_QUALITY_MEDIUM (the default: builds
  // 2.5-5x faster, frames as fast within the noise on the shared scenes, docs/results/load.md),
  // true HIGH (spatial splits). Entries of the other quality in the cache are not used.
  static void set_high_quality_bvh(bool high);
  static bool high_quality_bvh();
  // The live device's cache figures; false (and nothing made) when no device lives.
  static bool geometry_stats(GeometryCache::Stats& out);

 private:
  EmbreeDevice();
  static void on_error(void* self, RTCError code, const char* message);

  RTCDevice device_ = nullptr;
  std::atomic<uint64_t> errors_{0};
  mutable std::mutex mu_;
  std::string last_;
  GeometryCache geometries_;  // after device_: its scenes are released before the device
};

}  // namespace tessera

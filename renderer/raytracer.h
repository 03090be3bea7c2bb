#pragma once
// The Embree ray tracer (paper section 5.1): ray packets sized to the CPU (16 rays as 4x4
// pixels on AVX-512, 8 as 4x2 on AVX2, 4 as 2x2 on SSE) for tracing and shading, TBB's
// work stealing over the packets of a task, and a TSC cost map per packet.
#include <memory>
#include <vector>

#include "renderer/renderer.h"

namespace tessera {

// Which features the scene in its current state needs; everything else is skipped.
struct SceneFeatures {
  bool secondary = false;   // some visible material reflects, refracts or is see-through
  bool textures = false;    // some visible material is textured
  bool alpha_masks = false; // some visible geometry runs an alpha-mask filter function
  bool lights = false;      // at least one light is on
};

// The packet layout for the widest ISA this CPU and Embree both support natively.
PacketLayout detect_packet_layout();
// The instruction set of the kernel copy that runs packets of this size, and the size.
const char* isa_name(PacketLayout p);
// The time-stamp counter's frequency in kHz (read from the kernel or calibrated once).
double tsc_khz();

// How RayTracer::render_scheduled spreads the packets of a task over threads (the
// thread-level comparison of the paper's Table 2). render() always uses work stealing.
enum class ThreadSchedule {
  work_stealing,  // TBB parallel_for over 2D blocks of packets, exactly as render()
  static_tiles,   // one thread per given tile (packet space), e.g. from the static tiler
  shared_queue,   // `threads` threads pulling packet rows from one shared atomic counter
};
const char* schedule_name(ThreadSchedule s);

class RayTracer final : public Renderer {
 public:
  // layout.w * layout.h must be 4, 8 or 16; {0, 0} picks detect_packet_layout().
  explicit RayTracer(PacketLayout layout = {0, 0});
  ~RayTracer() override;
  RayTracer(const RayTracer&) = delete;
  RayTracer& operator=(const RayTracer&) = delete;

  const char* name() const override { return "raytracer"; }
  void sync(const Scene& scene, std::vector<std::string>& warnings) override;
  // Renders with the kernel the scene and settings need: the one with AO, secondary rays and
  // textures compiled out when none of them is used (see plain_kernel), else the general one.
  void render(const Rect& pixels, const RenderSettings& settings, TaskResult& out) override;
  // Whether render() picks the kernel with AO, secondary rays and textures compiled out.
  bool plain_kernel(const RenderSettings& settings) const;
  PacketLayout packet_layout() const override;

  SceneFeatures features() const;
  float scene_extent() const;  // diagonal of the world bounds
  // Number of BLAS builds and instance updates done by the last sync (for tests of incrementality).
  struct SyncStats {
    int geometries_built = 0, instances_updated = 0, instances_removed = 0;
  };
  SyncStats last_sync() const;

  // Benchmark hooks. A "specialised" kernel has AO, secondary rays, textures and alpha
  // filters compiled out; it renders only scenes that need none of them (else it throws).
  void render_specialised(const Rect& pixels, const RenderSettings& settings, TaskResult& out);
  // The general kernel (every feature compiled in) whatever the scene needs: what render()
  // would cost without picking a kernel per scene.
  void render_general(const Rect& pixels, const RenderSettings& settings, TaskResult& out);
  // The physical limit: the same camera rays in the same packets, traced with no shading and
  // no cost map. Returns wall milliseconds; rays traced in *rays. With intersect_ms, the
  // intersection calls are timed as time_intersections times render()'s (summed over threads).
  double trace_primary_only(const Rect& pixels, uint64_t* rays, double* intersect_ms = nullptr);
  // The same kernel, cost map and image as render(), with the task's packets scheduled over
  // threads as `schedule` says. static_tiles: tiles[i] (absolute packet coordinates, clipped
  // to the task) is rendered by thread i, all tiles together must cover the task's packets;
  // shared_queue: `threads` threads (>= 1). work_stealing ignores tiles and threads (TBB's
  // limit applies). Threads are std::threads started per call (the calling thread runs one).
  void render_scheduled(const Rect& pixels, const RenderSettings& settings, ThreadSchedule schedule,
                        const std::vector<Rect>& tiles, int threads, TaskResult& out);

  // Tests only: with false, sync uses a camera outside core/validate.h's bounds as it is
  // (and rebases on it) instead of rendering the background, so that its rays reach the
  // kernel's second line (rays not finite or beyond kRayLimit are dropped before Embree).
  void set_camera_check(bool on);

  struct Impl;  // opaque; public so the kernel and filter functions in the .cpp can name it

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace tessera

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
  bool vertex_colors = false; // some visible mesh has vertex colours and a material with use_vertex_color
  bool lights = false;      // at least one light is on
};

// The packet layout for the widest ISA this CPU and Embree both support natively.
PacketLayout detect_packet_layout();
// The instruction set of the kernel copy that runs packets of this size, and the size.
const char* isa_name(PacketLayout p);
// The time-stamp counter's frequency in kHz (read from the kernel or calibrated once).
double tsc_khz();

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
  // What the last sync did (for tests of incrementality): geometries set up anew, of which
  // `geometries_shared` took their BVH from the process's geometry cache (built by another
  // ray tracer, or earlier) instead of building it; instances updated and removed.
  struct SyncStats {
    int geometries_built = 0, instances_updated = 0, instances_removed = 0;
    int geometries_shared = 0;
  };
  SyncStats last_sync() const;

  // Tests only: with false, sync uses a camera outside core/validate.h's bounds as it is
  // (and rebases on it) instead of rendering the background, so that its rays reach the
  // kernel's second line (rays not finite or beyond kRayLimit are dropped before Embree).
  void set_camera_check(bool on);

  // The ray tracer's state, opaque here. renderer/raytracer_impl.h defines it for the kernel,
  // the filter functions, and the benchmarks' kernel variants (app/bench_kernels.h), which
  // reach it through impl().
  struct Impl;
  const Impl& impl() const { return *impl_; }

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace tessera

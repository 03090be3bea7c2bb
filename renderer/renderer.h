#pragma once
// The renderer API that every renderer implements (paper section 5.1): sync with the
// scene model, render any rectangle of the image into RGBA, report its cost data.
#include <atomic>
#include <cstdint>
#include <string>
#include <vector>

#include "core/cost_map.h"
#include "core/image.h"
#include "core/rect.h"
#include "core/scene.h"

namespace tessera {

struct RenderSettings {
  int32_t ao_samples = 0;     // ambient occlusion rays per hit; 0 = off (no AO rays traced)
  float ao_distance = 0.0f;   // AO ray length; 0 = a fraction of the scene's extent
  int32_t max_depth = 4;      // maximum recursion depth of reflection/refraction (1 = primary only)
  bool shadows = true;
  bool cost_map = true;       // time each packet with the TSC
  // With cost_map: find the packets whose cost includes a stall of the thread (preemption,
  // long interrupt: wall time without CPU time) and replace their cost by a prediction from
  // undisturbed neighbours (renderer/disturbance.h, docs/load-balancing.md).
  bool disturbance_check = true;
  // Test hook: sleep stall_us microseconds inside the timing window of packet
  // (stall_px, stall_py) (absolute packet coordinates), as a preemption would; 0 = none.
  uint32_t stall_us = 0;
  int32_t stall_px = -1, stall_py = -1;
  // Trilinear texture filtering over mip levels for linear textures (the kernel's textures());
  // false: every texture read at level 0 alone, as before mip levels (`tessera bench --compare
  // mipmaps` measures the difference).
  bool mip_levels = true;
  uint32_t frame = 0;         // seeds the AO sample pattern
  // Progressive rendering (renderer/sampling.h): which of the frame's samples this render is.
  // 0: pixel centres and the fixed AO pattern (what a non-progressive frame shows); s > 0: a
  // jittered sub-pixel position and AO directions further along the pixel's sequence.
  uint32_t sample = 0;
  // Also write each pixel's linear colour (after exposure, before encoding) to
  // TaskResult::radiance, for averaging samples (renderer/accumulation.h).
  bool radiance = false;
  // Also write what each packet saw first to TaskResult::points (lb/reproject.h uses it to
  // carry a frame's cost map into the next camera).
  bool hit_points = false;
  // Also write what each pixel's primary ray saw to TaskResult::guides (the denoiser's
  // guides, renderer/denoise.h).
  bool guides = false;
  // Stopping early: once *cancel_through >= cancel_frame, the packets not yet begun are
  // skipped and TaskResult::cancelled says so (their pixels, radiance, guides and costs are
  // left as zeros). A session abandons a still's sample this way when its client asks for a new
  // frame (docs/renderer.md). None: the task always runs to its end. The ray tracer only.
  const std::atomic<uint32_t>* cancel_through = nullptr;
  uint32_t cancel_frame = 0;
  // Adaptive refinement (renderer/adaptive.h): per plan block (kPlanBlock x kPlanBlock pixels,
  // whatever the packet layout: every layout's packets tile a block) of the rectangle
  // `plan_blocks` (in blocks, row by row), the progressive sample its packets render instead of
  // `sample`, or kSkipPacket: not rendered (pixels, radiance and guides left as zeros, cost 0;
  // so is a packet outside `plan_blocks`). None: every packet renders `sample`. The ray tracer only.
  const uint32_t* block_samples = nullptr;
  Rect plan_blocks;
};

constexpr uint32_t kSkipPacket = 0xFFFFFFFFu;

constexpr int kGuideFloats = 8;  // TaskResult::guides: nx, ny, nz, distance, ambient r, g, b, open

struct RayCounts {
  uint64_t primary = 0, shadow = 0, ao = 0, secondary = 0;
  uint64_t total() const { return primary + shadow + ao + secondary; }
  RayCounts& operator+=(const RayCounts& o) {
    primary += o.primary; shadow += o.shadow; ao += o.ao; secondary += o.secondary;
    return *this;
  }
};

// What a renderer produces for one task (a pixel rectangle of the frame).
struct TaskResult {
  Rect pixels;            // the task, in pixels
  Image image;            // pixels.width() x pixels.height()
  std::vector<float> radiance;  // with RenderSettings::radiance: RGB per pixel, row by row (else empty)
  CostMap cost;           // per-packet cost (cost_map.h for the unit); empty if not measured
  PacketPoints points;    // with RenderSettings::hit_points (cost_map.h); else empty
  // With RenderSettings::guides: per pixel, row by row, kGuideFloats floats about what the
  // primary ray hit: its shading normal (world space, facing the viewer), its distance along
  // the ray, the sky's ambient light it would show unoccluded (RGB, linear, after exposure and
  // the share that reflection and refraction leave to its own shading), and the fraction of
  // its ambient occlusion rays that were open. The pixel's radiance holds ambient x open.
  // A miss has normal 0, distance -1, ambient 0 and open 1. Else empty.
  std::vector<float> guides;
  double kernel_ms = 0;   // sum of the cost map, in milliseconds of one core
  double rendering_ms = 0;  // wall time of the multi-threaded rendering
  RayCounts rays;
  // RenderSettings::disturbance_check: packets whose measured cost was replaced, and the
  // stall found (wall - CPU time summed over the disturbed sub-blocks), in ns.
  uint32_t disturbed_packets = 0;
  uint64_t disturbed_ns = 0;
  bool cancelled = false;  // RenderSettings::cancel_through: stopped early, part of it not rendered
};

class Renderer {
 public:
  virtual ~Renderer() = default;
  virtual const char* name() const = 0;
  // Brings the renderer up to date with the scene, touching only what changed since the
  // last sync. Meshes that cannot be rendered yet (buffers missing or inconsistent) are
  // skipped; why is appended to warnings.
  virtual void sync(const Scene& scene, std::vector<std::string>& warnings) = 0;
  // Renders the given pixel rectangle of the scene's current resolution. The rectangle is
  // clipped to the image; an empty rectangle gives an empty result.
  virtual void render(const Rect& pixels, const RenderSettings& settings, TaskResult& out) = 0;
  // The pixel footprint of one packet (cost map granularity).
  virtual PacketLayout packet_layout() const = 0;
};

// The settings that change nothing on `scene`, each as one sentence for the user (none: empty).
// Ambient occlusion only occludes the sky's ambient light (Environment::ambient), so AO rays on
// a scene without one are never traced; the rasterizer has no AO at all.
inline std::vector<std::string> ineffective_settings(const Scene& scene, int ao_samples, bool rasterizer) {
  std::vector<std::string> out;
  if (ao_samples <= 0) return out;
  const Vec3& a = scene.environment().ambient;
  if (rasterizer)
    out.push_back("ao-samples " + std::to_string(ao_samples) + " has no effect: the rasterizer has no ambient occlusion");
  else if (!(a.x > 0 || a.y > 0 || a.z > 0))
    out.push_back("ao-samples " + std::to_string(ao_samples) +
                  " has no effect: the scene has no sky or ambient light for ambient occlusion to occlude");
  return out;
}

}  // namespace tessera

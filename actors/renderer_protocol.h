#pragma once
// Renderer actor: renders one task of a frame from a scene snapshot and returns pixels and
// the serialised SAT of the task's cost map. It is the unit of distribution: a child node
// is later just another (remote) renderer actor with this interface.
//
// Rendering blocks for tens of milliseconds and runs TBB inside, so the actor is spawned
// detached (its own thread) and CAF's scheduler is capped (configs/*.ini).
#include <atomic>
#include <cstdint>

#include <caf/typed_actor.hpp>
#include <caf/replies_to.hpp>

#include "actors/messages.h"

namespace tessera {

// RenderTask::guides: none; all of TaskResult::guides (kGuideFloats floats a pixel: what a
// still's first sample gives the denoiser); only the open fraction of the AO rays (1 float a
// pixel: what each later sample adds).
constexpr uint8_t kNoGuides = 0, kAllGuides = 1, kOpenGuides = 2;

// One rendering task: a pixel rectangle of frame `frame` at width x height.
struct RenderTask {
  uint32_t frame = 0;  // the session's frame sequence number (not the client's)
  int32_t width = 0, height = 0;
  Rect pixels;
  int32_t ao_samples = 0;
  int32_t max_depth = 4;
  uint8_t renderer = 0;  // protocol::RendererKind: 0 ray tracer, 1 rasterizer
  // Progressive stills (renderer/sampling.h): which sample of the still this is (0: the plain
  // frame) and the frame number that seeds its sample pattern (the still's first frame, so
  // every sample continues the same low-discrepancy sequences; 0: `frame` seeds it). `radiance`: also return the
  // linear colour, for averaging (TileResult::radiance).
  uint32_t sample = 0;
  uint32_t seed = 0;
  bool radiance = false;
  // Also return each packet's first-hit depth (TileResult::depth), for the balancer's
  // reprojection (lb/reproject.h). The ray tracer only; the rasterizer gives none.
  bool hit_points = false;
  // Also return the denoiser's guides of each pixel (TileResult::guides), with radiance.
  uint8_t guides = kNoGuides;
  // Adaptive refinement (renderer/adaptive.h): the sample of each plan block (kPlanBlock x
  // kPlanBlock pixels) of `plan_blocks`, row by row, kSkipPacket for a block not rendered; it
  // covers the blocks the task's pixels touch. Empty: every pixel renders `sample`.
  Rect plan_blocks;
  std::vector<uint32_t> plan;
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, RenderTask& x) {
  return f(caf::meta::type_name("tessera::render_task"), x.frame, x.width, x.height, x.pixels, x.ao_samples,
           x.max_depth, x.renderer, x.sample, x.seed, x.radiance, x.hit_points, x.guides, x.plan_blocks, x.plan);
}

// What a rendering node returns for a task: RGBA pixels of the rectangle and the serialised
// SAT of its cost map (Sat wire format), plus its measurements.
struct TileResult {
  uint32_t frame = 0;
  Rect pixels;
  std::vector<uint8_t> rgba;  // pixels.width() * pixels.height() * 4
  std::vector<uint8_t> sat;   // Sat::serialize(); empty when no cost map was measured
  // With RenderTask::radiance: each pixel's linear RGB as float32 (pixels.area() x 12 bytes,
  // row by row, the byte order of x86 peers); else empty.
  std::vector<uint8_t> radiance;
  // With RenderTask::hit_points: lb/reproject.h's encode_depths over the SAT's packets (4 bytes
  // a packet); else empty.
  std::vector<uint8_t> depth;
  // With RenderTask::guides: the guides it asked for as float32 (kAllGuides: area x 32 bytes,
  // kOpenGuides: area x 4 bytes, row by row); else empty.
  std::vector<uint8_t> guides;
  double kernel_ms = 0, rendering_ms = 0, sat_ms = 0;
  uint64_t rays = 0;
  protocol::ErrorCode code = protocol::ErrorCode::ok;  // not ok: the task failed (pixels are not valid)
  std::string error;                                   // why, when it failed
  // The frame was abandoned while this task rendered (CancelMark): the tile carries no pixels,
  // radiance, guides, SAT or depths (check_tile), and only a frame its master cancelled may end
  // so (frame_actor.cpp).
  bool cancelled = false;
  bool failed() const { return code != protocol::ErrorCode::ok; }
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, TileResult& x) {
  return f(caf::meta::type_name("tessera::tile_result"), x.frame, x.pixels, BytesField{x.rgba}, BytesField{x.sat},
           BytesField{x.radiance}, BytesField{x.depth}, BytesField{x.guides}, x.kernel_ms,
           x.rendering_ms, x.sat_ms, x.rays, x.code, x.error, x.cancelled);
}

// The frames of one session a renderer abandons: a task of frame f stops early once `through`
// >= f (RenderSettings::cancel_through). Frame numbers only grow, so one number says it; the
// subtree that owns the renderer, its one writer, raises it (subtree_protocol.h, cancel) while
// the renderer's thread reads it before each packet.
struct CancelMark {
  std::atomic<uint32_t> through{0};
  void raise(uint32_t frame) {
    if (frame > through.load(std::memory_order_relaxed)) through.store(frame, std::memory_order_relaxed);
  }
};

using renderer_actor = caf::typed_actor<caf::replies_to<render_atom, SceneSnapshot, RenderTask>::with<TileResult>>;

}  // namespace tessera

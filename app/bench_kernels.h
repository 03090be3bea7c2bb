#pragma once
// The ray tracer's benchmark-only kernels: what `tessera bench --compare bare|specialised`
// and `tessera threadbench` measure, and the tests that check them. They compile the
// production kernel's source (renderer/raytracer_kernel.inc) here, in the app, with policies
// of their own (app/bench_kernels.inc), so the renderer library, and with it the node's
// render path, holds none of their code and no branch on their switches (docs/renderer.md,
// "Where the benchmark kernels live"). Target tessera_bench_kernels.
#include <cstdint>
#include <vector>

#include "renderer/raytracer.h"

namespace tessera::bench {

// The general kernel (every feature compiled in) whatever the scene needs: what render()
// would cost without picking a kernel per scene. The renderer's own general kernel.
void render_general(const RayTracer& rt, const Rect& pixels, const RenderSettings& settings, TaskResult& out);
// The specialised kernel: AO, secondary rays, textures and alpha filters compiled out (the one
// render() picks where rt.plain_kernel(settings)). It renders only scenes that need none of
// them, else it throws std::invalid_argument.
void render_specialised(const RayTracer& rt, const Rect& pixels, const RenderSettings& settings, TaskResult& out);

// render() with Embree's primary-ray intersection calls timed by the TSC (two more reads per
// packet); image, cost map and rays as render()'s. Returns the time inside those calls, summed
// over threads (milliseconds of one core, as kernel_ms).
double render_timing_intersections(const RayTracer& rt, const Rect& pixels, const RenderSettings& settings,
                                   TaskResult& out);

// The shading floor: render() with no shading at all. Every hit lane is white and every miss
// the background, so the render costs tracing, ray set-up, output and cost map alone.
void render_shading_floor(const RayTracer& rt, const Rect& pixels, const RenderSettings& settings, TaskResult& out);

// The physical limit ("bare"): the same camera rays in the same packets, traced with no
// shading and no cost map. Returns wall milliseconds; rays traced in *rays. With
// intersect_ms, the intersection calls are timed as render_timing_intersections times ours.
double trace_primary_only(const RayTracer& rt, const Rect& pixels, uint64_t* rays, double* intersect_ms = nullptr);

// How render_scheduled spreads the packets of a task over threads (the thread-level
// comparison of the paper's Table 2). render() always uses work stealing.
enum class ThreadSchedule {
  work_stealing,  // TBB parallel_for over 2D blocks of packets, exactly as render()
  static_tiles,   // one thread per given tile (packet space), e.g. from the static tiler
  shared_queue,   // `threads` threads pulling packet rows from one shared atomic counter
};
const char* schedule_name(ThreadSchedule s);

// render()'s kernel, cost map and image, with the task's packets scheduled over threads as
// `schedule` says. static_tiles: tiles[i] (absolute packet coordinates, clipped to the task)
// is rendered by thread i, all tiles together must cover the task's packets exactly once;
// shared_queue: `threads` threads (>= 1). work_stealing ignores tiles and threads (TBB's
// limit applies). Threads are std::threads started per call (the calling thread runs one).
void render_scheduled(const RayTracer& rt, const Rect& pixels, const RenderSettings& settings, ThreadSchedule schedule,
                      const std::vector<Rect>& tiles, int threads, TaskResult& out);

}  // namespace tessera::bench

#include "app/bench_kernels.h"

#include "core/validate.h"
#include "renderer/raytracer_impl.h"
#include "renderer/sampling.h"

#include <embree3/rtcore.h>
#include <tbb/blocked_range2d.h>
#include <tbb/combinable.h>
#include <tbb/parallel_for.h>
#include <x86intrin.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <thread>
#include <vector>

namespace tessera {

using namespace raytracer_detail;

// The production kernel's source and the benchmarks' variants, compiled once per instruction
// set as raytracer.cpp compiles the kernel (same target pragmas; the same floating-point flags
// through the tessera_kernel_flags target), in namespaces of their own: no kernel function
// here is shared with the renderer library, so render() never runs code compiled in this file.
namespace bench_sse {
#include "renderer/raytracer_kernel.inc"
#include "app/bench_kernels.inc"
}  // namespace bench_sse

#if defined(__clang__)
// clang ignores `#pragma GCC target`: one copy, as in raytracer.cpp.
namespace bench_avx2 = bench_sse;
namespace bench_avx512 = bench_sse;
#else
TESSERA_ISA_AVX2_BEGIN
namespace bench_avx2 {
#include "renderer/raytracer_kernel.inc"
#include "app/bench_kernels.inc"
}  // namespace bench_avx2
TESSERA_ISA_END

TESSERA_ISA_AVX512_BEGIN
namespace bench_avx512 {
#include "renderer/raytracer_kernel.inc"
#include "app/bench_kernels.inc"
}  // namespace bench_avx512
TESSERA_ISA_END
#endif

namespace bench {
namespace {

// Calls call(Variants<N>{}) of the copy for this packet width and CPU, as render_dispatch in
// raytracer.cpp picks the production kernel's copy.
template <class Call>
double with_copy(const RayTracer::Impl& impl, Call&& call) {
  switch (impl.layout.size()) {
    case 16: return cpu_avx512() ? call(bench_avx512::Variants<16>{}) : call(bench_sse::Variants<16>{});
    case 8: return cpu_avx2() ? call(bench_avx2::Variants<8>{}) : call(bench_sse::Variants<8>{});
    default: return call(bench_sse::Variants<4>{});
  }
}

// Runs a render-like variant as render() runs: the kernel render() would pick, and Embree's
// errors during it thrown as render() throws them.
template <class Call>
double as_render(const RayTracer& rt, const RenderSettings& settings, Call&& call) {
  const RayTracer::Impl& impl = rt.impl();
  const uint64_t before = impl.shared_device->errors();
  const bool plain = rt.plain_kernel(settings);
  const double ms = with_copy(impl, [&](auto v) { return call(v, plain); });
  impl.check_device(before);
  return ms;
}

}  // namespace

void render_general(const RayTracer& rt, const Rect& pixels, const RenderSettings& settings, TaskResult& out) {
  const RayTracer::Impl& impl = rt.impl();
  const uint64_t before = impl.shared_device->errors();
  render_production(impl, false, pixels, settings, out);
  impl.check_device(before);
}

void render_specialised(const RayTracer& rt, const Rect& pixels, const RenderSettings& settings, TaskResult& out) {
  if (!rt.plain_kernel(settings))
    throw std::invalid_argument("the specialised kernel renders only scenes without AO, secondary rays, textures and alpha masks");
  const RayTracer::Impl& impl = rt.impl();
  const uint64_t before = impl.shared_device->errors();
  render_production(impl, true, pixels, settings, out);
  impl.check_device(before);
}

double render_timing_intersections(const RayTracer& rt, const Rect& pixels, const RenderSettings& settings,
                                   TaskResult& out) {
  return as_render(rt, settings, [&](auto v, bool plain) { return v.timed(rt.impl(), plain, pixels, settings, out); });
}

void render_shading_floor(const RayTracer& rt, const Rect& pixels, const RenderSettings& settings, TaskResult& out) {
  as_render(rt, settings, [&](auto v, bool plain) { return v.floor(rt.impl(), plain, pixels, settings, out); });
}

double trace_primary_only(const RayTracer& rt, const Rect& pixels, uint64_t* rays, double* intersect_ms) {
  // The same instruction set as the shading kernel, so the comparison is like for like.
  return with_copy(rt.impl(), [&](auto v) { return v.bare(rt.impl(), pixels, rays, intersect_ms); });
}

const char* schedule_name(ThreadSchedule s) {
  switch (s) {
    case ThreadSchedule::static_tiles: return "static tiles";
    case ThreadSchedule::shared_queue: return "shared queue";
    default: return "work stealing";
  }
}

void render_scheduled(const RayTracer& rt, const Rect& pixels, const RenderSettings& settings, ThreadSchedule schedule,
                      const std::vector<Rect>& tiles, int threads, TaskResult& out) {
  if (schedule == ThreadSchedule::static_tiles && tiles.empty())
    throw std::invalid_argument("static_tiles needs at least one tile");
  if (schedule == ThreadSchedule::shared_queue && threads < 1)
    throw std::invalid_argument("shared_queue needs at least one thread");
  as_render(rt, settings, [&](auto v, bool plain) {
    return v.scheduled(rt.impl(), plain, pixels, settings, out, schedule, tiles, threads);
  });
}

}  // namespace bench
}  // namespace tessera

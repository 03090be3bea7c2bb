// tessera bench --scene S.gltf --camera-loop L.json [--frames N] [--step K] [--ao N] ...
// Replays a camera loop on this node and prints one JSON line per frame, then a summary.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <limits>

#include "app/bench_kernels.h"
#include "app/command.h"
#include "app/common.h"
#include "renderer/embree_device.h"
#include "renderer/rasterizer.h"
#include "renderer/raytracer.h"

namespace tessera::app {
namespace {

const char* kHelp =
    "tessera bench --scene S.gltf --camera-loop L.json [--frames N] [--step K] [--size W H]\n"
    "              [--ao N] [--depth D] [--shadows 0|1] [--threads T] [--warmup W] [--reps R]\n"
    "              [--compare bare|specialised|costmap|disturbance|mipmaps|breakdown] [--plain] [--renderer raytracer|rasterizer]\n"
    "              [--bvh-quality medium|high]\n"
    "Replays the camera loop (every K-th frame with --step K) and prints one JSON line per frame:\n"
    "kernel_ms (sum of the cost map), rendering_ms (wall), rays by kind and Mrays/s, then a summary\n"
    "line with medians and conditions. --compare adds, in the same run and per frame (with --reps R\n"
    "both sides run R times in turn and the fastest of each is compared):\n"
    "  bare        a bare Embree loop tracing the same camera rays in the same packets, no shading;\n"
    "              then one more run of each with Embree's intersection calls timed: intersect_ms\n"
    "              (ours) and bare_intersect_ms, after_hit_ms (the rest of our kernel) and\n"
    "              after_hit_budget_ms (what ours/bare >= 0.8 leaves it: 1.25 x bare - ours inside Embree);\n"
    "              and ours with no shading at all (hits white): floor_ms, floor_over_bare, shading_ms\n"
    "              (ours - floor) and shading_budget_ms (what ours/bare >= 0.8 leaves it: 1.25 x bare - floor)\n"
    "  specialised the kernel with AO, secondary rays, textures and filters compiled out, against the\n"
    "              general kernel (render itself runs the specialised one where the scene allows:\n"
    "              \"kernel\" in the summary says which)\n"
    "  costmap     the same render with the per-packet TSC timing switched off\n"
    "  disturbance the same render with the disturbance check (stalled packets found with the thread's\n"
    "              CPU clock and replaced; docs/load-balancing.md) switched off; every frame also\n"
    "              prints disturbed_packets and disturbed_ms (the stall found) of its render\n"
    "  mipmaps     the same render with every texture read at level 0 (bilinear, no mip levels: the\n"
    "              renderer before trilinear filtering)\n"
    "  breakdown   marginal Mrays/s per ray kind (primary; +shadow; +AO; +secondary)\n"
    "--plain strips textures, reflection, refraction and alpha masks from the scene's materials.\n"
    "--renderer rasterizer replays the loop with the OpenGL ES rasterizer (its threads: LP_NUM_THREADS;\n"
    "no rays, no cost map); --compare bare then times the ray tracer's bare primary-ray loop on the same\n"
    "frames in the same run (ours_over_bare = rasterizer ms / bare ms).\n";

double mrays(uint64_t rays, double ms) { return ms > 0 ? double(rays) / (ms * 1e3) : 0; }

// The rasterizer's replay: frame time (wall, including read-back) per frame, and with
// compare_bare the ray tracer's bare primary-ray loop over the same camera in the same run.
int run_rasterizer(SceneSetup& setup, long frames, long step, long warmup, bool compare_bare, const RenderSettings& settings,
                   int threads) {
  Rasterizer gl;
  std::unique_ptr<RayTracer> rt;
  if (compare_bare) rt = std::make_unique<RayTracer>();
  std::vector<std::string> warnings;
  Scene& scene = setup.loaded.scene;
  const Rect full{0, 0, scene.width(), scene.height()};
  auto sync = [&] {
    warnings.clear();
    gl.sync(scene, warnings);
    if (rt) rt->sync(scene, warnings);
  };
  setup.set_frame(0);
  sync();
  for (auto& w : warnings) std::fprintf(stderr, "warning: %s\n", w.c_str());
  for (long i = 0; i < warmup; ++i) { TaskResult r; gl.render(full, settings, r); }
  std::vector<double> rendering, sync_ms, bare_ms, ratio;
  for (long f = 0; f < frames; ++f) {
    size_t k = size_t(f * step) % setup.loop.frames.size();
    setup.set_frame(k);
    auto t0 = std::chrono::steady_clock::now();
    warnings.clear();
    gl.sync(scene, warnings);
    sync_ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    if (rt) rt->sync(scene, warnings);
    // Alternate which side goes first, so that neither always pays for a cold cache.
    double bare = 0;
    uint64_t n = 0;
    if (rt && f % 2 == 1) bare = bench::trace_primary_only(*rt, full, &n);
    TaskResult r;
    gl.render(full, settings, r);
    if (rt && f % 2 == 0) bare = bench::trace_primary_only(*rt, full, &n);
    rendering.push_back(r.rendering_ms);
    std::printf("{\"frame\": %zu, \"rendering_ms\": %.3f, \"sync_ms\": %.3f", k, r.rendering_ms, sync_ms.back());
    if (rt) {
      bare_ms.push_back(bare);
      ratio.push_back(bare > 0 ? r.rendering_ms / bare : 0);
      std::printf(", \"bare_ms\": %.3f, \"ours_over_bare\": %.4f", bare, ratio.back());
    }
    std::printf("}\n");
    std::fflush(stdout);
  }
  const char* lp = std::getenv("LP_NUM_THREADS");
  std::printf("{\"summary\": true, \"renderer\": \"rasterizer\", \"scene\": %s, \"width\": %d, \"height\": %d, "
              "\"frames\": %ld, \"step\": %ld, \"rendering_ms\": %.3f, \"sync_ms\": %.3f, \"triangles\": %zu, "
              "\"gl\": %s, \"lp_num_threads\": %s, \"cpu\": %s, \"threads\": %d",
              json_str(setup.scene_path).c_str(), scene.width(), scene.height(), frames, step, median(rendering),
              median(sync_ms), scene.triangle_count(), json_str(gl.gl_description()).c_str(),
              json_str(lp ? lp : "unset").c_str(), json_str(cpu_model()).c_str(), threads);
  if (rt)
    std::printf(", \"compare\": \"bare\", \"compare_ms\": %.3f, \"compare_ratio\": %.4f, \"isa\": %s", median(bare_ms),
                median(ratio), json_str(isa_name(rt->packet_layout())).c_str());
  std::printf("}\n");
  return 0;
}

int run(const std::vector<std::string>& argv) {
  Args args(argv);
  if (args.flag("--help")) { std::fputs(kHelp, stdout); return 0; }
  int threads = 0;
  auto limit = limit_threads(args, &threads);
  SceneSetup setup = load_scene(args, 1280, 720, LoopOption::required);
  long step = args.integer("--step", 1);
  long frames = args.integer("--frames", long(setup.loop.frames.size()) / std::max(1L, step));
  long warmup = args.integer("--warmup", 1);
  const long reps = args.integer("--reps", 1);
  if (reps < 1 || reps > 100) throw std::invalid_argument("--reps must be 1..100");
  std::string compare = args.str("--compare");
  RenderSettings settings = read_settings(args);
  std::string kind = read_renderer_kind(args);
  args.finish();
  for (auto& w : ineffective_settings(setup.loaded.scene, settings.ao_samples, kind == "rasterizer"))
    std::fprintf(stderr, "warning: %s\n", w.c_str());
  if (kind == "rasterizer") {
    if (!compare.empty() && compare != "bare")
      throw std::invalid_argument("--compare " + compare + " is for the ray tracer; the rasterizer takes only --compare bare");
    return run_rasterizer(setup, frames, step, warmup, compare == "bare", settings, threads);
  }
  if (step < 1 || frames < 1) throw std::invalid_argument("--step and --frames must be >= 1");
  if (!compare.empty() && compare != "bare" && compare != "specialised" && compare != "costmap" && compare != "disturbance" &&
      compare != "mipmaps" && compare != "breakdown")
    throw std::invalid_argument("--compare must be bare, specialised, costmap, disturbance, mipmaps or breakdown");

  RayTracer rt;
  std::vector<std::string> warnings;
  Scene& scene = setup.loaded.scene;
  const Rect full{0, 0, scene.width(), scene.height()};
  auto sync = [&] { warnings.clear(); rt.sync(scene, warnings); };
  setup.set_frame(0);
  const auto t_sync = std::chrono::steady_clock::now();
  sync();
  const double first_sync_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t_sync).count();
  for (auto& w : warnings) std::fprintf(stderr, "warning: %s\n", w.c_str());
  // What a second session of the same scene pays: its ray tracer takes the BVHs the first one
  // built from the process's geometry cache (renderer/geometry_cache.h).
  double second_sync_ms = 0;
  int geometries_shared = 0;
  {
    RayTracer second;
    std::vector<std::string> ignored;
    const auto t_second = std::chrono::steady_clock::now();
    second.sync(scene, ignored);
    second_sync_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t_second).count();
    geometries_shared = second.last_sync().geometries_shared;
  }
  // --compare specialised times the general kernel (render() itself picks the specialised one
  // for such scenes, so comparing it would compare a kernel with itself).
  auto ours = [&](TaskResult& r) {
    if (compare == "specialised") bench::render_general(rt, full, settings, r);
    else rt.render(full, settings, r);
  };
  for (long i = 0; i < warmup; ++i) { TaskResult r; ours(r); }

  std::vector<double> kernel, rendering, rate, cmp_ms, cmp_ratio, b_primary, b_shadow, b_ao, b_secondary;
  std::vector<double> isect, bare_isects, after_hit;  // --compare bare: the split of our time
  std::vector<double> floor_ratio, shading, shading_budget;  // --compare bare: against no shading
  RayCounts total_rays;
  uint64_t disturbed_packets = 0;  // summed over the frames
  for (long f = 0; f < frames; ++f) {
    size_t k = setup.replay(f, step, settings);
    sync();
    // With a same-run comparison, odd frames render the comparison first so that neither
    // side always pays for the first touch after a camera change.
    // specialised, costmap, disturbance and mipmaps compare against the same frame rendered another way.
    const bool against_variant =
        compare == "specialised" || compare == "costmap" || compare == "disturbance" || compare == "mipmaps";
    auto variant = [&] {
      TaskResult t;
      RenderSettings off = settings;
      if (compare == "disturbance") off.disturbance_check = false;
      else if (compare == "mipmaps") off.mip_levels = false;
      else off.cost_map = false;
      if (compare == "specialised") bench::render_specialised(rt, full, settings, t);
      else rt.render(full, off, t);
      return t;
    };
    const bool alternate = against_variant && (f % 2 == 1);
    TaskResult pre;
    if (alternate) pre = variant();
    TaskResult r;
    ours(r);
    kernel.push_back(r.kernel_ms);
    rendering.push_back(r.rendering_ms);
    rate.push_back(mrays(r.rays.total(), r.rendering_ms));
    total_rays += r.rays;
    std::printf("{\"frame\": %zu, \"kernel_ms\": %.3f, \"rendering_ms\": %.3f, \"rays\": {\"primary\": %llu, \"shadow\": %llu, "
                "\"ao\": %llu, \"secondary\": %llu}, \"mrays_per_s\": %.3f, \"disturbed_packets\": %u, \"disturbed_ms\": %.3f",
                k, r.kernel_ms, r.rendering_ms, (unsigned long long)r.rays.primary, (unsigned long long)r.rays.shadow,
                (unsigned long long)r.rays.ao, (unsigned long long)r.rays.secondary, rate.back(), r.disturbed_packets,
                double(r.disturbed_ns) * 1e-6);
    disturbed_packets += r.disturbed_packets;
    // --reps R: both sides run R times in turn and the fastest of each counts (noise on a
    // shared machine only ever adds time).
    auto best = [&](double& ours_ms, double& other_ms, auto&& other) {
      for (long i = 1; i < reps; ++i) {
        TaskResult again;
        ours(again);
        ours_ms = std::min(ours_ms, again.rendering_ms);
        other_ms = std::min(other_ms, other());
      }
    };
    if (compare == "bare") {
      uint64_t n = 0;
      double ms = bench::trace_primary_only(rt, full, &n);
      best(r.rendering_ms, ms, [&] { return bench::trace_primary_only(rt, full, nullptr); });
      // The floor: ours with no shading (bench::render_shading_floor), its R runs in turn
      // with R more of the bare loop.
      double floor_ms = std::numeric_limits<double>::infinity();
      for (long i = 0; i < reps; ++i) {
        TaskResult fl;
        bench::render_shading_floor(rt, full, settings, fl);
        floor_ms = std::min(floor_ms, fl.rendering_ms);
        ms = std::min(ms, bench::trace_primary_only(rt, full, nullptr));
      }
      double ours = mrays(r.rays.primary, r.rendering_ms), bare = mrays(n, ms);
      cmp_ms.push_back(ms);
      cmp_ratio.push_back(bare > 0 ? ours / bare : 0);
      std::printf(", \"bare_ms\": %.3f, \"bare_mrays_per_s\": %.3f, \"primary_mrays_per_s\": %.3f, \"ours_over_bare\": %.4f", ms, bare,
                  ours, cmp_ratio.back());
      floor_ratio.push_back(floor_ms > 0 ? ms / floor_ms : 0);  // same rays: the ratio of rates
      shading.push_back(r.rendering_ms - floor_ms);
      shading_budget.push_back(1.25 * ms - floor_ms);
      std::printf(", \"floor_ms\": %.3f, \"floor_over_bare\": %.4f, \"shading_ms\": %.3f, \"shading_budget_ms\": %.3f", floor_ms,
                  floor_ratio.back(), shading.back(), shading_budget.back());
      // Where our time goes, from one more run of each side with Embree's primary-ray
      // intersection calls timed (CPU ms): inside them, and everything else of our kernel
      // (ray set-up, shading, output, cost map). The 0.8 target allows the latter
      // 1.25 x bare - ours inside Embree (more than the bare loop when shading evicts its data).
      RenderSettings timed = settings;
      timed.cost_map = true;
      TaskResult ti;
      const double ti_isect = bench::render_timing_intersections(rt, full, timed, ti);
      double bare_isect = 0;
      bench::trace_primary_only(rt, full, nullptr, &bare_isect);
      isect.push_back(ti_isect);
      bare_isects.push_back(bare_isect);
      after_hit.push_back(ti.kernel_ms - ti_isect);
      std::printf(", \"intersect_ms\": %.3f, \"bare_intersect_ms\": %.3f, \"after_hit_ms\": %.3f, \"after_hit_budget_ms\": %.3f",
                  isect.back(), bare_isect, after_hit.back(), 1.25 * bare_isect - isect.back());
    } else if (against_variant) {
      TaskResult v = alternate ? pre : variant();
      best(r.rendering_ms, v.rendering_ms, [&] { return variant().rendering_ms; });
      cmp_ms.push_back(v.rendering_ms);
      cmp_ratio.push_back(v.rendering_ms > 0 ? r.rendering_ms / v.rendering_ms : 0);
      if (compare == "specialised")
        std::printf(", \"specialised_rendering_ms\": %.3f, \"general_over_specialised\": %.4f", v.rendering_ms, cmp_ratio.back());
      else if (compare == "mipmaps")
        std::printf(", \"level0_rendering_ms\": %.3f, \"trilinear_over_level0\": %.4f", v.rendering_ms, cmp_ratio.back());
      else if (compare == "disturbance")
        std::printf(", \"no_check_rendering_ms\": %.3f, \"no_check_kernel_ms\": %.3f, \"with_over_without\": %.4f", v.rendering_ms,
                    v.kernel_ms, cmp_ratio.back());
      else
        std::printf(", \"no_costmap_rendering_ms\": %.3f, \"with_over_without\": %.4f", v.rendering_ms, cmp_ratio.back());
    } else if (compare == "breakdown") {
      // Marginal throughput: each configuration adds one kind of ray to the previous one.
      RenderSettings c = settings;
      c.shadows = false; c.ao_samples = 0; c.max_depth = 1;
      TaskResult p, sh, ao, sec;
      rt.render(full, c, p);
      c.shadows = true;
      rt.render(full, c, sh);
      c.ao_samples = settings.ao_samples;
      rt.render(full, c, ao);
      c.max_depth = settings.max_depth;
      rt.render(full, c, sec);
      auto marginal = [](uint64_t rays, double ms) { return ms > 0 ? double(rays) / (ms * 1e3) : 0.0; };
      b_primary.push_back(marginal(p.rays.primary, p.rendering_ms));
      b_shadow.push_back(marginal(sh.rays.shadow, sh.rendering_ms - p.rendering_ms));
      b_ao.push_back(marginal(ao.rays.ao, ao.rendering_ms - sh.rendering_ms));
      b_secondary.push_back(marginal(sec.rays.total() - ao.rays.total(), sec.rendering_ms - ao.rendering_ms));
      std::printf(", \"breakdown_mrays_per_s\": {\"primary\": %.3f, \"shadow\": %.3f, \"ao\": %.3f, \"secondary\": %.3f}",
                  b_primary.back(), b_shadow.back(), b_ao.back(), b_secondary.back());
    }
    std::printf("}\n");
    std::fflush(stdout);
  }
  PacketLayout pl = rt.packet_layout();
  SceneFeatures feat = rt.features();
  std::printf("{\"summary\": true, \"scene\": %s, \"width\": %d, \"height\": %d, \"frames\": %ld, \"step\": %ld, "
              "\"ao\": %d, \"depth\": %d, \"kernel_ms\": %.3f, \"rendering_ms\": %.3f, \"mrays_per_s\": %.3f, "
              "\"triangles\": %zu, \"features\": {\"secondary\": %s, \"textures\": %s, \"alpha_masks\": %s}, "
              "\"kernel\": \"%s\", \"cpu\": %s, \"isa\": %s, \"packet\": \"%dx%d\", \"threads\": %d",
              json_str(setup.scene_path).c_str(), scene.width(), scene.height(), frames, step, settings.ao_samples,
              settings.max_depth, median(kernel), median(rendering), median(rate), scene.triangle_count(),
              feat.secondary ? "true" : "false", feat.textures ? "true" : "false", feat.alpha_masks ? "true" : "false",
              rt.plain_kernel(settings) ? "specialised" : "general", json_str(cpu_model()).c_str(), json_str(isa_name(pl)).c_str(), pl.w, pl.h, threads);
  std::printf(", \"bvh_quality\": \"%s\"", EmbreeDevice::high_quality_bvh() ? "high" : "medium");
  std::printf(", \"disturbed_packets\": %llu", (unsigned long long)disturbed_packets);
  // Where loading went: tinygltf (JSON and buffers), the textures' images (decoded in
  // parallel), the scene model, and the ray tracer's first sync (Embree BVHs, textures).
  const LoadedScene::Times& lt = setup.loaded.times;
  std::printf(", \"load\": {\"parse_ms\": %.1f, \"images_ms\": %.1f, \"convert_ms\": %.1f, \"sync_ms\": %.1f, \"total_ms\": %.1f, "
              "\"second_session_sync_ms\": %.1f, \"geometries_shared\": %d}",
              lt.parse_ms, lt.images_ms, lt.convert_ms, first_sync_ms, lt.parse_ms + lt.images_ms + lt.convert_ms + first_sync_ms,
              second_sync_ms, geometries_shared);
  if (!cmp_ratio.empty())
    std::printf(", \"compare\": %s, \"reps\": %ld, \"compare_ms\": %.3f, \"compare_ratio\": %.4f", json_str(compare).c_str(), reps, median(cmp_ms),
                median(cmp_ratio));
  if (!isect.empty())
    std::printf(", \"intersect_ms\": %.3f, \"bare_intersect_ms\": %.3f, \"after_hit_ms\": %.3f, \"after_hit_budget_ms\": %.3f",
                median(isect), median(bare_isects), median(after_hit), 1.25 * median(bare_isects) - median(isect));
  if (!floor_ratio.empty())
    std::printf(", \"floor_over_bare\": %.4f, \"shading_ms\": %.3f, \"shading_budget_ms\": %.3f", median(floor_ratio),
                median(shading), median(shading_budget));
  if (!b_primary.empty())
    std::printf(", \"breakdown_mrays_per_s\": {\"primary\": %.3f, \"shadow\": %.3f, \"ao\": %.3f, \"secondary\": %.3f}",
                median(b_primary), median(b_shadow), median(b_ao), median(b_secondary));
  std::printf("}\n");
  return 0;
}

const Command reg("bench", "replay a camera loop and print per-frame figures", run);

}  // namespace
}  // namespace tessera::app

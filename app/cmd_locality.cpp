// tessera locality --scene S.gltf --camera-loop L.json [--nodes 4,16,64] [--thread-counts 1,2]
// An experiment on why node kernels can sum to less than the single-node kernel (the paper's
// super-linear kernel scaling, which it attributes to cache locality). For each frame and
// thread count it renders, in one interleaved run: the whole frame (before and after the
// tiles), every tile of an N-way tiling alone, and every tile again right away (a warm
// repeat); kernels are sums of the per-packet TSC cost maps, as in `tessera balance`.
#include <algorithm>
#include <cstdio>
#include <numeric>

#include <sys/resource.h>

#include "app/command.h"
#include "app/common.h"
#include "renderer/raytracer.h"
#include "lb/sat.h"
#include "lb/tiler.h"

namespace tessera::app {
namespace {

const char* kHelp =
    "tessera locality --scene S.gltf --camera-loop L.json [--nodes 4,16,64] [--thread-counts 1,2]\n"
    "                 [--frames F] [--step K] [--reps R] [--size W H] [--ao A] [--depth D]\n"
    "Per frame, thread count T and node count N (medians of R interleaved repetitions):\n"
    "  full_kernel_ms   the whole frame as one task (rendered before and after the tiles; median)\n"
    "  tiles_ratio      sum of the N tiles' kernels, each tile rendered alone / full kernel\n"
    "  warm_ratio       the same tiles rendered a second time right after the first / first time\n"
    "  full_warm_ratio  the full frame rendered a second time right after the first / first time\n"
    "  rendering_ratio  sum of the tiles' wall times / the full frame's wall time\n"
    "  drift_ratio      full frame after the tiles / full frame before (order effects, noise)\n"
    "  cpu_ratio        process CPU time (getrusage) of the tiles / of the full frame: unlike the TSC\n"
    "                   kernel it excludes time a thread spent descheduled (but includes TBB's idle\n"
    "                   spinning when T > 1)\n"
    "  full_kernel_per_cpu  the full frame's kernel / its process CPU time: > 1 means the per-packet\n"
    "                   TSC timings counted time the threads were not running (oversubscription)\n"
    "The tiling is balanced on the frame's own cost map (as the balancer would with perfect\n"
    "coherence). tiles_ratio < 1 is the super-linear effect; if it stays < 1 with T = 1 it is\n"
    "not a threading effect; if warm_ratio < 1 re-touching the same data helps (caches).\n";

double cpu_ms() {  // user + system CPU time of the whole process
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  auto ms = [](const timeval& t) { return double(t.tv_sec) * 1e3 + double(t.tv_usec) * 1e-3; };
  return ms(u.ru_utime) + ms(u.ru_stime);
}

double sum_kernels(RayTracer& rt, const std::vector<Rect>& tasks, PacketLayout pl, const Scene& scene,
                   const RenderSettings& s, double* wall) {
  double k = 0;
  for (const Rect& t : tasks) {
    Rect px = packets_to_pixels(t, pl, scene.width(), scene.height());
    if (px.empty()) continue;
    TaskResult r;
    rt.render(px, s, r);
    k += r.kernel_ms;
    if (wall) *wall += r.rendering_ms;
  }
  return k;
}

int run(const std::vector<std::string>& argv) {
  Args args(argv);
  if (args.flag("--help")) { std::fputs(kHelp, stdout); return 0; }
  SceneSetup setup = load_scene(args, 640, 360, LoopOption::required);
  std::vector<double> node_list = parse_number_list("--nodes", args.str("--nodes", "4,16,64"));
  std::vector<double> thread_list = parse_number_list("--thread-counts", args.str("--thread-counts", "1,2"));
  long step = args.integer("--step", 1);
  long frames = args.integer("--frames", 4);
  long reps = args.integer("--reps", 3);
  RenderSettings settings = read_settings(args);
  args.finish();
  for (double n : node_list)
    if (n != long(n) || n < 1 || n > 4096) throw std::invalid_argument("--nodes: counts must be integers in 1..4096");
  for (double t : thread_list)
    if (t != long(t) || t < 1 || t > 1024) throw std::invalid_argument("--thread-counts: counts must be integers in 1..1024");
  if (step < 1 || frames < 1 || reps < 1) throw std::invalid_argument("--step, --frames and --reps must be >= 1");

  RayTracer rt;
  Scene& scene = setup.loaded.scene;
  const PacketLayout pl = rt.packet_layout();
  const Rect space = packet_space(scene.width(), scene.height(), pl);
  const Rect full{0, 0, scene.width(), scene.height()};
  std::vector<std::string> warnings;
  // Per (thread count, node count): the per-frame ratios, for the summary.
  std::vector<std::vector<double>> tiles_r(thread_list.size() * node_list.size()), warm_r(tiles_r.size()),
      wall_r(tiles_r.size()), cpu_r(tiles_r.size()), per_cpu_r(tiles_r.size()), full_warm_r(tiles_r.size());
  for (long f = 0; f < frames; ++f) {
    size_t k = setup.replay(f, step, settings);
    warnings.clear();
    rt.sync(scene, warnings);
    for (size_t ti = 0; ti < thread_list.size(); ++ti) {
      tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(thread_list[ti]));
      TaskResult ref;
      rt.render(full, settings, ref);  // warm-up, and the cost map the tilings balance on
      SatArray sats(space);
      sats.add(Sat::from_cost_map(ref.cost));
      sats.finalize();
      for (size_t ni = 0; ni < node_list.size(); ++ni) {
        const std::vector<Rect> tasks = tile(&sats, space, std::vector<double>(size_t(node_list[ni]), 1.0));
        std::vector<double> fulls, fulls_wall, tiles, warm, drift, tiles_wall, cpu, per_cpu, full_warm;
        for (long r = 0; r < reps; ++r) {
          TaskResult before, after;
          double c0 = cpu_ms();
          rt.render(full, settings, before);
          double c1 = cpu_ms();
          TaskResult again0;  // ... and the full frame repeated right away
          rt.render(full, settings, again0);
          full_warm.push_back(before.kernel_ms > 0 ? again0.kernel_ms / before.kernel_ms : 0);
          const double c1b = cpu_ms();
          double wall = 0;
          double first = sum_kernels(rt, tasks, pl, scene, settings, &wall);
          double c2 = cpu_ms();
          cpu.push_back(c1 > c0 ? (c2 - c1b) / (c1 - c0) : 0);
          per_cpu.push_back(c1 > c0 ? before.kernel_ms / (c1 - c0) : 0);
          // Each tile twice in a row: the second pass finds the tile's data in the caches.
          double warm_sum = 0, cold_sum = 0;
          for (const Rect& t : tasks) {
            double w0 = 0;
            cold_sum += sum_kernels(rt, {t}, pl, scene, settings, &w0);
            warm_sum += sum_kernels(rt, {t}, pl, scene, settings, &w0);
          }
          rt.render(full, settings, after);
          double fk = 0.5 * (before.kernel_ms + after.kernel_ms);
          fulls.push_back(fk);
          fulls_wall.push_back(0.5 * (before.rendering_ms + after.rendering_ms));
          tiles.push_back(first / fk);
          tiles_wall.push_back(wall / fulls_wall.back());
          warm.push_back(cold_sum > 0 ? warm_sum / cold_sum : 0);
          drift.push_back(before.kernel_ms > 0 ? after.kernel_ms / before.kernel_ms : 0);
        }
        size_t slot = ti * node_list.size() + ni;
        tiles_r[slot].push_back(median(tiles));
        warm_r[slot].push_back(median(warm));
        wall_r[slot].push_back(median(tiles_wall));
        cpu_r[slot].push_back(median(cpu));
        per_cpu_r[slot].push_back(median(per_cpu));
        full_warm_r[slot].push_back(median(full_warm));
        std::printf("{\"frame\": %zu, \"threads\": %ld, \"nodes\": %ld, \"full_kernel_ms\": %.3f, \"tiles_ratio\": %.4f, "
                    "\"warm_ratio\": %.4f, \"rendering_ratio\": %.4f, \"drift_ratio\": %.4f, \"cpu_ratio\": %.4f, "
                    "\"full_kernel_per_cpu\": %.4f, \"full_warm_ratio\": %.4f}\n",
                    k, long(thread_list[ti]), long(node_list[ni]), median(fulls), median(tiles), median(warm),
                    median(tiles_wall), median(drift), median(cpu), median(per_cpu), median(full_warm));
        std::fflush(stdout);
      }
    }
  }
  for (size_t ti = 0; ti < thread_list.size(); ++ti)
    for (size_t ni = 0; ni < node_list.size(); ++ni) {
      size_t slot = ti * node_list.size() + ni;
      const auto& v = tiles_r[slot];
      std::printf("{\"group_summary\": true, \"threads\": %ld, \"nodes\": %ld, \"median_tiles_ratio\": %.4f, "
                  "\"min_tiles_ratio\": %.4f, \"max_tiles_ratio\": %.4f, \"median_warm_ratio\": %.4f, "
                  "\"median_rendering_ratio\": %.4f, \"median_cpu_ratio\": %.4f, \"median_full_kernel_per_cpu\": %.4f, "
                  "\"median_full_warm_ratio\": %.4f}\n",
                  long(thread_list[ti]), long(node_list[ni]), median(v), *std::min_element(v.begin(), v.end()),
                  *std::max_element(v.begin(), v.end()), median(warm_r[slot]), median(wall_r[slot]), median(cpu_r[slot]),
                  median(per_cpu_r[slot]), median(full_warm_r[slot]));
    }
  std::printf("{\"summary\": true, \"scene\": %s, \"frames\": %ld, \"step\": %ld, \"reps\": %ld, \"width\": %d, "
              "\"height\": %d, \"ao\": %d, \"depth\": %d, \"cpu\": %s, \"isa\": %s, \"packet\": \"%dx%d\", \"hardware_threads\": %d}\n",
              json_str(setup.scene_path).c_str(), frames, step, reps, scene.width(), scene.height(), settings.ao_samples,
              settings.max_depth, json_str(cpu_model()).c_str(), json_str(isa_name(pl)).c_str(), pl.w, pl.h,
              hardware_threads());
  return 0;
}

const Command reg("locality", "experiment: why node kernels can sum to less than the single-node kernel", run);

}  // namespace
}  // namespace tessera::app

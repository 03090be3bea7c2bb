// tessera threadbench --scene S.gltf --camera-loop L.json [--threads T] [--frames F] [--reps R]
// The thread-level comparison of the paper's Table 2: on one node, the packets of each frame
// spread over the threads by (a) the static tiler, one tile per thread, tiled from the
// previous frame's cost map; (b) TBB's work stealing (what render() does); (c) a shared task
// queue (threads pulling packet rows from one atomic counter). Same scene, frames, kernel.
#include <algorithm>
#include <cstdio>

#include "app/bench_kernels.h"
#include "app/command.h"
#include "app/common.h"
#include "renderer/raytracer.h"
#include "lb/sat.h"
#include "lb/tiler.h"

namespace tessera::app {
namespace {

const char* kHelp =
    "tessera threadbench --scene S.gltf --camera-loop L.json [--threads T] [--frames F] [--step K]\n"
    "                    [--reps R] [--size W H] [--ao A] [--depth D]\n"
    "Per frame: the wall time of the multi-threaded rendering (rendering_ms) and the kernel (sum of\n"
    "the cost map) for three schedules of the packets over T threads: static tiles (one tile per\n"
    "thread from the tiler, using the previous frame's cost map; frame 0 is split by area and not\n"
    "counted), work stealing (TBB, as render()), shared queue (packet rows from an atomic counter).\n"
    "Each schedule runs R times per frame in rotating order; the per-frame figure is the median.\n"
    "static_vs_X_pct = 100 x (t_X / t_static - 1): the rendering performance of the static method\n"
    "relative to X (negative: static is slower), as the paper's Table 2. The summary gives the\n"
    "median over frames of the per-frame ratios. The three images must be identical.\n";

using bench::ThreadSchedule;
constexpr ThreadSchedule kSchedules[] = {ThreadSchedule::static_tiles, ThreadSchedule::work_stealing,
                                         ThreadSchedule::shared_queue};
constexpr int kNs = 3;

int run(const std::vector<std::string>& argv) {
  Args args(argv);
  if (args.flag("--help")) { std::fputs(kHelp, stdout); return 0; }
  int threads = 0;
  auto limit = limit_threads(args, &threads);
  SceneSetup setup = load_scene(args, 640, 360, LoopOption::required);
  long step = args.integer("--step", 1);
  long frames = args.integer("--frames", long(setup.loop.frames.size()) / std::max(1L, step));
  long reps = args.integer("--reps", 3);
  RenderSettings settings = read_settings(args);
  args.finish();
  if (step < 1 || frames < 2) throw std::invalid_argument("--step >= 1 and --frames >= 2 are needed");
  if (reps < 1 || reps > 1000) throw std::invalid_argument("--reps must be in 1..1000");

  RayTracer rt;
  Scene& scene = setup.loaded.scene;
  const PacketLayout pl = rt.packet_layout();
  const Rect space = packet_space(scene.width(), scene.height(), pl);
  const Rect full{0, 0, scene.width(), scene.height()};
  const std::vector<double> equal(size_t(threads), 1.0);
  std::vector<std::string> warnings;
  std::unique_ptr<SatArray> prev;
  std::vector<double> ratio_ws, ratio_q, ratio_kernel_ws, ratio_kernel_q, tile_balance;
  bool all_identical = true;
  for (long f = 0; f < frames; ++f) {
    size_t k = setup.replay(f, step, settings);
    warnings.clear();
    rt.sync(scene, warnings);
    const std::vector<Rect> tiles = tile(prev.get(), space, equal);

    std::vector<double> wall[kNs], kern[kNs];
    TaskResult res[kNs];
    for (long r = 0; r < reps; ++r)
      for (int j = 0; j < kNs; ++j) {
        int s = int((j + r) % kNs);  // rotate the order so no schedule always runs first
        bench::render_scheduled(rt, full, settings, kSchedules[s], tiles, threads, res[s]);
        wall[s].push_back(res[s].rendering_ms);
        kern[s].push_back(res[s].kernel_ms);
      }
    bool identical = true;
    for (int s = 1; s < kNs; ++s)
      identical = identical && res[s].image.width == res[0].image.width && res[s].image.rgba == res[0].image.rgba;
    // The static tiles' balance as the cost map of this frame sees it: largest / mean tile kernel.
    const CostMap& cm = res[0].cost;
    double worst = 0, total = 0;
    for (const Rect& t : tiles) {
      double c = 0;
      for (int y = t.y0; y < t.y1; ++y)
        for (int x = t.x0; x < t.x1; ++x) c += cm.at(x, y);
      worst = std::max(worst, c);
      total += c;
    }
    double bal = total > 0 ? worst / (total / double(tiles.size())) : 0;
    double t[kNs], kk[kNs];
    for (int s = 0; s < kNs; ++s) { t[s] = median(wall[s]); kk[s] = median(kern[s]); }
    double pct_ws = 100 * (t[1] / t[0] - 1), pct_q = 100 * (t[2] / t[0] - 1);
    if (f > 0) {
      ratio_ws.push_back(t[1] / t[0]);
      ratio_q.push_back(t[2] / t[0]);
      ratio_kernel_ws.push_back(kk[1] / kk[0]);
      ratio_kernel_q.push_back(kk[2] / kk[0]);
      tile_balance.push_back(bal);
      all_identical = all_identical && identical;
    }
    std::printf("{\"frame\": %zu, \"threads\": %d, \"tiled_from\": \"%s\", \"rendering_ms\": {\"static tiles\": %.3f, "
                "\"work stealing\": %.3f, \"shared queue\": %.3f}, \"kernel_ms\": {\"static tiles\": %.3f, \"work stealing\": %.3f, "
                "\"shared queue\": %.3f}, \"static_vs_work_stealing_pct\": %.2f, \"static_vs_shared_queue_pct\": %.2f, "
                "\"static_tile_balance\": %.4f, \"images_identical\": %s}\n",
                k, threads, f == 0 ? "area" : "previous frame's cost map", t[0], t[1], t[2], kk[0], kk[1], kk[2], pct_ws, pct_q,
                bal, identical ? "true" : "false");
    std::fflush(stdout);
    auto next = std::make_unique<SatArray>(space);
    next->add(Sat::from_cost_map(res[0].cost));
    next->finalize();
    prev = std::move(next);
  }
  auto spread = [](const std::vector<double>& v) {
    return v.empty() ? 0.0 : *std::max_element(v.begin(), v.end()) - *std::min_element(v.begin(), v.end());
  };
  std::printf("{\"summary\": true, \"scene\": %s, \"frames_counted\": %zu, \"step\": %ld, \"reps\": %ld, "
              "\"static_vs_work_stealing_pct\": %.2f, \"static_vs_shared_queue_pct\": %.2f, "
              "\"ratio_spread_work_stealing\": %.4f, \"ratio_spread_shared_queue\": %.4f, "
              "\"kernel_static_vs_work_stealing_pct\": %.2f, \"kernel_static_vs_shared_queue_pct\": %.2f, "
              "\"median_static_tile_balance\": %.4f, \"images_identical\": %s, "
              "\"width\": %d, \"height\": %d, \"ao\": %d, \"depth\": %d, \"cpu\": %s, \"isa\": %s, \"packet\": \"%dx%d\", \"threads\": %d}\n",
              json_str(setup.scene_path).c_str(), ratio_ws.size(), step, reps, 100 * (median(ratio_ws) - 1),
              100 * (median(ratio_q) - 1), spread(ratio_ws), spread(ratio_q), 100 * (median(ratio_kernel_ws) - 1),
              100 * (median(ratio_kernel_q) - 1), median(tile_balance), all_identical ? "true" : "false", scene.width(),
              scene.height(), settings.ao_samples, settings.max_depth, json_str(cpu_model()).c_str(),
              json_str(isa_name(pl)).c_str(), pl.w, pl.h, threads);
  return all_identical ? 0 : 1;
}

const Command reg("threadbench", "thread-level scheduling: static tiles vs work stealing vs a shared queue (paper Table 2)", run);

}  // namespace
}  // namespace tessera::app

// tessera balance --scene S.gltf --camera-loop L.json --nodes N [--step K] [--coefficients c1,...]
// The simulated cluster: replays a camera loop, tiles frame f+1 from the per-node SATs of
// frame f (paper section 6), renders each node's task in turn on this machine and reports
// the kernel scaling efficiency per frame (paper Table 1, kernel rows).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <numeric>

#include "app/command.h"
#include "app/common.h"
#include "renderer/raytracer.h"
#include "renderer/sat.h"
#include "renderer/tiler.h"

namespace tessera::app {
namespace {

const char* kHelp =
    "tessera balance --scene S.gltf --camera-loop L.json --nodes N [--frames F] [--step K] [--size W H]\n"
    "                [--ao A] [--depth D] [--coefficients c1,c2,...] [--whole-task] [--threads T]\n"
    "                [--tiling-png F.png]\n"
    "Per frame: the single-node kernel (the whole frame rendered as one task), each node's kernel for\n"
    "its task, efficiency = (single kernel / sum of coefficients) / max_i(kernel_i / c_i) (for equal\n"
    "coefficients: single / (N x largest node kernel)), balance = largest / mean normalised node\n"
    "kernel, SAT generation and tiling times. Frame 0 is split by area; frame f+1 is tiled from frame\n"
    "f's SATs. --whole-task replaces each node's cost map by its task's average (whole-task timings,\n"
    "as Cosenza et al. 2008) to show what the per-packet cost map buys. All nodes run here in turn,\n"
    "so costs share one unit and SATs get performance coefficient 1; --coefficients (renderer\n"
    "coefficients, e.g. 1,1,0.5) set each node's share as a slower or faster node would.\n";

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

int run(const std::vector<std::string>& argv) {
  Args args(argv);
  if (args.flag("--help")) { std::fputs(kHelp, stdout); return 0; }
  int threads = 0;
  auto limit = limit_threads(args, &threads);
  SceneSetup setup = load_scene(args, 640, 360);
  if (setup.loop.frames.empty()) throw std::invalid_argument("--camera-loop is required");
  long nodes = args.integer("--nodes", 2);
  long step = args.integer("--step", 1);
  long frames = args.integer("--frames", long(setup.loop.frames.size()) / std::max(1L, step));
  std::string coeff_arg = args.str("--coefficients");
  bool whole_task = args.flag("--whole-task");
  std::string png = args.str("--tiling-png");
  RenderSettings settings = read_settings(args);
  args.finish();
  if (nodes < 1 || nodes > 4096) throw std::invalid_argument("--nodes must be in 1..4096");
  if (step < 1 || frames < 2) throw std::invalid_argument("--step >= 1 and --frames >= 2 are needed");
  std::vector<double> coeff = coeff_arg.empty() ? std::vector<double>(size_t(nodes), 1.0) : parse_number_list("--coefficients", coeff_arg);
  if (coeff.size() != size_t(nodes)) throw std::invalid_argument("--coefficients needs one value per node");
  for (double c : coeff)
    if (!(c > 0) || !std::isfinite(c)) throw std::invalid_argument("coefficients must be finite and > 0");
  const double coeff_sum = std::accumulate(coeff.begin(), coeff.end(), 0.0);

  RayTracer rt;
  Scene& scene = setup.loaded.scene;
  const PacketLayout pl = rt.packet_layout();
  const Rect space = packet_space(scene.width(), scene.height(), pl);
  std::vector<std::string> warnings;
  std::unique_ptr<SatArray> prev;  // SATs of the previous frame
  std::vector<double> effs, balances;
  for (long f = 0; f < frames; ++f) {
    size_t k = size_t(f * step) % setup.loop.frames.size();
    setup.set_frame(k);
    settings.frame = uint32_t(k);
    warnings.clear();
    rt.sync(scene, warnings);

    auto t_tile = std::chrono::steady_clock::now();
    std::vector<Rect> tasks = tile(prev.get(), space, coeff);
    double tiling_ms = ms_since(t_tile);

    // Reference: the whole frame as one node's task.
    TaskResult single;
    rt.render({0, 0, scene.width(), scene.height()}, settings, single);

    auto next = std::make_unique<SatArray>(space);
    std::vector<double> kern(size_t(nodes), 0.0);
    double sat_ms = 0;
    Image frame_img(scene.width(), scene.height());
    for (long i = 0; i < nodes; ++i) {
      Rect px = packets_to_pixels(tasks[size_t(i)], pl, scene.width(), scene.height());
      if (px.empty()) continue;
      TaskResult r;
      rt.render(px, settings, r);
      kern[size_t(i)] = r.kernel_ms;
      if (!png.empty()) blit(frame_img, r.image, px.x0, px.y0);
      if (whole_task && !r.cost.cost.empty()) {  // one timing per task, spread evenly
        uint64_t avg = r.cost.total() / r.cost.cost.size();
        std::fill(r.cost.cost.begin(), r.cost.cost.end(), uint32_t(avg));
      }
      auto t_sat = std::chrono::steady_clock::now();
      Sat sat = Sat::from_cost_map(r.cost);
      sat_ms += ms_since(t_sat);
      next->add(std::move(sat), 1.0);
    }
    next->finalize();
    prev = std::move(next);

    double worst = 0, mean = 0;
    for (long i = 0; i < nodes; ++i) {
      double t = kern[size_t(i)] / coeff[size_t(i)];
      worst = std::max(worst, t);
      mean += kern[size_t(i)];
    }
    mean /= coeff_sum;
    double eff = worst > 0 ? (single.kernel_ms / coeff_sum) / worst : 0;
    double bal = mean > 0 ? worst / mean : 0;
    if (f > 0) {  // frame 0 is the area split; efficiency counts from the first balanced frame
      effs.push_back(eff);
      balances.push_back(bal);
    }
    std::printf("{\"frame\": %zu, \"nodes\": %ld, \"single_kernel_ms\": %.3f, \"node_kernel_ms\": [", k, nodes, single.kernel_ms);
    for (long i = 0; i < nodes; ++i) std::printf("%s%.3f", i ? ", " : "", kern[size_t(i)]);
    std::printf("], \"efficiency\": %.4f, \"balance\": %.4f, \"sat_ms\": %.3f, \"tiling_ms\": %.4f, \"tiled_from\": \"%s\"}\n", eff,
                bal, sat_ms, tiling_ms, f == 0 ? "area" : (whole_task ? "whole-task timings" : "previous frame's SATs"));
    std::fflush(stdout);
    if (!png.empty() && f == frames - 1) {
      // Draw the task borders over the last frame (like the paper's figure 6).
      for (const Rect& t : tasks) {
        Rect px = packets_to_pixels(t, pl, scene.width(), scene.height());
        if (px.empty()) continue;
        for (int x = px.x0; x < px.x1; ++x)
          for (int y : {px.y0, px.y1 - 1}) { uint8_t* p = frame_img.pixel(x, y); p[0] = 255; p[1] = 230; p[2] = 0; }
        for (int y = px.y0; y < px.y1; ++y)
          for (int x : {px.x0, px.x1 - 1}) { uint8_t* p = frame_img.pixel(x, y); p[0] = 255; p[1] = 230; p[2] = 0; }
      }
      write_png(png, frame_img);
    }
  }
  double mean_eff = effs.empty() ? 0 : std::accumulate(effs.begin(), effs.end(), 0.0) / double(effs.size());
  double mean_bal = balances.empty() ? 0 : std::accumulate(balances.begin(), balances.end(), 0.0) / double(balances.size());
  std::printf("{\"summary\": true, \"scene\": %s, \"nodes\": %ld, \"frames\": %ld, \"step\": %ld, \"whole_task\": %s, "
              "\"coefficients\": %s, \"mean_efficiency\": %.4f, \"median_efficiency\": %.4f, \"mean_balance\": %.4f, "
              "\"width\": %d, \"height\": %d, \"ao\": %d, \"depth\": %d, \"cpu\": %s, \"isa\": %s, \"packet\": \"%dx%d\", \"threads\": %d}\n",
              json_str(setup.scene_path).c_str(), nodes, frames, step, whole_task ? "true" : "false",
              json_str(coeff_arg.empty() ? "equal" : coeff_arg).c_str(), mean_eff, median(effs), mean_bal, scene.width(),
              scene.height(), settings.ao_samples, settings.max_depth, json_str(cpu_model()).c_str(), json_str(isa_name(pl)).c_str(),
              pl.w, pl.h, threads);
  return 0;
}

const Command reg("balance", "simulated cluster: kernel scaling efficiency of the static load balancer", run);

}  // namespace
}  // namespace tessera::app

// tessera balance --scene S.gltf --camera-loop L.json --nodes N1,N2,... [--step K] [--coefficients c1,...]
// The simulated cluster: replays a camera loop, tiles frame f+1 from the per-node SATs of
// frame f (paper section 6), renders each node's task in turn on this machine and reports
// the kernel scaling efficiency per frame (paper Table 1, kernel rows), for every node count
// of a list in one run (the single-node reference frame is shared by all node counts).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <numeric>

#include "app/command.h"
#include "app/common.h"
#include "renderer/raytracer.h"
#include "lb/reproject.h"
#include "lb/sat.h"
#include "lb/tiler.h"

namespace tessera::app {
namespace {

const char* kHelp =
    "tessera balance --scene S.gltf --camera-loop L.json --nodes N[,N2,...] [--frames F] [--step K]\n"
    "                [--size W H] [--ao A] [--depth D] [--coefficients c1,c2,...] [--whole-task]\n"
    "                [--threads T] [--reps R] [--predictor previous|reproject|both] [--tiling-png F.png]\n"
    "For every node count N of the list and every frame: the single-node kernel (the whole frame\n"
    "rendered as one task, once per frame for all N), each node's kernel for its task, efficiency,\n"
    "balance = largest / mean normalised node kernel, SAT generation and tiling times. Frame 0 is\n"
    "split by area and not counted; frame f+1 is tiled from frame f's SATs. One JSON line per frame\n"
    "and node count, one \"nodes_summary\" line per node count, then the \"summary\" line.\n"
    "--coefficients: renderer coefficients; node i of N gets c[i mod len] (so 1,2 alternates slow and\n"
    "fast nodes at every N). A node with coefficient c simulates a node c times as fast as this one:\n"
    "its kernel is the measured kernel / c, its cost map is the measured one / c, and its SAT enters\n"
    "the SAT array with performance coefficient c, which normalises it back (paper 6.3).\n"
    "Efficiency = (single kernel / sum of coefficients) / max_i(kernel_i / c_i): the ideal time of\n"
    "the cluster over its slowest node; with equal coefficients single / (N x largest node kernel).\n"
    "--whole-task replaces each node's cost map by its task's average (whole-task timings, as\n"
    "Cosenza et al. 2008) to show what the per-packet cost map buys. --tiling-png draws the last\n"
    "frame's tiling of the last node count over the image (paper figure 6).\n"
    "--reps R (default 3) renders the reference and every node's task R times in a row and keeps,\n"
    "per packet, the smallest cost (the kernel is the sum of that map): on a shared machine a TSC\n"
    "timing also counts the time a thread was descheduled, a spike on one packet that a repeat\n"
    "does not repeat; a real node has its machine to itself. --threads defaults to 1: every\n"
    "simulated node renders on one thread, as the reference does.\n"
    "The noise floor: every frame's reference is rendered twice (R times each); the smaller kernel\n"
    "over the larger is the efficiency of one node against itself, the best any row can be trusted\n"
    "to. Each row names its predictor: area (frame 0), previous_frame (the last frame's cost maps),\n"
    "reprojected (the last frame's cost carried into this frame's camera with each packet's first\n"
    "hit, lb/reproject.h; its rows also give reproject_ms, filled packets and whether it was a cut),\n"
    "whole_task. --predictor both (the default) balances every node count twice, once with each,\n"
    "on the same frames and the same single-node reference, so the two compare within one run.\n"
    "Judged on cost maps of the frame instead of node kernels (so neither the nodes' sum against\n"
    "the single kernel nor the noise in the largest of N kernels counts): two reference maps, each\n"
    "packet's best over one reference and the tasks of every other row (rows 0, 2, ... and 1, 3,\n"
    "...). map_efficiency: the tiling's ideal time over its largest share of the first map (the\n"
    "prediction and the tiler); map_efficiency_again: the same on the second (the difference is\n"
    "this figure's own noise); map_oracle_efficiency: the tiling made from the first map itself\n"
    "(the tiler's bound); map_self_efficiency: the tiling made from the second map (what timing\n"
    "noise alone leaves of a prediction from the very same frame). Summaries: medians, minima.\n";

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

// Renders px `reps` times; out gets the first render's image and the per-packet minimum cost.
void render_min(RayTracer& rt, const Rect& px, const RenderSettings& s, long reps, TaskResult& out) {
  rt.render(px, s, out);
  for (long r = 1; r < reps; ++r) {
    TaskResult t;
    rt.render(px, s, t);
    for (size_t i = 0; i < out.cost.cost.size(); ++i) out.cost.cost[i] = std::min(out.cost.cost[i], t.cost.cost[i]);
  }
  if (reps > 1) out.kernel_ms = double(out.cost.total()) * 1e-6;
}

// The simulated cluster of one node count: its coefficients and last frame's SATs.
struct Cluster {
  long nodes = 0;
  bool reproject = false;  // predictor: the last frame's map carried into this camera
  CostMap last_cost;       // reproject: last frame's normalised cost over the packet space
  PacketPoints last_points;
  std::vector<double> coeff;
  double coeff_sum = 0;
  std::unique_ptr<SatArray> prev;
  std::vector<Rect> tasks;  // this frame's tiling
  std::string line;         // this frame's JSON line so far (the map figures come last)
  std::vector<double> effs, balances;
  std::vector<double> map_effs, oracle_effs, self_effs, map_noise;  // per counted frame (map_efficiency)
};

// The efficiency a tiling would reach if every packet cost what a reference map of the frame
// says (`truth`, as a SAT): the ideal time over the slowest node's share of that map. It leaves
// out what the node renders measure beside the tiling (their sum against the single kernel,
// and timing noise in the largest of N kernels), so it is the prediction and the tiler alone.
double map_efficiency(const Sat& truth, const std::vector<Rect>& tasks, const std::vector<double>& coeff, double coeff_sum) {
  double worst = 0;
  for (size_t i = 0; i < tasks.size() && i < coeff.size(); ++i) worst = std::max(worst, double(truth.cost(tasks[i])) / coeff[i]);
  return worst > 0 ? (double(truth.total()) / coeff_sum) / worst : 0;
}

// dst = min(dst, src) packet by packet over src's packets (inside dst's).
void take_min(CostMap& dst, const CostMap& src) {
  const Rect& b = src.packets;
  if (!dst.packets.contains(b) || src.cost.size() != size_t(b.area())) throw std::logic_error("a task's cost map outside the frame's");
  for (int32_t y = b.y0; y < b.y1; ++y)
    for (int32_t x = b.x0; x < b.x1; ++x) {
      uint32_t& c = dst.cost[size_t(y - dst.packets.y0) * size_t(dst.packets.width()) + size_t(x - dst.packets.x0)];
      c = std::min(c, src.at(x, y));
    }
}

std::string list_json(const std::vector<double>& v, const char* fmt) {
  std::string s = "[";
  char buf[64];
  for (size_t i = 0; i < v.size(); ++i) {
    std::snprintf(buf, sizeof buf, fmt, v[i]);
    s += (i ? ", " : "") + std::string(buf);
  }
  return s + "]";
}

const char* predictor_name(const Cluster& cl, long frame, bool whole_task) {
  if (frame == 0) return "area";
  if (whole_task) return cl.reproject ? "whole_task_reprojected" : "whole_task";
  return cl.reproject ? "reprojected" : "previous_frame";
}

// A node's task into the frame-wide map and hit points the reprojection starts from.
void copy_task(const TaskResult& r, CostMap& cost, PacketPoints& points) {
  const Rect& t = r.cost.packets;
  const bool has_points = r.points.packets == t && r.points.xyzw.size() == r.cost.cost.size() * 4;
  for (int32_t y = t.y0; y < t.y1; ++y)
    for (int32_t x = t.x0; x < t.x1; ++x) {
      if (!cost.packets.contains(x, y)) continue;
      const size_t src = size_t(y - t.y0) * size_t(t.width()) + size_t(x - t.x0);
      const size_t dst = size_t(y) * size_t(cost.packets.width()) + size_t(x);
      cost.cost[dst] = r.cost.cost[src];
      if (has_points)
        for (int k = 0; k < 4; ++k) points.xyzw[dst * 4 + k] = r.points.xyzw[src * 4 + k];
    }
}

void draw_tiling(Image& img, const std::vector<Rect>& tasks, PacketLayout pl) {
  for (const Rect& t : tasks) {
    Rect px = packets_to_pixels(t, pl, img.width, img.height);
    if (px.empty()) continue;
    auto mark = [&](int x, int y) { uint8_t* p = img.pixel(x, y); p[0] = 255; p[1] = 230; p[2] = 0; p[3] = 255; };
    for (int x = px.x0; x < px.x1; ++x) { mark(x, px.y0); mark(x, px.y1 - 1); }
    for (int y = px.y0; y < px.y1; ++y) { mark(px.x0, y); mark(px.x1 - 1, y); }
  }
}

int run(const std::vector<std::string>& argv) {
  Args args(argv);
  if (args.flag("--help")) { std::fputs(kHelp, stdout); return 0; }
  int threads = 0;
  auto limit = limit_threads(args, &threads, 1);  // one thread per simulated node, as a real one has its cores
  SceneSetup setup = load_scene(args, 640, 360, LoopOption::required);
  std::vector<double> node_list = parse_number_list("--nodes", args.str("--nodes", "2"));
  long step = args.integer("--step", 1);
  long frames = args.integer("--frames", long(setup.loop.frames.size()) / std::max(1L, step));
  std::string coeff_arg = args.str("--coefficients");
  bool whole_task = args.flag("--whole-task");
  std::string png = args.str("--tiling-png");
  long reps = args.integer("--reps", 3);
  const std::string predictor = args.str("--predictor", "both");
  RenderSettings settings = read_settings(args);
  args.finish();
  if (step < 1 || frames < 2) throw std::invalid_argument("--step >= 1 and --frames >= 2 are needed");
  if (reps < 1 || reps > 100) throw std::invalid_argument("--reps must be in 1..100");
  if (predictor != "previous" && predictor != "reproject" && predictor != "both")
    throw std::invalid_argument("--predictor must be previous, reproject or both");
  std::vector<double> coeff_pattern = coeff_arg.empty() ? std::vector<double>{1.0} : parse_number_list("--coefficients", coeff_arg);
  for (double c : coeff_pattern)
    if (!(c > 0) || !std::isfinite(c)) throw std::invalid_argument("coefficients must be finite and > 0");
  std::vector<Cluster> clusters;
  for (double n : node_list) {
    if (n != std::floor(n) || n < 1 || n > 4096) throw std::invalid_argument("--nodes: each count must be an integer in 1..4096");
    Cluster c;
    c.nodes = long(n);
    for (long i = 0; i < c.nodes; ++i) c.coeff.push_back(coeff_pattern[size_t(i) % coeff_pattern.size()]);
    c.coeff_sum = std::accumulate(c.coeff.begin(), c.coeff.end(), 0.0);
    if (predictor != "previous") {
      Cluster r;
      r.nodes = c.nodes;
      r.coeff = c.coeff;
      r.coeff_sum = c.coeff_sum;
      r.reproject = true;
      if (predictor == "both") clusters.push_back(std::move(c));
      clusters.push_back(std::move(r));
    } else {
      clusters.push_back(std::move(c));
    }
  }

  // Every render of the run writes hit points when a predictor needs them, the reference's too,
  // so that the kernels compared include the same per-packet work.
  settings.hit_points = predictor != "previous";
  RayTracer rt;
  Scene& scene = setup.loaded.scene;
  const PacketLayout pl = rt.packet_layout();
  const Rect space = packet_space(scene.width(), scene.height(), pl);
  std::vector<std::string> warnings;
  std::vector<double> noise_effs;  // per counted frame: the reference against itself
  for (long f = 0; f < frames; ++f) {
    size_t k = setup.replay(f, step, settings);
    warnings.clear();
    rt.sync(scene, warnings);

    // Reference: the whole frame as one node's task (shared by every node count).
    TaskResult single, again;
    render_min(rt, {0, 0, scene.width(), scene.height()}, settings, reps, single);
    render_min(rt, {0, 0, scene.width(), scene.height()}, settings, reps, again);
    const double noise_eff = std::min(single.kernel_ms, again.kernel_ms) / std::max(1e-9, std::max(single.kernel_ms, again.kernel_ms));
    if (f > 0) noise_effs.push_back(noise_eff);
    if (single.cost.packets != space || again.cost.packets != space)
      throw std::runtime_error("the reference render's cost map does not cover the frame's packets");
    // The frame's two reference maps for the map figures: the per-packet minimum over the
    // first reference and the renders of clusters 0, 2, 4, ..., and over the second reference
    // and clusters 1, 3, 5, ...: every packet's best of several renders spread over the
    // frame's whole measurement, in two independent halves.
    CostMap pool[2] = {single.cost, again.cost};

    for (size_t ci = 0; ci < clusters.size(); ++ci) {
      Cluster& cl = clusters[ci];
      const bool draw = !png.empty() && f == frames - 1 && ci + 1 == clusters.size();
      // Reprojected prediction: the last frame's map in this frame's camera, as one SAT.
      ReprojectStats rs;
      double reproject_ms = 0;
      if (cl.reproject && cl.prev) {
        auto t_rep = std::chrono::steady_clock::now();
        const CostMap carried =
            reproject(cl.last_cost, cl.last_points, ViewRays::of(scene.camera(), scene.width(), scene.height()), pl, &rs);
        auto array = std::make_unique<SatArray>(space);
        array->add(Sat::from_cost_map(carried));
        array->finalize();
        cl.prev = std::move(array);
        reproject_ms = ms_since(t_rep);
      }
      auto t_tile = std::chrono::steady_clock::now();
      std::vector<Rect> tasks = tile(cl.prev.get(), space, cl.coeff);
      double tiling_ms = ms_since(t_tile);
      if (cl.reproject) {
        cl.last_cost = CostMap{space, std::vector<uint32_t>(size_t(space.area()), 0)};
        cl.last_points = PacketPoints{space, std::vector<float>(size_t(space.area()) * 4, -1.0f)};
      }

      auto next = std::make_unique<SatArray>(space);
      std::vector<double> kern(size_t(cl.nodes), 0.0);  // simulated: measured / coefficient
      double sat_ms = 0;
      Image frame_img = draw ? Image(scene.width(), scene.height()) : Image();
      for (long i = 0; i < cl.nodes; ++i) {
        Rect px = packets_to_pixels(tasks[size_t(i)], pl, scene.width(), scene.height());
        if (px.empty()) continue;
        const double c = cl.coeff[size_t(i)];
        TaskResult r;
        render_min(rt, px, settings, reps, r);
        take_min(pool[ci % 2], r.cost);
        kern[size_t(i)] = r.kernel_ms / c;
        if (draw) blit(frame_img, r.image, px.x0, px.y0);
        if (cl.reproject) copy_task(r, cl.last_cost, cl.last_points);
        if (whole_task && !r.cost.cost.empty()) {  // one timing per task, spread evenly
          uint64_t avg = r.cost.total() / r.cost.cost.size();
          std::fill(r.cost.cost.begin(), r.cost.cost.end(), uint32_t(avg));
        }
        if (c != 1.0)  // what a node c times as fast would have measured
          for (uint32_t& v : r.cost.cost) v = uint32_t(std::lround(double(v) / c));
        auto t_sat = std::chrono::steady_clock::now();
        Sat sat = Sat::from_cost_map(r.cost);
        sat_ms += ms_since(t_sat);
        next->add(std::move(sat), c);
      }
      next->finalize();
      cl.prev = std::move(next);

      double worst = 0, mean = 0;
      for (long i = 0; i < cl.nodes; ++i) {
        worst = std::max(worst, kern[size_t(i)]);
        mean += kern[size_t(i)] * cl.coeff[size_t(i)];
      }
      mean /= cl.coeff_sum;  // the ideal: every node busy for the same time
      double eff = worst > 0 ? (single.kernel_ms / cl.coeff_sum) / worst : 0;
      double bal = mean > 0 ? worst / mean : 0;
      if (f > 0) {  // frame 0 is the area split; efficiency counts from the first balanced frame
        cl.effs.push_back(eff);
        cl.balances.push_back(bal);
      }
      double kern_sum = std::accumulate(kern.begin(), kern.end(), 0.0, [&, i = size_t(0)](double s, double v) mutable {
        return s + v * cl.coeff[i++];
      });
      cl.tasks = std::move(tasks);
      cl.line = format("{\"frame\": %zu, \"nodes\": %ld, \"whole_task\": %s, \"single_kernel_ms\": %.3f, \"node_kernel_ms\": %s, "
                  "\"node_kernel_sum_ratio\": %.4f, \"efficiency\": %.4f, \"balance\": %.4f, \"sat_ms\": %.3f, "
                  "\"tiling_ms\": %.4f, \"predictor\": \"%s\", \"reproject_ms\": %.3f, \"reproject_filled\": %lld, "
                  "\"reproject_cut\": %s, \"noise_floor_efficiency\": %.4f",
                  k, cl.nodes, whole_task ? "true" : "false", single.kernel_ms, list_json(kern, "%.3f").c_str(),
                  single.kernel_ms > 0 ? kern_sum / single.kernel_ms : 0, eff, bal, sat_ms, tiling_ms,
                  predictor_name(cl, f, whole_task), reproject_ms, (long long)rs.filled,
                  cl.reproject && f > 0 && rs.cut ? "true" : "false", noise_eff);
      if (draw) {
        draw_tiling(frame_img, cl.tasks, pl);
        write_png(png, frame_img);
      }
    }
    // Every tiling of the frame judged on the pooled reference maps: on the first (on the
    // second too: the difference is this figure's own noise). And two tilings made from them:
    // from the first, the tiler's bound (a perfect prediction); from the second, what timing
    // noise alone leaves of a prediction from the very same frame. One SAT array per map,
    // shared by every row.
    SatArray pooled[2] = {SatArray(space), SatArray(space)};
    for (int m = 0; m < 2; ++m) {
      pooled[m].add(Sat::from_cost_map(pool[m]));
      pooled[m].finalize();
    }
    const Sat &truth = pooled[0].entries()[0].sat, &truth_again = pooled[1].entries()[0].sat;
    for (Cluster& cl : clusters) {
      const double map_eff = map_efficiency(truth, cl.tasks, cl.coeff, cl.coeff_sum);
      const double map_eff_again = map_efficiency(truth_again, cl.tasks, cl.coeff, cl.coeff_sum);
      const double oracle_eff = map_efficiency(truth, tile(&pooled[0], space, cl.coeff), cl.coeff, cl.coeff_sum);
      const double self_eff = map_efficiency(truth, tile(&pooled[1], space, cl.coeff), cl.coeff, cl.coeff_sum);
      if (f > 0) {
        cl.map_effs.push_back(map_eff);
        cl.oracle_effs.push_back(oracle_eff);
        cl.self_effs.push_back(self_eff);
        cl.map_noise.push_back(std::abs(map_eff - map_eff_again));
      }
      std::printf("%s, \"map_efficiency\": %.4f, \"map_efficiency_again\": %.4f, \"map_oracle_efficiency\": %.4f, "
                  "\"map_self_efficiency\": %.4f}\n",
                  cl.line.c_str(), map_eff, map_eff_again, oracle_eff, self_eff);
    }
    std::fflush(stdout);
  }
  std::vector<double> means, medians, map_medians;
  std::string rows = "[";  // which node count and predictor each entry of the lists below is
  for (const Cluster& cl : clusters)
    rows += (rows.size() > 1 ? ", " : "") + std::string("\"") + std::to_string(cl.nodes) +
            (cl.reproject ? " reprojected" : " previous_frame") + "\"";
  rows += "]";
  for (const Cluster& cl : clusters) {
    double mean_eff = cl.effs.empty() ? 0 : std::accumulate(cl.effs.begin(), cl.effs.end(), 0.0) / double(cl.effs.size());
    double mean_bal = cl.balances.empty() ? 0 : std::accumulate(cl.balances.begin(), cl.balances.end(), 0.0) / double(cl.balances.size());
    const auto min_of = [](const std::vector<double>& v) { return v.empty() ? 0.0 : *std::min_element(v.begin(), v.end()); };
    double lo = min_of(cl.effs);
    double hi = cl.effs.empty() ? 0 : *std::max_element(cl.effs.begin(), cl.effs.end());
    means.push_back(mean_eff);
    medians.push_back(median(cl.effs));
    map_medians.push_back(median(cl.map_effs));
    const double map_noise_max = cl.map_noise.empty() ? 0.0 : *std::max_element(cl.map_noise.begin(), cl.map_noise.end());
    std::printf("{\"nodes_summary\": true, \"nodes\": %ld, \"predictor\": \"%s\", \"whole_task\": %s, \"coefficients\": %s, \"frames_counted\": %zu, "
                "\"mean_efficiency\": %.4f, \"median_efficiency\": %.4f, \"min_efficiency\": %.4f, \"max_efficiency\": %.4f, "
                "\"mean_balance\": %.4f, \"median_map_efficiency\": %.4f, \"min_map_efficiency\": %.4f, "
                "\"median_map_oracle_efficiency\": %.4f, \"min_map_oracle_efficiency\": %.4f, \"median_map_self_efficiency\": %.4f, "
                "\"min_map_self_efficiency\": %.4f, \"map_noise_max\": %.4f}\n",
                cl.nodes, cl.reproject ? "reprojected" : "previous_frame", whole_task ? "true" : "false",
                list_json(cl.coeff, "%g").c_str(), cl.effs.size(), mean_eff,
                medians.back(), lo, hi, mean_bal, map_medians.back(), min_of(cl.map_effs), median(cl.oracle_effs),
                min_of(cl.oracle_effs), median(cl.self_effs), min_of(cl.self_effs), map_noise_max);
  }
  std::printf("{\"summary\": true, \"scene\": %s, \"nodes\": %s, \"frames\": %ld, \"step\": %ld, \"whole_task\": %s, "
              "\"coefficients\": %s, \"rows\": %s, \"mean_efficiency\": %s, \"median_efficiency\": %s, "
              "\"median_map_efficiency\": %s, \"reps\": %ld, \"width\": %d, \"height\": %d, \"ao\": %d, \"depth\": %d, \"cpu\": %s, \"isa\": %s, \"packet\": \"%dx%d\", "
              "\"threads\": %d, \"noise_floor_median_efficiency\": %.4f, \"noise_floor_min_efficiency\": %.4f}\n",
              json_str(setup.scene_path).c_str(), list_json(node_list, "%g").c_str(), frames, step, whole_task ? "true" : "false",
              json_str(coeff_arg.empty() ? "equal" : coeff_arg).c_str(), rows.c_str(), list_json(means, "%.4f").c_str(),
              list_json(medians, "%.4f").c_str(), list_json(map_medians, "%.4f").c_str(), reps, scene.width(), scene.height(), settings.ao_samples, settings.max_depth,
              json_str(cpu_model()).c_str(), json_str(isa_name(pl)).c_str(), pl.w, pl.h, threads, median(noise_effs),
              noise_effs.empty() ? 0.0 : *std::min_element(noise_effs.begin(), noise_effs.end()));
  return 0;
}

const Command reg("balance", "simulated cluster: kernel scaling efficiency of the static load balancer", run);

}  // namespace
}  // namespace tessera::app
